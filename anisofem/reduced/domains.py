"""A body cut into domains, each of which a framed reduced model (anisofem.reduced.framed)
moves in its own rotating frame: bands of distance from the held vertices, through the mesh,
each band cut into its connected pieces. A T or a Y splits at its junction by itself: past
it, the band's vertices fall into one piece per arm.

    labels, count = split(scene, bands=3)    # labels (n,): -1 held, else 0 .. count - 1
"""
import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components, dijkstra

#: A domain with fewer vertices than this is merged into the neighbour it shares the most
#: edges with: a frame needs a few points off one plane, and a local basis some room.
MIN_VERTICES = 8


def edge_graph(mesh):
    """The mesh's nodes joined where they share an element, weighted by their rest distance, m:
    a symmetric scipy CSR (n, n). Quadratic tets join their midside nodes too."""
    x = mesh.vertices
    n = x.shape[0]
    cells = mesh.cells
    k = cells.shape[1]
    pairs = np.vstack([cells[:, [i, j]] for i in range(k) for j in range(i + 1, k)])
    pairs = np.unique(np.sort(pairs, axis=1), axis=0)
    length = np.linalg.norm(x[pairs[:, 0]] - x[pairs[:, 1]], axis=1)
    graph = sp.coo_matrix((length, (pairs[:, 0], pairs[:, 1])), shape=(n, n)).tocsr()
    return graph + graph.T


def held_distance(scene, graph=None):
    """(n,) each node's distance from the nearest held vertex through the mesh, m; -1 for nodes
    no element holds (they are held in place)."""
    graph = edge_graph(scene.mesh) if graph is None else graph
    held = np.flatnonzero(scene.fixed_mask.any(axis=1))
    distance = dijkstra(graph, directed=False, indices=held, min_only=True)
    distance[~np.isfinite(distance)] = -1.0
    return distance


def split(scene, bands):
    """Labels (n,) int of the scene's nodes: -1 for held nodes (and nodes no element holds),
    else their domain, 0 .. count - 1, and count. The free nodes fall into `bands` equal bands
    of held_distance, each band into its connected pieces; pieces under MIN_VERTICES nodes are
    merged into a neighbour."""
    graph = edge_graph(scene.mesh)
    distance = held_distance(scene, graph)
    held = scene.fixed_mask.any(axis=1) | (distance < 0)
    band = np.minimum((distance / distance.max() * bands).astype(int), bands - 1)
    labels = np.full(distance.size, -1)
    count = 0
    for b in range(bands):
        nodes = np.flatnonzero((band == b) & ~held)
        if nodes.size:
            pieces, piece = connected_components(graph[nodes][:, nodes], directed=False)
            labels[nodes] = piece + count
            count += pieces
    return _merge_small(labels, graph)


def _merge_small(labels, graph):
    """labels with each domain of fewer than MIN_VERTICES nodes merged into the domain it
    shares the most edges with (smallest first), renumbered 0 .. count - 1; and count."""
    coo = graph.tocoo()
    while True:
        sizes = np.bincount(labels[labels >= 0])
        small = [d for d in np.argsort(sizes) if 0 < sizes[d] < MIN_VERTICES]
        if not small or (sizes > 0).sum() == 1:
            break
        d = small[0]
        a, b = labels[coo.row], labels[coo.col]
        across = (a == d) & (b >= 0) & (b != d)
        if not across.any():
            break
        labels[labels == d] = np.bincount(b[across]).argmax()
    kept = np.unique(labels[labels >= 0])
    renumber = np.full(labels.max() + 2, -1)
    renumber[kept] = np.arange(kept.size)
    return renumber[labels], int(kept.size)


def tree(scene, labels):
    """The domains' kinematic tree: parent (count,) int, each domain's neighbour nearer the held
    nodes through the mesh (-1: the held nodes), and pivot (count, 3), m, the rest centroid of
    the nodes on either side of the interface with the parent (where a turn of the domain
    leaves the joint in place). The parent is the neighbour (domain or held) with the least
    mean held_distance below the domain's own; parents come before their children in
    `order` (count,), returned third."""
    graph = edge_graph(scene.mesh)
    distance = held_distance(scene, graph)
    count = int(labels.max()) + 1
    mean = np.array([distance[labels == d].mean() for d in range(count)])
    coo = graph.tocoo()
    a, b = labels[coo.row], labels[coo.col]
    x = scene.mesh.vertices
    parent = np.full(count, -1)
    pivot = np.empty((count, 3))
    for d in range(count):
        across = (a == d) & (b != d)
        near = {int(e) for e in np.unique(b[across]) if e < 0 or mean[e] < mean[d]}
        if near - {-1}:
            parent[d] = min(near - {-1}, key=lambda e: mean[e])
        elif -1 not in near:  # no neighbour nearer the held nodes: the domain's own centroid
            pivot[d] = x[labels == d].mean(axis=0)
            continue
        side = across & (b == parent[d])
        pivot[d] = x[np.union1d(coo.row[side], coo.col[side])].mean(axis=0)
    order, placed = [], np.zeros(count, bool)
    while len(order) < count:
        for d in range(count):
            if not placed[d] and (parent[d] < 0 or placed[parent[d]]):
                order.append(d)
                placed[d] = True
    return parent, pivot, np.array(order, np.int64)
