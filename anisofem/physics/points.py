"""Points of a body at rest located in its mesh: the tet that holds each, and its nodes' shape
functions there, so that any nodal field interpolates at the point (a reduced model's basis
on a display mesh, a cable's routing points, a fit's markers)."""
import numpy as np
from scipy.spatial import cKDTree

#: Tets whose centroids are nearest a point, tried first (doubled until one holds it).
CANDIDATES = 16

#: A point counts as inside a tet when its smallest barycentric coordinate is at least
#: -TOLERANCE (points on a face or a little outside a curved surface's facets).
TOLERANCE = 1e-6


def locate(mesh, points):
    """(tets (p,) int64, weights (p, 4)): for each rest point (p, 3), m, the tet of mesh holding
    it and its barycentric coordinates there. Raises ValueError naming the first point that no
    tet holds (within TOLERANCE)."""
    points = np.asarray(points, dtype=float)
    X = mesh.vertices[mesh.tets]
    tree = cKDTree(X.mean(axis=1))
    found = np.full(points.shape[0], -1)
    weights = np.zeros((points.shape[0], 4))
    todo = np.arange(points.shape[0])
    k = min(CANDIDATES, mesh.n_tets)
    while todo.size:
        _, near = tree.query(points[todo], k=k)
        near = near.reshape(todo.size, -1)                              # (t, k)
        xi = np.einsum("tkij,tkj->tki", mesh.inverse_jacobians[near],
                       points[todo, None, :] - X[near, 0])
        lam = np.concatenate([1.0 - xi.sum(axis=2, keepdims=True), xi], axis=2)
        best = lam.min(axis=2).argmax(axis=1)
        rows = np.arange(todo.size)
        inside = lam[rows, best].min(axis=1) >= -TOLERANCE
        found[todo[inside]] = near[rows, best][inside]
        weights[todo[inside]] = lam[rows, best][inside]
        todo = todo[~inside]
        if todo.size and k == mesh.n_tets:
            raise ValueError(f"points: point {todo[0]} at {points[todo[0]].tolist()} m lies in "
                             f"no tet of the mesh (not the same body?)")
        k = min(2 * k, mesh.n_tets)
    return found, weights


def node_weights(mesh, points):
    """(nodes (p, k) int64, weights (p, k)): each rest point (p, 3), m, as a weighted sum of
    the k nodes of mesh's element holding it (the element's shape functions there), so that
    any nodal field u interpolates there as sum_a weights[:, a] u[nodes[:, a]]."""
    tets, weights = locate(mesh, points)
    return mesh.cells[tets], mesh.element.shape(weights[:, 1:])    # shapes at xi = L_1..3
