"""Linear solvers for Newton's symmetric systems H p = -g.

Each solver is a class with `layout` ("dense", "banded" or "csr", the Hessian layout it reads),
`factor(layout, data)` returning a function b -> H^-1 b, or raising FactorizationError when
the matrix is singular or (for Cholesky) not positive definite, and `threads()`, the context
a Newton solve runs its factorizations in.

- "dense":   LAPACK Cholesky (potrf/potrs called directly: scipy.linalg.cho_factor's checks
             and copies cost more than the factorization of a 135-unknown system), with one
             BLAS thread: OpenBLAS' threads make these small factorizations slower
             (`python -m anisofem bench` measures both).
- "banded":  LAPACK banded Cholesky (pbtrf/pbtrs) in the reverse Cuthill-McKee order of the
             unknowns (anisofem.physics.assembly.BandedLayout). On the 100-tet beam the band has 47
             subdiagonals for 135 unknowns and the factorization takes 2/3 to 3/4 of the
             one-thread dense one's time (`python -m anisofem bench` prints both); it runs
             under the default BLAS threads.
- "superlu": scipy's SuperLU with the minimum-degree ordering on A^T + A and diagonal
             pivoting. With a symmetric permutation and diagonal pivots, U's diagonal is D of
             A = L D L^T, so its signs give the inertia: like Cholesky, the factorization is
             refused unless the matrix is positive definite (Newton then knows to project).
             scipy's default (COLAMD ordering, partial pivoting, no definiteness check) is kept
             as "superlu-colamd" for comparison.
- "cholmod": CHOLMOD sparse Cholesky from scikit-sparse, used only if it is installed.
- "auto":    banded up to BANDED_MAX unknowns, then cholmod if importable, else superlu.
"""
import contextlib
import functools

import numpy as np
import scipy.linalg
import scipy.sparse as sp
import scipy.sparse.linalg as spla

#: "auto" uses the banded Cholesky up to this many unknowns.
BANDED_MAX = 450


class FactorizationError(RuntimeError):
    """The matrix could not be factored (singular, or not positive definite for Cholesky)."""


_POTRF, _POTRS, _PBTRF, _PBTRS = scipy.linalg.lapack.get_lapack_funcs(
    ("potrf", "potrs", "pbtrf", "pbtrs"), dtype=np.float64)


@functools.cache
def _blas_libraries():
    """threadpoolctl's controllers of the loaded BLAS libraries (found once per process)."""
    from threadpoolctl import ThreadpoolController
    return ThreadpoolController().select(user_api="blas").lib_controllers


@contextlib.contextmanager
def one_blas_thread():
    """Context with every loaded BLAS library on one thread. Besides small factorizations, it
    serves loops that mix numpy's vector products with numba's parallel assembly: after a BLAS
    call OpenBLAS' idle threads spin for a while, and on 2 cores an assembly that starts then
    runs 2-4x slower (10^5 tets: energy and gradient 45 against 11 ms, Hessian 140 against
    70 ms)."""
    # cheaper than threadpoolctl's limit(), which re-reads every library's info (~40 us)
    libs = _blas_libraries()
    before = [lib.get_num_threads() for lib in libs]
    for lib in libs:
        lib.set_num_threads(1)
    try:
        yield
    finally:
        for lib, n in zip(libs, before):
            lib.set_num_threads(n)


class _SolverBase:
    def threads(self):
        """Context in which this solver's factorizations run (default: unchanged)."""
        return contextlib.nullcontext()


def _not_definite(name, info):
    return FactorizationError(f"{name}: leading minor {info} is not positive definite"
                              if info > 0 else f"{name}: LAPACK info {info}")


class DenseCholesky(_SolverBase):
    layout = "dense"

    def threads(self):
        return one_blas_thread()

    def factor(self, layout, data, coupled=None):
        """Factors in place: data is overwritten. coupled: a sparse matrix added first."""
        if coupled is not None:
            layout.matrix(data)[...] += coupled.toarray()
        # the matrix is symmetric, so the transposed view is its Fortran-ordered self
        c, info = _POTRF(layout.matrix(data).T, lower=True, overwrite_a=True, clean=False)
        if info != 0:
            raise _not_definite("dense Cholesky", info)
        return lambda b: _POTRS(c, b, lower=True)[0]


class BandedCholesky(_SolverBase):
    layout = "banded"

    def factor(self, layout, data, coupled=None):
        """Factors in place: data is overwritten. coupled: must be None (no band holds it)."""
        if coupled is not None:
            raise FactorizationError("banded Cholesky: couplings outside the band")
        c, info = _PBTRF(layout.band(data), lower=1, overwrite_ab=1)
        if info != 0:
            raise _not_definite("banded Cholesky", info)
        perm = layout.perm

        def solve(b):
            x = np.empty_like(b)
            x[perm] = _PBTRS(c, b[perm], lower=1)[0]
            return x
        return solve


def _csc(layout, data, coupled=None):
    # H is symmetric, so its CSR arrays read as CSC describe the same matrix
    H = sp.csc_matrix((data, layout.indices, layout.indptr), shape=layout.shape)
    return H if coupled is None else (H + coupled).tocsc()


class SuperLU(_SolverBase):
    layout = "csr"

    def __init__(self, ordering="MMD_AT_PLUS_A", symmetric=True):
        self.ordering = ordering
        self.symmetric = symmetric

    def factor(self, layout, data, coupled=None):
        kwargs = {"permc_spec": self.ordering}
        if self.symmetric:
            kwargs.update(diag_pivot_thresh=0.0, options={"SymmetricMode": True})
        try:
            lu = spla.splu(_csc(layout, data, coupled), **kwargs)
        except RuntimeError as err:
            raise FactorizationError(str(err)) from None
        if self.symmetric:
            if not np.array_equal(lu.perm_r, lu.perm_c):
                raise FactorizationError("superlu: off-diagonal pivoting (matrix indefinite)")
            if not (lu.U.diagonal() > 0).all():
                raise FactorizationError("superlu: matrix not positive definite")
        return lu.solve


class Cholmod(_SolverBase):
    layout = "csr"

    def __init__(self):
        from sksparse.cholmod import cholesky  # optional dependency
        self._cholesky = cholesky

    def factor(self, layout, data, coupled=None):
        try:
            # supernodal is LL^T and refuses an indefinite matrix; "auto" may pick the
            # simplicial LDL^T, which factors indefinite matrices without complaint
            return self._cholesky(_csc(layout, data, coupled), mode="supernodal")
        except Exception as err:  # CholmodNotPositiveDefiniteError and friends
            raise FactorizationError(str(err)) from None


def cholmod_available():
    try:
        import sksparse.cholmod  # noqa: F401
    except ImportError:
        return False
    return True


NAMES = ("auto", "banded", "dense", "superlu", "superlu-colamd", "cholmod")


def make(name, n_unknowns, coupled=False):
    """The solver called `name` (see NAMES) for a system of n_unknowns; coupled: the system
    couples nodes no element joins (self-contact, surface obstacles), which no band holds."""
    if name == "banded" and coupled:
        raise ValueError("linear_solver: 'banded' cannot hold the couplings of self-contact "
                         "and surface obstacles; use 'superlu', 'cholmod' or 'dense'")
    if name == "auto":
        if n_unknowns <= BANDED_MAX and not coupled:
            name = "banded"
        else:
            name = "cholmod" if cholmod_available() else "superlu"
    if name == "banded":
        return BandedCholesky()
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
