"""The 4-node linear tetrahedron: shape functions the barycentric coordinates, constant
gradients, so one quadrature point (the centroid, weight 1) integrates every energy density
exactly."""
import numpy as np

from . import Element


def _shape(xi):
    xi = np.atleast_2d(xi)
    return np.column_stack([1.0 - xi.sum(1), xi])


def _shape_gradients(xi):
    grad = np.array([[-1.0, -1.0, -1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    return np.broadcast_to(grad, (np.atleast_2d(xi).shape[0], 4, 3))


TET4 = Element(name="tet4", cell_type="tetra",
               nodes=np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0],
                               [0.0, 0.0, 1.0]]),
               shape=_shape, shape_gradients=_shape_gradients,
               points=np.full((1, 3), 0.25), weights=np.ones(1))
