"""Smoothed-aggregation algebraic multigrid: the preconditioner of the "cg" method's
preconditioner="amg", the rung for large meshes (no factorization, memory linear in the mesh).

The hierarchy is pyamg's: aggregation by strength of connection, prolongators smoothed by
Jacobi, Galerkin coarse operators R A P, with the six rigid-body modes as the near-null space
(without them smoothed aggregation is a poor elasticity preconditioner: 350-425 CG iterations
on the 10^5-tet cantilever, against 79 with them). The V-cycle is this module's: numba
kernels on every core (anisofem.physics.sparse), in float32. A preconditioner needs no more digits
(conjugate gradients, in float64, correct what it leaves): at 10^5 tets the float32 V-cycle
took 12 ms against 14-15 ms for the same kernels in float64, with the same 56 CG iterations to
1e-8; pyamg's own V-cycle, float64 on one core, took 28-33 ms (docs/experiments.md).

Quadratic tets get one geometric level first: their space holds the linear tets' on the same
corners exactly (a midside node takes the mean of its edge's ends), so the V-cycle smooths the
quadratic system and hands its residual to the linear tets' Galerkin operator P^T A P, whose
smoothed-aggregation hierarchy is built as above (p-multigrid).
"""
import contextlib
from types import SimpleNamespace

import numba as nb
import numpy as np
import scipy.sparse as sp

from ..physics.sparse import SparseOperator

#: The V-cycle's smoothers: on the finest level one forward Gauss-Seidel sweep before the
#: coarse correction and one backward sweep after it (the pair keeps the V-cycle symmetric,
#: as conjugate gradients need); on the coarser levels, whose aggregated operators hold more
#: nonzeros than the finest (six modes per aggregate), a degree-3 Chebyshev polynomial in A,
#: cheaper there than Gauss-Seidel sweeps and parallel. The polynomial targets the spectrum
#: [rho / CHEBYSHEV_LOWER, CHEBYSHEV_UPPER rho] of each level's A (rho: its spectral radius,
#: estimated by pyamg), pyamg's defaults.
CHEBYSHEV_DEGREE = 3
CHEBYSHEV_LOWER, CHEBYSHEV_UPPER = 30.0, 1.1

#: Strength of connection per level (pyamg's; the last serves the coarser levels). Every
#: connection counts on the finest level. The aggregated second level couples each node to
#: about 50 others, and aggregating all of them made 60-node aggregates and a 156-unknown third
#: level at 10^5 tets, which left the intermediate scales to the smoother; dropping the
#: connections |a_ij| < 0.02 sqrt(|a_ii a_jj|) there gives a 366-unknown third level: 42
#: against 54 CG iterations to 1e-8, backward-Euler steps 12-17% faster (docs/experiments.md).
STRENGTH = (("symmetric", {"theta": 0.0}), ("symmetric", {"theta": 0.02}))

#: The hierarchy coarsens until a level has at most this many nodes (pyamg's max_coarse: on
#: the aggregated levels a node holds the six modes), whose matrix is then solved densely
#: (pseudo-inverse). At 500 the coarsest levels had up to 2,916 unknowns (10^6 tets) and
#: 1,128 (10^4), whose dense pseudo-inverse took seconds per hierarchy: static solves 0.8
#: against 1.8 s at 10^4 tets and 121 against 155 s at 10^6.
COARSEST = 100


def rigid_body_modes(x, free):
    """(k, 6) translations and infinitesimal rotations (about the centroid, which conditions
    them better than the origin) of positions x (n, 3), restricted to the free DOFs free (k,)
    (flat indices 3 i + c)."""
    n = x.shape[0]
    modes = np.zeros((3 * n, 6))
    for c in range(3):
        modes[c::3, c] = 1.0
    centered = x - x.mean(axis=0)
    for k, (a, b) in enumerate(((0, 1), (1, 2), (2, 0))):
        modes[a::3, 3 + k] = -centered[:, b]
        modes[b::3, 3 + k] = centered[:, a]
    return modes[free]


def hierarchy(A, near_null):
    """pyamg's smoothed-aggregation hierarchy of the symmetric positive definite sparse A
    (m, m) with near_null (m, k) as the near-null space, without smoothers (VCycle brings
    its own)."""
    import pyamg
    with _seeded():
        return pyamg.smoothed_aggregation_solver(sp.csr_matrix(A), B=near_null,
                                                 symmetry="symmetric", max_coarse=COARSEST,
                                                 strength=list(STRENGTH), presmoother=None,
                                                 postsmoother=None)


def preconditioner(A, near_null, nested=None):
    """r -> M^-1 r (float64 (m,) in and out) for the symmetric positive definite sparse A:
    one V-cycle of its hierarchy (see hierarchy and VCycle). nested: a sparse prolongation
    (m, c) from a nested coarser space (corner_prolongation) whose Galerkin operator gets the
    hierarchy; near_null (c, k) is then that space's."""
    if nested is None:
        return VCycle(hierarchy(A, near_null).levels)
    P = sp.csr_matrix(nested)
    R = P.T.tocsr()
    coarse = hierarchy((R @ A @ P).tocsr(), near_null)
    return VCycle([SimpleNamespace(A=sp.csr_matrix(A), P=P, R=R)] + coarse.levels)


def corner_prolongation(mesh, free_dofs):
    """(P, corner_dofs) of a quadratic mesh: P (k, c) sparse interpolates the linear tets' field
    on its corners, given at the free corner DOFs corner_dofs (c,), to the free DOFs free_dofs
    (k,) (flat indices 3 i + d): a corner keeps its value, a midside node takes the mean of its
    edge's ends."""
    corners = np.unique(mesh.tets)
    column = np.full(mesh.n_vertices, -1)
    column[corners] = np.arange(corners.size)
    mids, ends = mesh.midside_edges
    rows = np.concatenate([corners, mids, mids])
    cols = column[np.concatenate([corners, ends[:, 0], ends[:, 1]])]
    vals = np.concatenate([np.ones(corners.size), np.full(2 * mids.size, 0.5)])
    nodal = sp.csr_matrix((vals, (rows, cols)), shape=(mesh.n_vertices, corners.size))
    dofs = sp.kron(nodal, sp.identity(3), format="csr")
    corner_dofs = (3 * corners[:, None] + np.arange(3)).ravel()
    free = np.zeros(3 * mesh.n_vertices, bool)
    free[free_dofs] = True
    keep = free[corner_dofs]
    return dofs[free_dofs][:, np.flatnonzero(keep)], corner_dofs[keep]


@contextlib.contextmanager
def _seeded():
    """numpy's global random state seeded, and restored after: pyamg estimates spectral
    radii (of the prolongator smoother and the Chebyshev polynomials) from random start
    vectors, and seeded estimates make every solve repeat exactly."""
    state = np.random.get_state()
    np.random.seed(0)
    try:
        yield
    finally:
        np.random.set_state(state)


class VCycle:
    """One V-cycle from zero of the levels of a hierarchy (pyamg's levels: each level's A, P
    and R, the last level's A alone), with this module's smoothers, in float32 on numba's
    threads: call it with a right-hand side b (m,) to get the approximate solution (m,) in
    float64."""

    def __init__(self, levels):
        from pyamg.relaxation.chebyshev import chebyshev_polynomial_coefficients
        from pyamg.util.linalg import approximate_spectral_radius
        self.operators, self.prolongators, self.restrictors, self.smoothers = [], [], [], []
        for k, level in enumerate(levels[:-1]):
            self.operators.append(SparseOperator.of(level.A))
            self.prolongators.append(SparseOperator.of(level.P))
            self.restrictors.append(SparseOperator.of(level.R))
            if k == 0:
                self.smoothers.append(None)  # Gauss-Seidel
            else:
                with _seeded():
                    rho = approximate_spectral_radius(level.A)  # cached on level.A
                self.smoothers.append(-chebyshev_polynomial_coefficients(
                    rho / CHEBYSHEV_LOWER, rho * CHEBYSHEV_UPPER,
                    CHEBYSHEV_DEGREE)[:-1].astype(np.float32))
        coarsest = levels[-1].A.toarray()
        self.coarse_inverse = np.linalg.pinv(coarsest).astype(np.float32)
        self._diagonal = levels[0].A.diagonal().astype(np.float32)

    def __call__(self, b):
        return self._cycle(0, np.asarray(b, dtype=np.float32)).astype(np.float64)

    def _cycle(self, k, b):
        """The V-cycle's approximate solution (float32) on level k for right-hand side b."""
        if k == len(self.operators):
            return self.coarse_inverse @ b
        A = self.operators[k]
        x = self._smooth(k, b, None, forward=True)
        residual = A.combine(x, -1.0, b)                         # b - A x
        correction = self._cycle(k + 1, self.restrictors[k].combine(residual))
        x = self.prolongators[k].combine(correction, 1.0, x)    # x + P e
        return self._smooth(k, b, x, forward=False)

    def _smooth(self, k, b, x, forward):
        """Level k's smoother for A x = b from x (None: from zero), forward (the
        presmoother) or backward (the postsmoother): the improved x."""
        A, coefficients = self.operators[k], self.smoothers[k]
        if coefficients is None:
            x = np.zeros_like(b) if x is None else x
            _gauss_seidel(A.indptr, A.indices, A.blocks.reshape(-1), self._diagonal, x, b,
                          forward)
            return x
        residual = b if x is None else A.combine(x, -1.0, b)
        h = coefficients[0] * residual
        for c in coefficients[1:]:
            h = A.combine(h, 1.0, c * residual)                  # c r + A h
        return h if x is None else x + h


@nb.njit(cache=True)
def _gauss_seidel(indptr, indices, data, diagonal, x, b, forward):
    """One Gauss-Seidel sweep on A x = b in place, A in CSR with its diagonal, rows in order
    (forward) or in reverse."""
    n = len(x)
    for t in range(n):
        i = t if forward else n - 1 - t
        s = b[i] * 1.0
        for k in range(indptr[i], indptr[i + 1]):
            s -= data[k] * x[indices[k]]
        x[i] += s / diagonal[i]
