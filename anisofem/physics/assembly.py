"""Sparsity patterns: where each entry of each element Hessian (3k x 3k for k nodes per
element) lands, built once per mesh and set of unknowns, so that assembly is a scatter-add into
a preallocated array. A layout may also hold couplings, groups of nodes that no element joins
(a cable's routing points in two tets): `positions(groups)` places their blocks."""
from functools import cached_property

import numpy as np
import scipy.sparse as sp
from numba import njit, prange
from scipy.sparse.csgraph import reverse_cuthill_mckee

from .sparse import SparseOperator


def unknown_dofs(dof_map):
    """(k,) flat DOF index (3 i + c) of each unknown, in unknown order."""
    flat = dof_map.ravel()
    valid = flat >= 0
    dofs = np.empty(int(valid.sum()), np.int64)
    dofs[flat[valid]] = np.flatnonzero(valid)
    return dofs


def element_dofs(tets, dof_map):
    """(m, 3k) unknown index of each element DOF (3 a + i) of elements with k nodes tets (m, k),
    -1 where the DOF is not unknown.

    dof_map: (n, 3) int64, the unknown index of each node component or -1.
    """
    return dof_map[tets].reshape(tets.shape[0], -1)


def _entry_dofs(tets, dof_map):
    """(k unknowns, rows (m, (3k)^2), cols (m, (3k)^2)): the unknowns of each element-matrix
    entry."""
    ed = element_dofs(tets, dof_map)
    width = ed.shape[1]
    return int(dof_map.max()) + 1, np.repeat(ed, width, axis=1), np.tile(ed, (1, width))


def _groups(tets, couplings):
    """The node groups a pattern joins: the elements (m, k), and the couplings (g, w) where
    given."""
    if couplings is None or len(couplings) == 0:
        return [tets]
    return [tets, np.ascontiguousarray(couplings, dtype=np.int64)]


def _position_type(largest):
    """int32 for positions up to `largest` where they fit (the element loop is compiled for
    one index type), else int64."""
    return np.int32 if largest < 2 ** 31 - 1 else np.int64


class CsrLayout:
    """CSR pattern of the Hessian restricted to the unknowns of dof_map (n, 3), whose numbers
    must rise with the vertex index (each row is searched in vertex order).

    Attributes: map (m, (3k)^2) position of element entry (r, c) in the CSR data, -1 where r
    or c is not unknown (int32 while the pattern has fewer than 2^31 entries, else int64); diag
    (k,) position of each diagonal entry; dofs (k,) flat DOF of each unknown; shape (k, k).

    Built from the vertex adjacency (the unique vertex pairs of the tets, m * 16 of them) and
    expanded to DOFs in numba, then each element entry is found by binary search in its row:
    linear in the mesh up to the sort of the vertex pairs (10^6 tets: seconds and about the
    memory of the map itself, where sorting the m * 144 DOF pairs took 39 s and 10 GB).
    """

    kind = "csr"

    def __init__(self, tets, dof_map, couplings=None):
        tets = np.ascontiguousarray(tets, dtype=np.int64)
        dof_map = np.ascontiguousarray(dof_map, dtype=np.int64)
        self._dof_map = dof_map
        n = dof_map.shape[0]
        k = int(dof_map.max()) + 1 if dof_map.size else 0
        pairs = np.unique(np.concatenate([(g[:, :, None] * n + g[:, None, :]).ravel()
                                          for g in _groups(tets, couplings)]))
        vertex_ptr = np.searchsorted(pairs // n, np.arange(n + 1)).astype(np.int64)
        neighbors = (pairs % n).astype(np.int64)
        del pairs
        row_length = _dof_row_lengths(vertex_ptr, neighbors, dof_map, k)
        nnz = int(row_length.sum())
        index = _position_type(nnz)
        self.indptr = np.zeros(k + 1, index)
        np.cumsum(row_length, out=self.indptr[1:])
        self.indices = np.empty(nnz, index)
        _fill_dof_rows(vertex_ptr, neighbors, dof_map, self.indptr, self.indices)
        self.map = np.empty((tets.shape[0], (3 * tets.shape[1]) ** 2), index)
        _element_positions(tets, dof_map, self.indptr, self.indices, self.map)
        self.diag = np.empty(k, np.int64)
        _diagonal_positions(self.indptr, self.indices, self.diag)
        self.shape = (k, k)
        self.dofs = unknown_dofs(dof_map)
        self.nnz = nnz

    def zeros(self):
        return np.zeros(self.nnz)

    def positions(self, groups):
        """(g, (3w)^2) the positions of the blocks of node groups (g, w) (couplings given to
        the layout, or nodes of one element), as map's rows."""
        groups = np.ascontiguousarray(groups, dtype=np.int64)
        out = np.empty((groups.shape[0], (3 * groups.shape[1]) ** 2), self.indices.dtype)
        _element_positions(groups, self._dof_map, self.indptr, self.indices, out)
        return out

    def matrix(self, data):
        """scipy.sparse.csr_matrix sharing data."""
        return sp.csr_matrix((data, self.indices, self.indptr), shape=self.shape, copy=False)

    def operator(self, data):
        """anisofem.physics.sparse.SparseOperator sharing data: products on all threads."""
        return SparseOperator(*self._unsigned, data.reshape(-1, 1, 1), self.shape)

    @cached_property
    def _unsigned(self):
        """(indptr, indices) as the unsigned indices SparseOperator's kernels read fastest."""
        return self.indptr.astype(np.uint32), self.indices.astype(np.uint32)


@njit(cache=True)
def _dof_row_lengths(vertex_ptr, neighbors, dof_map, k):
    """(k,) entries of each unknown's row: the unknowns of its vertex's neighbors."""
    out = np.zeros(k, np.int64)
    for p in range(dof_map.shape[0]):
        count = 0
        for j in range(vertex_ptr[p], vertex_ptr[p + 1]):
            for c in range(3):
                count += dof_map[neighbors[j], c] >= 0
        for i in range(3):
            if dof_map[p, i] >= 0:
                out[dof_map[p, i]] = count
    return out


@njit(cache=True)
def _fill_dof_rows(vertex_ptr, neighbors, dof_map, indptr, indices):
    """The column indices of each unknown's row, ascending (unknowns are numbered in vertex
    order and neighbors are sorted)."""
    for p in range(dof_map.shape[0]):
        for i in range(3):
            r = dof_map[p, i]
            if r < 0:
                continue
            pos = indptr[r]
            for j in range(vertex_ptr[p], vertex_ptr[p + 1]):
                for c in range(3):
                    col = dof_map[neighbors[j], c]
                    if col >= 0:
                        indices[pos] = col
                        pos += 1


@njit(cache=True, inline="always")
def _find(indptr, indices, r, c):
    """Position of column c in row r (binary search; the entry exists)."""
    lo, hi = indptr[r], indptr[r + 1]
    while lo < hi:
        mid = (lo + hi) // 2
        if indices[mid] < c:
            lo = mid + 1
        else:
            hi = mid
    return lo


@njit(cache=True, parallel=True)
def _element_positions(tets, dof_map, indptr, indices, out):
    """out[e, 3k r + c]: position of element entry (r, c) (r, c = 3 a + i, k nodes) in the CSR
    data, or -1 where its row or column is not unknown."""
    k = tets.shape[1]
    for e in prange(tets.shape[0]):
        for a in range(k):
            for i in range(3):
                row = dof_map[tets[e, a], i]
                for b in range(k):
                    for kk in range(3):
                        col = dof_map[tets[e, b], kk]
                        slot = 3 * k * (3 * a + i) + 3 * b + kk
                        out[e, slot] = -1 if row < 0 or col < 0 else _find(indptr, indices,
                                                                           row, col)


@njit(cache=True)
def _diagonal_positions(indptr, indices, out):
    for r in range(out.shape[0]):
        out[r] = _find(indptr, indices, r, r)


class DenseLayout:
    """Row-major dense k x k Hessian of the unknowns of dof_map (for small systems)."""

    kind = "dense"

    def __init__(self, tets, dof_map, couplings=None):
        self._dof_map = dof_map
        self.map = self.positions(tets)
        k = int(dof_map.max()) + 1 if dof_map.size else 0
        self.diag = np.arange(k, dtype=np.int64) * (k + 1)
        self.dofs = unknown_dofs(dof_map)
        self.shape = (k, k)

    def positions(self, groups):
        """(g, (3w)^2) the positions of the blocks of node groups (g, w), as map's rows."""
        k, rows, cols = _entry_dofs(groups, self._dof_map)
        return np.where((rows >= 0) & (cols >= 0), rows * k + cols,
                        -1).astype(_position_type(k * k))

    def zeros(self):
        return np.zeros(self.shape[0] * self.shape[1])

    def matrix(self, data):
        """(k, k) ndarray view of data."""
        return data.reshape(self.shape)


class BandedLayout:
    """LAPACK lower band storage of the Hessian of the unknowns of dof_map, in the reverse
    Cuthill-McKee order of the unknowns (which keeps the band narrow on beams).

    Attributes: perm (k,) unknown at each banded position; kd the number of subdiagonals;
    map (m, (3k)^2) position of element entry (r, c) in the (kd + 1, k) column-major band, -1
    where r or c is not unknown or the entry lies above the diagonal (the band holds the lower
    triangle: band[i - j, j] = H[i, j] for i >= j, in banded positions); diag (k,) position of
    each unknown's diagonal entry; dofs (k,) flat DOF of each unknown; shape (k, k).
    """

    kind = "banded"

    def __init__(self, tets, dof_map, couplings=None):
        entries = [_entry_dofs(g, dof_map) for g in _groups(tets, couplings)]
        k = entries[0][0]
        rows = np.concatenate([e[1][(e[1] >= 0) & (e[2] >= 0)] for e in entries])
        cols = np.concatenate([e[2][(e[1] >= 0) & (e[2] >= 0)] for e in entries])
        graph = sp.csr_matrix((np.ones(rows.size), (rows, cols)), shape=(k, k))
        self.perm = reverse_cuthill_mckee(graph, symmetric_mode=True).astype(np.int64)
        self._position = np.empty(k, np.int64)
        self._position[self.perm] = np.arange(k)
        self._dof_map = dof_map
        pr, pc = self._position[rows], self._position[cols]
        self.kd = int((pr - pc).max()) if pr.size else 0
        self.map = self.positions(tets)
        self.diag = self._position * (self.kd + 1)
        self.dofs = unknown_dofs(dof_map)
        self.shape = (k, k)

    def positions(self, groups):
        """(g, (3w)^2) the positions of the blocks of node groups (g, w) in the band, as map's
        rows."""
        k, rows, cols = _entry_dofs(groups, self._dof_map)
        valid = (rows >= 0) & (cols >= 0)
        out = np.full(rows.shape, -1, _position_type((self.kd + 1) * k))
        pr, pc = self._position[rows[valid]], self._position[cols[valid]]
        out[valid] = np.where(pr >= pc, (pr - pc) + pc * (self.kd + 1), -1)
        return out

    def zeros(self):
        return np.zeros((self.kd + 1) * self.shape[0])

    def band(self, data):
        """(kd + 1, k) column-major view of data, as LAPACK's pbtrf reads it."""
        return data.reshape((self.kd + 1, self.shape[0]), order="F")

    def matrix(self, data):
        """scipy.sparse.csr_matrix of the Hessian in unknown order (a copy; for inspection)."""
        band = self.band(data)
        offset, col = np.nonzero(band)
        row, values = self.perm[col + offset], band[offset, col]
        col = self.perm[col]
        off = offset > 0  # mirror the strictly lower entries
        return sp.csr_matrix((np.concatenate([values, values[off]]),
                              (np.concatenate([row, col[off]]), np.concatenate([col, row[off]]))),
                             shape=self.shape)
