"""The 10-node quadratic tetrahedron (straight-sided): the four vertices, then the midpoints of
the edges (0,1), (1,2), (0,2), (0,3), (1,3), (2,3) (VTK's and meshio's tetra10 order).

In barycentric coordinates L (L_0 = 1 - xi_1 - xi_2 - xi_3, L_k = xi_k):
vertex a: N_a = L_a (2 L_a - 1); edge (i, j): N = 4 L_i L_j.

F is linear in a straight-sided element, so Saint Venant-Kirchhoff and fiber energies are
quartic there, and so are the integrands of their gradients and Hessians: a rule exact to
degree 4 with positive weights integrates them exactly and keeps a per-point PSD projection
PSD. The 14-point rule exact to degree 5 (Walkington, "Quadrature on simplices of arbitrary
dimension", 2000; all weights positive, all points inside) is used.
"""
import numpy as np

from . import Element

#: The edges of the midside nodes 4 to 9, by vertex.
EDGES = np.array([[0, 1], [1, 2], [0, 2], [0, 3], [1, 3], [2, 3]])


def _barycentric(xi):
    xi = np.atleast_2d(np.asarray(xi, dtype=float))
    return np.column_stack([1.0 - xi.sum(1), xi])


#: d L_c / d xi (4, 3)
_DL = np.array([[-1.0, -1.0, -1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])


def _shape(xi):
    L = _barycentric(xi)
    return np.column_stack([L * (2.0 * L - 1.0), 4.0 * L[:, EDGES[:, 0]] * L[:, EDGES[:, 1]]])


def _shape_gradients(xi):
    L = _barycentric(xi)
    vertex = (4.0 * L - 1.0)[:, :, None] * _DL[None]
    i, j = EDGES[:, 0], EDGES[:, 1]
    edge = 4.0 * (L[:, i, None] * _DL[None, j] + L[:, j, None] * _DL[None, i])
    return np.concatenate([vertex, edge], axis=1)


def _points_and_weights():
    """Walkington's degree-5 rule: four points (a, a, a, 1 - 3a) for each of two a, six points
    (b, b, 1/2 - b, 1/2 - b) (barycentric, all permutations); weights per reference volume."""
    L, w = [], []
    for a, weight in ((0.0927352503108912, 0.01224884051939366),
                      (0.3108859192633006, 0.01878132095300264)):
        for k in range(4):
            point = np.full(4, a)
            point[k] = 1.0 - 3.0 * a
            L.append(point)
            w.append(weight)
    b = 0.4544962958743504
    for i, j in EDGES:
        point = np.full(4, 0.5 - b)
        point[[i, j]] = b
        L.append(point)
        w.append(0.007091003462846911)
    w = np.array(w)
    return np.array(L)[:, 1:], w / w.sum()


_points, _weights = _points_and_weights()

_vertices = np.eye(4)[:, 1:]
TET10 = Element(name="tet10", cell_type="tetra10",
                nodes=np.vstack([_vertices, 0.5 * (_vertices[EDGES[:, 0]]
                                                   + _vertices[EDGES[:, 1]])]),
                shape=_shape, shape_gradients=_shape_gradients,
                points=_points, weights=_weights)


def quadratic_nodes(vertices, tets):
    """Raise a linear mesh to quadratic tets by shared edge midpoints.

    vertices (n, 3) m, tets (m, 4): returns nodes (n + e, 3), the vertices followed by the
    midpoints of the e unique edges (sorted vertex pairs, lexicographic), and tets10 (m, 10) in
    this element's node order."""
    tets = np.asarray(tets)
    pairs = np.sort(tets[:, EDGES], axis=2)  # (m, 6, 2)
    edges, index = np.unique(pairs.reshape(-1, 2), axis=0, return_inverse=True)
    nodes = np.vstack([vertices, 0.5 * (vertices[edges[:, 0]] + vertices[edges[:, 1]])])
    tets10 = np.hstack([tets, vertices.shape[0] + index.reshape(-1, 6)])
    return nodes, tets10
