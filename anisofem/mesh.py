"""The tetrahedral mesh: validated rest geometry, topology and element coloring."""
import warnings
from functools import cached_property

import numpy as np
from numba import njit

from ._validate import as_float_array, as_index_array
from .elements.tet4 import TET4

#: Tets per assembly block: the parallel assembly runs the blocks of one color on all threads
#: at once, each block's tets in order on one thread (anisofem.kernels). Runs of consecutive
#: tets keep what a thread reads and adds to close together: on 2 cores the 10^5-tet Hessian
#: assembled in 25-29 ms this way against 100 ms with tets colored one by one (every color
#: spread over the whole mesh) and 57 ms on one thread (docs/experiments.md).
ASSEMBLY_BLOCK = 512

#: A rest tet is rejected as zero-volume when 6 |V| / l_max^3 is below this (l_max: its
#: longest edge; 0.707 for a regular tet). Nearly flat elements above it are accepted.
MIN_SHAPE_QUALITY = 1e-9


class TetMesh:
    """Linear tetrahedral mesh in its rest configuration.

    Parameters
    ----------
    vertices : (n, 3) float array, rest positions in m.
    tets : (m, 4) integer array of vertex indices. Each tet must be positively oriented:
        det([X1-X0, X2-X0, X3-X0]) > 0.
    fix_orientation : True (default): negatively oriented tets are reordered (two vertices
        swapped: the same element, labelled the other way round, as export/runtime.py reads
        it); False: they are an error.
    unreferenced : what to do with vertices that no tet uses: "warn" (default: keep them; a
        Scene holds them in place, they carry no mass), "drop" (remove them and renumber;
        ``kept_vertices`` maps new to old indices) or "error".

    Raises ValueError / TypeError naming the problem: wrong shapes or dtypes, NaN or inf,
    indices out of range, repeated vertices in a tet, duplicate tets, zero-volume tets, and
    inverted ones with fix_orientation=False.
    """

    def __init__(self, vertices, tets, *, fix_orientation=True, unreferenced="warn"):
        vertices = as_float_array(vertices, "vertices", shape=(None, 3))
        tets = as_index_array(tets, "tets", shape=(None, 4))
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
        _, first, counts = np.unique(srt, axis=0, return_index=True, return_counts=True)
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
            tets = tets.copy()
            tets[inverted, 2], tets[inverted, 3] = tets[inverted, 3], tets[inverted, 2].copy()
        vertices.setflags(write=False)
        tets.setflags(write=False)
        self.vertices = vertices
        self.tets = tets

    def __repr__(self):
        return f"TetMesh({self.n_vertices} vertices, {self.n_tets} tets)"

    @property
    def n_vertices(self):
        return self.vertices.shape[0]

    @property
    def n_tets(self):
        return self.tets.shape[0]

    @cached_property
    def rest_volumes(self):
        """(m,) rest volume of each tet, m^3."""
        return _six_volumes(self.vertices, self.tets) / 6.0

    @cached_property
    def shape_gradients(self):
        """(m, 4, 3) material gradients of the four linear shape functions, 1/m.

        Row a is grad N_a; the deformation gradient is F = sum_a x_a grads[a]^T.
        """
        return np.einsum("ak,ekj->eaj", TET4.point_gradients[0], self.inverse_jacobians)

    @cached_property
    def inverse_jacobians(self):
        """(m, 3, 3) Dm^-1, Dm the columns X_1 - X_0, X_2 - X_0, X_3 - X_0 of each tet: row k is
        the material gradient of the reference coordinate xi_k (anisofem.elements), 1/m."""
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

    @cached_property
    def boundary_faces(self):
        """(k, 3) boundary triangles, ordered so that their normal points out of the mesh."""
        # faces opposite to vertex 0..3, each ordered outward for a positively oriented tet
        local = np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]])
        faces = self.tets[:, local].reshape(-1, 3)
        key = np.sort(faces, axis=1)
        _, inverse, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
        return faces[counts[inverse.ravel()] == 1]

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
        colors = _greedy_block_colors(self.tets, self.n_vertices, ASSEMBLY_BLOCK)
        order = np.argsort(colors, kind="stable")
        ptr = np.searchsorted(colors[order], np.arange(colors.max() + 2))
        return (order * ASSEMBLY_BLOCK).astype(np.int64), ptr.astype(np.int64)

    @property
    def size(self):
        """Diagonal of the rest bounding box, m."""
        return float(np.linalg.norm(self.vertices.max(0) - self.vertices.min(0)))


def _six_volumes(vertices, tets):
    X = vertices[tets]
    a, b, c = X[:, 1] - X[:, 0], X[:, 2] - X[:, 0], X[:, 3] - X[:, 0]
    return np.einsum("ij,ij->i", a, np.cross(b, c))


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
