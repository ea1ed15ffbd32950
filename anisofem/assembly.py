"""Sparsity patterns: where each entry of each 12x12 element Hessian lands, built once per mesh
and set of unknowns, so that assembly is a scatter-add into a preallocated array."""
import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import reverse_cuthill_mckee


def unknown_dofs(dof_map):
    """(k,) flat DOF index (3 i + c) of each unknown, in unknown order."""
    flat = dof_map.ravel()
    valid = flat >= 0
    dofs = np.empty(int(valid.sum()), np.int64)
    dofs[flat[valid]] = np.flatnonzero(valid)
    return dofs


def element_dofs(tets, dof_map):
    """(m, 12) unknown index of each element DOF (3 a + i), -1 where the DOF is not unknown.

    dof_map: (n, 3) int64, the unknown index of each vertex component or -1.
    """
    return dof_map[tets].reshape(tets.shape[0], 12)


def _entry_dofs(tets, dof_map):
    """(k unknowns, rows (m, 144), cols (m, 144)): the unknowns of each element-matrix entry."""
    ed = element_dofs(tets, dof_map)
    return int(dof_map.max()) + 1, np.repeat(ed, 12, axis=1), np.tile(ed, (1, 12))


class CsrLayout:
    """CSR pattern of the Hessian restricted to the unknowns of dof_map.

    Attributes: map (m, 144) int64 position of element entry (r, c) in the CSR data, -1 where
    r or c is not unknown; diag (k,) position of each diagonal entry; dofs (k,) flat DOF of
    each unknown; shape (k, k).
    """

    kind = "csr"

    def __init__(self, tets, dof_map):
        k, rows, cols = _entry_dofs(tets, dof_map)
        valid = (rows >= 0) & (cols >= 0)
        keys = rows.astype(np.int64) * k + cols
        unique, inverse = np.unique(keys[valid], return_inverse=True)
        self.map = np.full(keys.shape, -1, np.int64)
        self.map[valid] = inverse.ravel()
        self.indices = (unique % k).astype(np.int32)
        row_of = unique // k
        self.indptr = np.searchsorted(row_of, np.arange(k + 1)).astype(np.int32)
        self.diag = np.searchsorted(unique, np.arange(k, dtype=np.int64) * (k + 1))
        self.shape = (k, k)
        self.dofs = unknown_dofs(dof_map)
        self.nnz = unique.size

    def zeros(self):
        return np.zeros(self.nnz)

    def matrix(self, data):
        """scipy.sparse.csr_matrix sharing data."""
        return sp.csr_matrix((data, self.indices, self.indptr), shape=self.shape, copy=False)


class DenseLayout:
    """Row-major dense k x k Hessian of the unknowns of dof_map (for small systems)."""

    kind = "dense"

    def __init__(self, tets, dof_map):
        k, rows, cols = _entry_dofs(tets, dof_map)
        self.map = np.where((rows >= 0) & (cols >= 0), rows * k + cols, -1).astype(np.int64)
        self.diag = np.arange(k, dtype=np.int64) * (k + 1)
        self.dofs = unknown_dofs(dof_map)
        self.shape = (k, k)

    def zeros(self):
        return np.zeros(self.shape[0] * self.shape[1])

    def matrix(self, data):
        """(k, k) ndarray view of data."""
        return data.reshape(self.shape)


class BandedLayout:
    """LAPACK lower band storage of the Hessian of the unknowns of dof_map, in the reverse
    Cuthill-McKee order of the unknowns (which keeps the band narrow on beams).

    Attributes: perm (k,) unknown at each banded position; kd the number of subdiagonals;
    map (m, 144) position of element entry (r, c) in the (kd + 1, k) column-major band, -1
    where r or c is not unknown or the entry lies above the diagonal (the band holds the lower
    triangle: band[i - j, j] = H[i, j] for i >= j, in banded positions); diag (k,) position of
    each unknown's diagonal entry; dofs (k,) flat DOF of each unknown; shape (k, k).
    """

    kind = "banded"

    def __init__(self, tets, dof_map):
        k, rows, cols = _entry_dofs(tets, dof_map)
        valid = (rows >= 0) & (cols >= 0)
        graph = sp.csr_matrix((np.ones(int(valid.sum())), (rows[valid], cols[valid])),
                              shape=(k, k))
        self.perm = reverse_cuthill_mckee(graph, symmetric_mode=True).astype(np.int64)
        position = np.empty(k, np.int64)
        position[self.perm] = np.arange(k)
        pr, pc = position[rows[valid]], position[cols[valid]]
        self.kd = int((pr - pc).max()) if pr.size else 0
        self.map = np.full(rows.shape, -1, np.int64)
        self.map[valid] = np.where(pr >= pc, (pr - pc) + pc * (self.kd + 1), -1)
        self.diag = position * (self.kd + 1)
        self.dofs = unknown_dofs(dof_map)
        self.shape = (k, k)

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
