"""A reduced model's basis at other points of its body: physics on a fine mesh, display on a
coarse one. Each point is located in the fine mesh's tet that holds it and the basis is
interpolated there with the element's shape functions (linear or quadratic tets), so
positions at the points cost p x 3 x r, whatever the fine mesh.
"""
import numpy as np

from ..physics.points import node_weights


def interpolate(mesh, basis, points):
    """The basis (3n, r) of a model on mesh, interpolated at rest points (p, 3): (p, 3, r)."""
    nodes, shape = node_weights(mesh, points)
    U = basis.reshape(mesh.n_vertices, 3, -1)
    return np.einsum("pa,pakr->pkr", shape, U[nodes])
