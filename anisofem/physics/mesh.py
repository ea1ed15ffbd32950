"""The tetrahedral mesh: validated rest geometry, topology and element coloring."""
import warnings
from functools import cached_property

import numpy as np
from numba import njit

from .._validate import as_float_array, as_index_array
from .elements.tet4 import TET4
from .elements.tet10 import EDGES, TET10, quadratic_nodes

#: Tets per assembly block: the parallel assembly runs the blocks of one color on all threads
#: at once, each block's tets in order on one thread (anisofem.physics.kernels). Runs of consecutive
#: tets keep what a thread reads and adds to close together: on 2 cores the 10^5-tet Hessian
#: assembled in 25-29 ms this way against 100 ms with tets colored one by one (every color
#: spread over the whole mesh) and 57 ms on one thread (docs/experiments.md).
ASSEMBLY_BLOCK = 512

#: A quadratic tet's midside node within this share of its edge's length of the edge's
#: midpoint is at it; a tet with one farther is curved (isoparametric: its Jacobian taken at
#: each quadrature point).
MIDSIDE_TOLERANCE = 1e-6

#: Midside nodes of a tet whose vertices 2 and 3 are swapped, by their old places (4 to 9):
#: the edges (0,1), (1,3), (0,3), (0,2), (1,2), (3,2) of the old labels.
_SWAPPED_MIDSIDES = [4, 8, 7, 6, 5, 9]

#: The faces of a tet, opposite to its vertices 0 to 3, each ordered so that its normal points
#: out of a positively oriented tet.
TET_FACES = np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]])

#: A rest tet is rejected as zero-volume when 6 |V| / l_max^3 is below this (l_max: its
#: longest edge; 0.707 for a regular tet). Nearly flat elements above it are accepted.
MIN_SHAPE_QUALITY = 1e-9


class TetMesh:
    """Tetrahedral mesh in its rest configuration: linear (4-node) or quadratic (10-node,
    straight-sided) tets.

    Parameters
    ----------
    vertices : (n, 3) float array, rest positions in m (of every node: a quadratic mesh's
        midside nodes are vertices too).
    tets : (m, 4) integer array of vertex indices, or (m, 10) for quadratic tets: the four
        corners, then the midside nodes of the edges (0,1), (1,2), (0,2), (0,3), (1,3), (2,3)
        (VTK's and meshio's tetra10 order), each at its edge's midpoint and shared by every
        tet of the edge. Each tet must be positively oriented: det([X1-X0, X2-X0, X3-X0]) > 0.
    fix_orientation : True (default): negatively oriented tets are reordered (two vertices
        swapped: the same element, labelled the other way round, as export/runtime.py reads
        it); False: they are an error.
    unreferenced : what to do with vertices that no tet uses: "warn" (default: keep them; a
        Scene holds them in place, they carry no mass), "drop" (remove them and renumber;
        ``kept_vertices`` maps new to old indices) or "error".

    Attributes: tets (m, 4) the corners; cells (m, 4 or 10) every node of each tet; order (1
    or 2); element (anisofem.physics.elements' TET4 or TET10).

    Raises ValueError / TypeError naming the problem: wrong shapes or dtypes, NaN or inf,
    indices out of range, repeated vertices in a tet, duplicate tets, zero-volume tets,
    inverted ones with fix_orientation=False, and for quadratic tets midside nodes off their
    edge's midpoint or not shared along an edge.
    """

    def __init__(self, vertices, tets, *, fix_orientation=True, unreferenced="warn"):
        vertices = as_float_array(vertices, "vertices", shape=(None, 3))
        cells = as_index_array(tets, "tets", shape=(None, None))
        if cells.shape[1] not in (4, 10):
            raise ValueError(f"tets: expected (m, 4) linear or (m, 10) quadratic (tetra10) "
                             f"tets, got shape {cells.shape}")
        tets = cells
        n = vertices.shape[0]
        if tets.shape[0] == 0:
            raise ValueError("tets: the mesh has no tetrahedra")
        if tets.min() < 0 or tets.max() >= n:
            bad = np.flatnonzero((tets < 0).any(1) | (tets >= n).any(1))
            raise ValueError(f"tets: vertex index out of range [0, {n}) in tet(s) "
                             f"{bad[:5].tolist()}")
        srt = np.sort(tets, axis=1)
        rep = np.flatnonzero((srt[:, 1:] == srt[:, :-1]).any(1))
        if rep.size:
            raise ValueError(f"tets: tet(s) {rep[:5].tolist()} repeat a vertex (zero volume)")
        _, first, counts = np.unique(srt[:, :4] if tets.shape[1] == 4 else np.sort(
            tets[:, :4], axis=1), axis=0, return_index=True, return_counts=True)
        if (counts > 1).any():
            dup = np.sort(first[counts > 1])
            raise ValueError(f"tets: duplicate tets (same four vertices), e.g. tet(s) "
                             f"{dup[:5].tolist()} appear more than once")
        used = np.zeros(n, bool)
        used[tets.ravel()] = True
        if not used.all():
            missing = np.flatnonzero(~used)
            if unreferenced == "drop":
                new_index = np.cumsum(used) - 1
                tets = new_index[tets]
                vertices = vertices[used]
            elif unreferenced == "error":
                raise ValueError(f"vertices: {missing.size} vertices are used by no tet, e.g. "
                                 f"{missing[:5].tolist()}")
            elif unreferenced == "warn":
                warnings.warn(f"vertices: {missing.size} vertices are used by no tet (e.g. "
                              f"{missing[:5].tolist()}); a Scene holds them in place. Pass "
                              f"unreferenced='drop' to remove them.", stacklevel=2)
            else:
                raise ValueError(f"unreferenced: expected 'warn', 'drop' or 'error', got "
                                 f"{unreferenced!r}")
        self.kept_vertices = np.flatnonzero(used) if unreferenced == "drop" else None
        self.unreferenced = np.flatnonzero(~used) if unreferenced != "drop" else np.empty(0, int)
        cells, tets = tets, np.ascontiguousarray(tets[:, :4])
        six_vol = _six_volumes(vertices, tets)
        edges = vertices[tets[:, [1, 2, 3, 2, 3, 3]]] - vertices[tets[:, [0, 0, 0, 1, 1, 2]]]
        lmax = np.sqrt((edges ** 2).sum(-1).max(1))
        quality = six_vol / lmax ** 3
        flat = np.flatnonzero(np.abs(quality) < MIN_SHAPE_QUALITY)
        if flat.size:
            raise ValueError(f"tets: {flat.size} tet(s) have zero rest volume (6|V|/l^3 < "
                             f"{MIN_SHAPE_QUALITY:g}), e.g. {flat[:5].tolist()}")
        inverted = np.flatnonzero(quality < 0)
        if inverted.size:
            if not fix_orientation:
                raise ValueError(f"tets: {inverted.size} tet(s) are inverted (negative "
                                 f"orientation), e.g. {inverted[:5].tolist()}; reorder them or "
                                 f"pass fix_orientation=True")
            cells = cells.copy()
            cells[inverted, 2], cells[inverted, 3] = cells[inverted, 3], cells[inverted, 2].copy()
            if cells.shape[1] == 10:
                cells[inverted, 4:] = cells[inverted][:, _SWAPPED_MIDSIDES]
            tets = np.ascontiguousarray(cells[:, :4])
        #: whether some quadratic tet's midside node is off its edge's middle (isoparametric)
        self.curved = cells.shape[1] == 10 and _check_midsides(vertices, cells)
        for arr in (vertices, tets, cells):
            arr.setflags(write=False)
        self.vertices = vertices
        self.tets = tets
        self.cells = cells
        self.order = 1 if cells.shape[1] == 4 else 2
        self.element = TET4 if self.order == 1 else TET10
        if self.curved:
            _check_jacobians(self)

    def __repr__(self):
        kind = "" if self.order == 1 else " quadratic"
        return f"TetMesh({self.n_vertices} vertices, {self.n_tets}{kind} tets)"

    def raised(self):
        """This mesh with quadratic tets: a node at the middle of every edge, shared by the
        edge's tets (a quadratic mesh is returned as it is)."""
        if self.order == 2:
            return self
        nodes, cells = quadratic_nodes(self.vertices, self.tets)
        return TetMesh(nodes, cells, fix_orientation=False)

    def refined(self):
        """This linear mesh with every tet split into eight (Bey's red refinement: new vertices
        at the edge midpoints, the inner octahedron cut along one diagonal). The vertices keep
        their indices; the midpoints follow. (Refine a linear mesh, then raise it, for a finer
        quadratic one.)"""
        if self.order != 1:
            raise ValueError("refined: this mesh has quadratic tets; refine the linear mesh, "
                             "then raise it")
        nodes, cells = quadratic_nodes(self.vertices, self.tets)
        v0, v1, v2, v3, m01, m12, m02, m03, m13, m23 = cells.T
        children = np.array([[v0, m01, m02, m03], [m01, v1, m12, m13], [m02, m12, v2, m23],
                             [m03, m13, m23, v3], [m01, m02, m03, m13], [m01, m02, m12, m13],
                             [m02, m03, m13, m23], [m02, m12, m13, m23]])   # (8, 4, m)
        return TetMesh(nodes, children.transpose(2, 0, 1).reshape(-1, 4))

    def edge_nodes(self, pairs):
        """(k,) the midside nodes of a quadratic mesh's edges given as vertex pairs (k, 2)
        (either order); ValueError for a pair that is no edge of the mesh."""
        if self.order != 2:
            raise ValueError("edge_nodes: a linear mesh has no midside nodes")
        keys, nodes = self._edge_table
        pairs = np.sort(np.asarray(pairs, dtype=np.int64), axis=1)
        wanted = pairs[:, 0] * self.n_vertices + pairs[:, 1]
        at = np.minimum(np.searchsorted(keys, wanted), keys.size - 1)
        if not np.array_equal(keys[at], wanted):
            bad = pairs[np.flatnonzero(keys[at] != wanted)[0]]
            raise ValueError(f"pairs: {bad.tolist()} is not an edge of the mesh")
        return nodes[at]

    @property
    def midside_edges(self):
        """(nodes (e,), ends (e, 2)): each midside node of a quadratic mesh and the two corners
        of its edge."""
        if self.order != 2:
            raise ValueError("midside_edges: a linear mesh has no midside nodes")
        keys, nodes = self._edge_table
        return nodes, np.stack([keys // self.n_vertices, keys % self.n_vertices], axis=1)

    @cached_property
    def _edge_table(self):
        """(keys, nodes): every edge's key i n + j (i < j), sorted, and its midside node."""
        pairs = np.sort(self.cells[:, EDGES], axis=2).reshape(-1, 2)
        keys = pairs[:, 0] * self.n_vertices + pairs[:, 1]
        keys, first = np.unique(keys, return_index=True)
        return keys, self.cells[:, 4:].ravel()[first]

    @property
    def n_vertices(self):
        return self.vertices.shape[0]

    @property
    def n_tets(self):
        return self.tets.shape[0]

    @cached_property
    def rest_volumes(self):
        """(m,) rest volume of each tet, m^3 (of a curved one, its quadrature's: exact, det J
        being cubic in the reference coordinates)."""
        if self.curved:
            return self.point_weights.sum(axis=1)
        return _six_volumes(self.vertices, self.tets) / 6.0

    @cached_property
    def point_weights(self):
        """(m, q) each tet's quadrature weights times its volume element, m^3: the element's
        weights times the rest volume, or on curved tets times det J / 6 at each point."""
        if self.curved:
            return self.element.weights * np.linalg.det(self.point_jacobians) / 6.0
        return self.rest_volumes[:, None] * self.element.weights

    @cached_property
    def point_jacobians(self):
        """(m, q, 3, 3) dX/dxi at each tet's quadrature points (isoparametric: X(xi) =
        sum_a X_a N_a(xi); constant Dm on a straight-sided tet)."""
        return np.einsum("eai,pak->epik", self.vertices[self.cells],
                         self.element.point_gradients)

    @cached_property
    def shape_gradients(self):
        """(m, 4, 3) material gradients of the four linear shape functions, 1/m.

        Row a is grad N_a; the deformation gradient is F = sum_a x_a grads[a]^T.
        """
        return np.einsum("ak,ekj->eaj", TET4.point_gradients[0], self.inverse_jacobians)

    @cached_property
    def point_gradients(self):
        """(m, q, k, 3) material gradients of each tet's k shape functions at its element's q
        quadrature points, 1/m (straight-sided tets: Dm^-1 maps them from the reference tet;
        curved ones: each point's (dX/dxi)^-1). F at point p is sum_a x_a grads[p, a]^T."""
        if self.curved:
            return np.einsum("pak,epkj->epaj", self.element.point_gradients,
                             np.linalg.inv(self.point_jacobians))
        return np.einsum("pak,ekj->epaj", self.element.point_gradients,
                         self.inverse_jacobians)

    @cached_property
    def inverse_jacobians(self):
        """(m, 3, 3) Dm^-1, Dm the columns X_1 - X_0, X_2 - X_0, X_3 - X_0 of each tet: row k is
        the material gradient of the reference coordinate xi_k (anisofem.physics.elements), 1/m."""
        X = self.vertices[self.tets]
        Dm = np.stack([X[:, 1] - X[:, 0], X[:, 2] - X[:, 0], X[:, 3] - X[:, 0]], axis=2)
        return np.linalg.inv(Dm)

    @cached_property
    def edges(self):
        """(k, 2) unique undirected tet edges, sorted pairs (i < j), sorted lexicographically."""
        pairs = self.tets[:, [0, 0, 0, 1, 1, 2, 1, 2, 3, 2, 3, 3]].reshape(-1, 2, 6)
        pairs = np.stack([pairs[:, 0].ravel(), pairs[:, 1].ravel()], axis=1)
        pairs.sort(axis=1)
        return np.unique(pairs, axis=0)

    @property
    def boundary_faces(self):
        """(k, 3) boundary triangles, ordered so that their normal points out of the mesh."""
        return self._boundary[0]

    @cached_property
    def _boundary(self):
        """(boundary faces (k, 3) ordered outward, the tet (k,) each bounds)."""
        faces = self.tets[:, TET_FACES].reshape(-1, 3)
        key = np.sort(faces, axis=1)
        _, inverse, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
        at = np.flatnonzero(counts[inverse.ravel()] == 1)
        return faces[at], at // 4

    def find_boundary_faces(self, faces, name):
        """(the faces (k, 3) as the boundary faces they name, ordered outward; the tet (k,)
        each bounds) of vertex triples `faces` (k, 3) in any order; ValueError naming `name`
        and the first that is no boundary face of the mesh."""
        oriented, owners = self._boundary
        table = {tuple(k): i for i, k in enumerate(np.sort(oriented, axis=1).tolist())}
        found = []
        for i, f in enumerate(np.sort(faces, axis=1).tolist()):
            if tuple(f) not in table:
                raise ValueError(f"{name}: face {i} {faces[i].tolist()} is not a boundary face "
                                 f"of the mesh")
            found.append(table[tuple(f)])
        return oriented[found], owners[found]

    def faces_where(self, predicate):
        """Boundary faces whose centroid c (k, 3) satisfies predicate(c) -> (k,) bool."""
        faces = self.boundary_faces
        mask = np.asarray(predicate(self.vertices[faces].mean(axis=1)), dtype=bool)
        if mask.shape != (faces.shape[0],):
            raise ValueError(f"predicate: must return a ({faces.shape[0]},) bool array, "
                             f"got shape {mask.shape}")
        return faces[mask]

    @cached_property
    def coloring(self):
        """(starts, ptr): the assembly blocks (runs of ASSEMBLY_BLOCK consecutive tets, the
        last one shorter) grouped by color, no two blocks of a color sharing a vertex. Color
        c holds the blocks that start at tets starts[ptr[c]:ptr[c+1]]."""
        return block_coloring(self.tets, self.n_vertices)

    @property
    def size(self):
        """Diagonal of the rest bounding box, m."""
        return float(np.linalg.norm(self.vertices.max(0) - self.vertices.min(0)))


def _check_midsides(vertices, cells):
    """Whether some midside node of the quadratic tets cells (m, 10) is off its edge's midpoint
    (by more than MIDSIDE_TOLERANCE of the edge's length: a curved tet); ValueError unless
    every midside node is no tet's corner and is the one node of its edge in every tet sharing
    it."""
    ends = cells[:, EDGES]                                          # (m, 6, 2)
    X = vertices[ends]
    length = np.linalg.norm(X[:, :, 1] - X[:, :, 0], axis=2)
    off = np.linalg.norm(vertices[cells[:, 4:]] - X.mean(axis=2), axis=2) / length
    curved = bool((off > MIDSIDE_TOLERANCE).any())
    corners = np.isin(cells[:, 4:], cells[:, :4])
    if corners.any():
        e, k = np.argwhere(corners)[0]
        raise ValueError(f"tets: the midside node {cells[e, 4 + k]} of tet {e} is a corner of "
                         f"another tet")
    pairs = np.sort(ends, axis=2).reshape(-1, 2)
    mids = cells[:, 4:].ravel()
    order = np.lexsort((mids, pairs[:, 1], pairs[:, 0]))
    pairs, mids = pairs[order], mids[order]
    same_edge = (pairs[1:] == pairs[:-1]).all(axis=1)
    clash = np.flatnonzero(same_edge & (mids[1:] != mids[:-1]))
    if clash.size:
        i = clash[0]
        raise ValueError(f"tets: the edge {pairs[i].tolist()} has two midside nodes, "
                         f"{mids[i]} and {mids[i + 1]}, in the tets that share it")
    return curved


def _check_jacobians(mesh):
    """ValueError naming a curved tet whose map from the reference tet folds or flattens:
    det dX/dxi at a quadrature point or a corner at most MIN_SHAPE_QUALITY times its corners'
    straight tet's."""
    corners = mesh.element.shape_gradients(mesh.element.nodes[:4])         # (4, 10, 3)
    J = np.concatenate([mesh.point_jacobians, np.einsum(
        "eai,pak->epik", mesh.vertices[mesh.cells], corners)], axis=1)
    straight = _six_volumes(mesh.vertices, mesh.tets)
    ratio = np.linalg.det(J) / straight[:, None]
    bad = np.argwhere(ratio <= MIN_SHAPE_QUALITY)
    if bad.size:
        e, p = bad[0]
        where = (f"quadrature point {p}" if p < mesh.element.weights.size
                 else f"corner {p - mesh.element.weights.size}")
        raise ValueError(f"tets: curved tet {e} is {'inverted' if ratio[e, p] < 0 else 'flat'} "
                         f"at its {where} (det dX/dxi {ratio[e, p]:.3g} of its straight tet's; "
                         f"{np.unique(bad[:, 0]).size} such tets): its midside nodes fold it")


def _six_volumes(vertices, tets):
    X = vertices[tets]
    a, b, c = X[:, 1] - X[:, 0], X[:, 2] - X[:, 0], X[:, 3] - X[:, 0]
    return np.einsum("ij,ij->i", a, np.cross(b, c))


def block_coloring(tets, n_vertices):
    """(starts, ptr) of TetMesh.coloring for the corners tets (m, 4) of any set of tets over
    n_vertices vertices."""
    colors = _greedy_block_colors(tets, n_vertices, ASSEMBLY_BLOCK)
    order = np.argsort(colors, kind="stable")
    ptr = np.searchsorted(colors[order], np.arange(colors.max() + 2))
    return (order * ASSEMBLY_BLOCK).astype(np.int64), ptr.astype(np.int64)


@njit(cache=True)
def _greedy_block_colors(tets, n_vertices, block):
    """Color the blocks of `block` consecutive tets so that blocks sharing a vertex differ:
    each block takes the smallest color free at all its vertices. (blocks,) int64."""
    m = tets.shape[0]
    blocks = (m + block - 1) // block
    # vertex -> incident blocks, with repeats (CSR over the tets' vertex slots)
    count = np.zeros(n_vertices + 1, np.int64)
    for e in range(m):
        for a in range(4):
            count[tets[e, a] + 1] += 1
    ptr = np.cumsum(count)
    fill = ptr[:-1].copy()
    inc = np.empty(ptr[-1], np.int64)
    for e in range(m):
        for a in range(4):
            v = tets[e, a]
            inc[fill[v]] = e // block
            fill[v] += 1
    colors = -np.ones(blocks, np.int64)
    taken = np.full(blocks + 1, -1, np.int64)  # taken[c] == b: a neighbour of b has color c
    for b in range(blocks):
        for e in range(b * block, min(m, (b + 1) * block)):
            for a in range(4):
                v = tets[e, a]
                for k in range(ptr[v], ptr[v + 1]):
                    c = colors[inc[k]]
                    if c >= 0:
                        taken[c] = b
        c = 0
        while taken[c] == b:
            c += 1
        colors[b] = c
    return colors
