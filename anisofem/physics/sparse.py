"""Sparse matrix-vector products on numba's threads, the block size compiled in: the
operations of the "cg" method's iterations and of its multigrid V-cycle
(anisofem.solvers.multigrid). scipy's products run on one core. A matrix with fewer than
PARALLEL_MIN_ENTRIES stored entries is multiplied on the calling thread alone (a coarse multigrid
level, a small mesh), a larger one on anisofem.threads.parallel_threads()."""
import functools

import numba as nb
import numpy as np
import scipy.sparse as sp

from ..threads import parallel_threads

#: Stored entries below which a product runs on one thread, launching none: at 7,839 entries
#: (the 200-tet Hessian) 2 threads save 1 us of 10 on an idle machine, at 49,293 16 us of 40.
PARALLEL_MIN_ENTRIES = 20000


class SparseOperator:
    """A sparse matrix for products on numba's threads, in BSR (a CSR matrix is BSR with 1 x 1
    blocks): indptr and indices (unsigned: numba checks signed indices for negative,
    wrap-around values), blocks (nnzb, R, C) in float32 or float64, and shape."""

    def __init__(self, indptr, indices, blocks, shape):
        self.indptr, self.indices = indptr, indices
        self.blocks, self.shape = blocks, shape
        self.parallel = blocks.size >= PARALLEL_MIN_ENTRIES
        self._kernel = _combine_kernel(blocks.shape[1], blocks.shape[2], self.parallel)

    @classmethod
    def of(cls, M, dtype=np.float32):
        """The operator of the scipy sparse matrix M, its entries in dtype."""
        if not (sp.issparse(M) and M.format == "bsr"):
            M = sp.bsr_matrix(sp.csr_matrix(M), blocksize=(1, 1))
        return cls(M.indptr.astype(np.uint32), M.indices.astype(np.uint32),
                   M.data.astype(dtype), M.shape)

    def __matmul__(self, v):
        return self.combine(v)

    def combine(self, v, alpha=1.0, w=None):
        """alpha M v + w ((rows,), in the operator's dtype); w (rows,) None for none."""
        out = np.empty(self.shape[0], dtype=self.blocks.dtype)
        add = w is not None
        if self.parallel:
            parallel_threads()
        self._kernel(self.indptr, self.indices, self.blocks, v, alpha, out if w is None else w,
                     add, out)
        return out


@functools.cache
def _combine_kernel(rows, cols, parallel):
    """The numba kernel out = alpha A v (+ w if add) for A in BSR with rows x cols blocks
    (indptr, indices, blocks (nnzb, rows, cols)), the block size compiled in: with the
    loops' lengths known the compiler unrolls them, 2.5-3.5x faster at 6 x 6 and 6 x 1
    blocks than the same loops over a runtime size. Sums in float64. parallel: rows on numba's
    threads, else on the calling thread (the loop function is part of the closure, so numba's
    cache keeps the two apart)."""
    loop = nb.prange if parallel else range
    if rows == 1:
        @nb.njit(parallel=parallel, cache=True)
        def kernel(indptr, indices, blocks, v, alpha, w, add, out):
            data = blocks.reshape(blocks.shape[0], cols)
            for i in loop(len(indptr) - 1):
                s = 0.0
                for k in range(indptr[i], indptr[i + 1]):
                    base = indices[k] * cols
                    for c in range(cols):
                        s += data[k, c] * v[base + c]
                out[i] = alpha * s + w[i] if add else alpha * s
        return kernel

    @nb.njit(parallel=parallel, cache=True)
    def kernel(indptr, indices, blocks, v, alpha, w, add, out):
        for row_block in loop(len(indptr) - 1):
            s = np.zeros(rows)
            for k in range(indptr[row_block], indptr[row_block + 1]):
                base = indices[k] * cols
                for r in range(rows):
                    for c in range(cols):
                        s[r] += blocks[k, r, c] * v[base + c]
            for r in range(rows):
                i = row_block * rows + r
                out[i] = alpha * s[r] + w[i] if add else alpha * s[r]
    return kernel
