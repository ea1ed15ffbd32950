"""Linear solvers for Newton's symmetric systems H p = -g.

Each solver is a class with `layout` ("dense" or "csr", the Hessian layout it reads) and
`factor(layout, data)` returning a function b -> H^-1 b, or raising FactorizationError when
the matrix is singular or (for Cholesky) not positive definite.

- "dense":   LAPACK Cholesky (scipy.linalg.cho_factor); fastest below about 10^3 unknowns.
- "superlu": scipy's SuperLU with the minimum-degree ordering on A^T + A and diagonal
             pivoting. With a symmetric permutation and diagonal pivots, U's diagonal is D of
             A = L D L^T, so its signs give the inertia: like Cholesky, the factorization is
             refused unless the matrix is positive definite (Newton then knows to project).
             scipy's default (COLAMD ordering, partial pivoting, no definiteness check) is kept
             as "superlu-colamd" for comparison.
- "cholmod": CHOLMOD sparse Cholesky from scikit-sparse, used only if it is installed.
- "auto":    dense up to DENSE_MAX unknowns, then cholmod if importable, else superlu.
"""
import numpy as np
import scipy.linalg
import scipy.sparse as sp
import scipy.sparse.linalg as spla

#: "auto" uses dense Cholesky up to this many unknowns.
DENSE_MAX = 450


class FactorizationError(RuntimeError):
    """The matrix could not be factored (singular, or not positive definite for Cholesky)."""


class DenseCholesky:
    layout = "dense"

    def factor(self, layout, data):
        try:
            c = scipy.linalg.cho_factor(layout.matrix(data), overwrite_a=True, check_finite=False)
        except np.linalg.LinAlgError as err:
            raise FactorizationError(str(err)) from None
        return lambda b: scipy.linalg.cho_solve(c, b, check_finite=False)


def _csc(layout, data):
    # H is symmetric, so its CSR arrays read as CSC describe the same matrix
    return sp.csc_matrix((data, layout.indices, layout.indptr), shape=layout.shape)


class SuperLU:
    layout = "csr"

    def __init__(self, ordering="MMD_AT_PLUS_A", symmetric=True):
        self.ordering = ordering
        self.symmetric = symmetric

    def factor(self, layout, data):
        kwargs = {"permc_spec": self.ordering}
        if self.symmetric:
            kwargs.update(diag_pivot_thresh=0.0, options={"SymmetricMode": True})
        try:
            lu = spla.splu(_csc(layout, data), **kwargs)
        except RuntimeError as err:
            raise FactorizationError(str(err)) from None
        if self.symmetric:
            if not np.array_equal(lu.perm_r, lu.perm_c):
                raise FactorizationError("superlu: off-diagonal pivoting (matrix indefinite)")
            if not (lu.U.diagonal() > 0).all():
                raise FactorizationError("superlu: matrix not positive definite")
        return lu.solve


class Cholmod:
    layout = "csr"

    def __init__(self):
        from sksparse.cholmod import cholesky  # optional dependency
        self._cholesky = cholesky

    def factor(self, layout, data):
        try:
            return self._cholesky(_csc(layout, data))
        except Exception as err:  # CholmodNotPositiveDefiniteError and friends
            raise FactorizationError(str(err)) from None


def cholmod_available():
    try:
        import sksparse.cholmod  # noqa: F401
    except ImportError:
        return False
    return True


NAMES = ("auto", "dense", "superlu", "superlu-colamd", "cholmod")


def make(name, n_unknowns):
    """The solver called `name` (see NAMES) for a system of n_unknowns."""
    if name == "auto":
        if n_unknowns <= DENSE_MAX:
            name = "dense"
        else:
            name = "cholmod" if cholmod_available() else "superlu"
    if name == "dense":
        return DenseCholesky()
    if name == "superlu":
        return SuperLU()
    if name == "superlu-colamd":
        return SuperLU("COLAMD", symmetric=False)
    if name == "cholmod":
        if not cholmod_available():
            raise ValueError("linear_solver: 'cholmod' needs scikit-sparse (pip install "
                             "scikit-sparse)")
        return Cholmod()
    raise ValueError(f"linear_solver: expected one of {NAMES}, got {name!r}")
