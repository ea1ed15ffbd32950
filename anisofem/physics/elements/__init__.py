"""Finite elements on straight-sided tetrahedra: shape functions in reference coordinates and
a quadrature rule. Each element is one module defining an Element; the element loop
(anisofem.physics.kernels) reads only its shape gradients and weights at the quadrature points.

Reference tetrahedron: vertices (0,0,0), (1,0,0), (0,1,0), (0,0,1); the affine map
X = X_0 + Dm xi (Dm: the columns X_1 - X_0, X_2 - X_0, X_3 - X_0) takes it to a mesh element,
so material shape gradients are grad N_a = Dm^-T grad_xi N_a (TetMesh.inverse_jacobians
holds Dm^-1 per element).
"""
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Element:
    """A tetrahedral element type.

    name: how files and messages call it; cell_type: meshio's name; nodes: (k, 3) reference
    coordinates of its k nodes (the four vertices first); shape: xi (p, 3) -> (p, k) shape
    functions; shape_gradients: xi (p, 3) -> (p, k, 3) their reference gradients; points
    (q, 3) and weights (q,) the quadrature rule (weights > 0, summing to 1: fractions of the
    element's volume)."""
    name: str
    cell_type: str
    nodes: np.ndarray
    shape: object
    shape_gradients: object
    points: np.ndarray
    weights: np.ndarray

    @property
    def n_nodes(self):
        return self.nodes.shape[0]

    @property
    def point_gradients(self):
        """(q, k, 3) reference shape gradients at the quadrature points (C-contiguous)."""
        return np.ascontiguousarray(self.shape_gradients(self.points))
