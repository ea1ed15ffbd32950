"""Torch-free pieces of the anisognn graph: the constant mesh tensors the network reads.

This file imports only numpy (and, for stepping an exported model, onnxruntime), so that a user
can copy it next to model.onnx. anisognn builds its graphs with these same functions, so the
trained model and the exported one cannot disagree about what a graph is.

Graph of a tet mesh with n vertices (all arrays are numpy; float32 unless said):

- undirected edges: the unique tet edges (k, 2) int64, pairs i < j, sorted.
- directed edges, E = 2 k: edge e goes from senders[e] to receivers[e]; edges 0..k-1 are
  (i -> j), edges k..2k-1 the reverses (j -> i).
- rest features (E, 4): unit rest vector u = (X_s - X_r) / |X_s - X_r| and the rest length
  |X_s - X_r| (m).
- directional weights (E, 3): u itself (paper eq. 4: w_k = u . e_k). Signed: an edge and its
  reverse carry opposite weights.
- fiber features (E, 3): kappa_e d_e where, over the tets sharing the edge, T = mean of
  kappa d d^T (Pa), kappa_e its largest eigenvalue and d_e the unit eigenvector (averaging
  d d^T cannot cancel, and d and -d are one fiber). The sign of d_e is fixed by the fiber alone:
  d_e . r >= 0 with the reference direction r = (1, sqrt 2, sqrt 3) / sqrt 6, so an edge and its
  reverse carry the same feature, a uniform fiber gives every edge the same feature, and
  relabeling the vertices changes nothing (only fibers almost orthogonal to r, which no
  axis-aligned or 45-degree fiber is, sit on the sign flip).
- incoming table (n, K) int64: the edges received by each vertex, padded with the index E
  (a padding edge whose latent features are zero); K is the largest in-degree.
- incoming weights (n, K, 3): the directional weights of those edges, 0 at padding.
"""
import numpy as np

#: Fiber features of edges whose tets have no fiber are 0; below this kappa (Pa) a fiber is
#: treated as absent when choosing its direction.
FIBER_EPS = 1e-12


def _tet_edges(tets):
    """(m, 6, 2) int64 vertex pairs of the six edges of each tet, each pair sorted."""
    tets = np.asarray(tets, dtype=np.int64)
    return np.sort(tets[:, [[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3]]], axis=2)


def mesh_edges(tets):
    """(k, 2) int64 unique undirected edges (i < j, sorted) of tets (m, 4)."""
    return np.unique(_tet_edges(tets).reshape(-1, 2), axis=0)


def directed_edges(edges):
    """(senders, receivers), each (2k,) int64: the k edges i -> j, then their reverses."""
    return (np.concatenate([edges[:, 0], edges[:, 1]]),
            np.concatenate([edges[:, 1], edges[:, 0]]))


def rest_features(vertices, senders, receivers):
    """(E, 4) float64: unit rest vectors (X_s - X_r)/|.| and rest lengths (m)."""
    vec = vertices[senders] - vertices[receivers]
    length = np.linalg.norm(vec, axis=1, keepdims=True)
    return np.concatenate([vec / length, length], axis=1)


#: the reference direction that fixes the sign of fiber features
FIBER_REFERENCE = np.array([1.0, np.sqrt(2.0), np.sqrt(3.0)]) / np.sqrt(6.0)


def edge_fibers(tets, edges, fiber_direction, fiber_stiffness):
    """(E, 3) float64 fiber features kappa_e d_e of the directed edges (see module docstring).

    tets (m, 4); edges (k, 2) undirected; fiber_direction (m, 3) unit; fiber_stiffness (m,) Pa.
    """
    k = edges.shape[0]
    tensor = np.einsum("m,mi,mj->mij", fiber_stiffness, fiber_direction, fiber_direction)
    ends = _tet_edges(tets)
    # the index of each tet edge among the unique (sorted) edges
    base = int(tets.max()) + 1
    index = np.searchsorted(edges[:, 0] * base + edges[:, 1], ends[..., 0] * base + ends[..., 1])
    total = np.zeros((k, 3, 3))
    np.add.at(total, index.ravel(), np.repeat(tensor, 6, axis=0))
    total /= np.bincount(index.ravel(), minlength=k)[:, None, None]
    values, vectors = np.linalg.eigh(total)
    kappa, d = np.maximum(values[:, 2], 0.0), vectors[:, :, 2]
    d *= np.where(d @ FIBER_REFERENCE < 0, -1.0, 1.0)[:, None]
    feature = np.where((kappa > FIBER_EPS)[:, None], kappa[:, None] * d, 0.0)
    return np.concatenate([feature, feature])


def incoming_table(receivers, n_vertices):
    """(n, K) int64 indices of the edges each vertex receives, padded with E = len(receivers)."""
    n_edges = receivers.shape[0]
    order = np.argsort(receivers, kind="stable")
    counts = np.bincount(receivers, minlength=n_vertices)
    width = max(int(counts.max()) if n_vertices else 0, 1)
    start = np.concatenate([[0], np.cumsum(counts)[:-1]])
    slot = np.arange(n_edges) - np.repeat(start, counts)
    table = np.full((n_vertices, width), n_edges, dtype=np.int64)
    table[receivers[order], slot] = order
    return table


def incoming_weights(table, weights):
    """(n, K, 3) weights of the incoming edges (0 at padding); weights (E, 3)."""
    padded = np.concatenate([weights, np.zeros((1, weights.shape[1]))])
    return padded[table]
