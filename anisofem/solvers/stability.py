"""Whether a state is a minimum of its potential or a saddle: the smallest eigenpair of the
Hessian of G over the free components (the true Hessian, not its PSD projection).

The verdict (stability) first factors the Hessian: where it is positive definite (the
factorization with its definiteness check succeeds, anisofem.solvers.linsolve "superlu"), the state
is a minimum, and the smallest eigenvalue comes from Lanczos on the inverse (shift-invert about
0: a few iterations). Otherwise the most negative eigenpair comes from Lanczos on the Hessian
itself (ARPACK through scipy; negative_curvature), started from a given vector or a fixed
pseudo-random one, so that a solve is repeatable.

Newton uses negative_curvature (anisofem.solvers.methods.Newton): where the true Hessian is
indefinite and the projected iterations stall, the eigenvector is a direction of negative curvature
to step along; and where a solve meets its tolerance at a state whose last true Hessian was
indefinite, a negative eigenvalue means a saddle, which the solve leaves along the eigenvector."""
import math
from dataclasses import dataclass

import numpy as np
import scipy.sparse.linalg as spla

from . import linsolve

#: an eigenvalue above -ROUNDOFF times the Hessian's largest diagonal entry counts as zero
ROUNDOFF = 1e-9
#: Lanczos restarts before the smallest eigenvalue is called unknown
MAX_LANCZOS = 5000
#: Hessians of fewer unknowns are decomposed densely (ARPACK wants more than its basis size)
DENSE_MAX = 16


@dataclass
class Stability:
    """smallest: the smallest eigenvalue of the free Hessian at the state, N/m (NaN where
    Lanczos did not converge); scale: the Hessian's largest diagonal entry, N/m; vector: the
    unit eigenvector (unknown order), None where Lanczos did not converge; definite: the
    Hessian factored as positive definite."""
    smallest: float
    scale: float
    vector: np.ndarray = None
    definite: bool = False

    @property
    def minimum(self):
        """A minimum, not a saddle: the Hessian is positive definite, or its smallest
        eigenvalue is above -ROUNDOFF times scale (zero to round-off)."""
        return self.definite or self.smallest >= -ROUNDOFF * self.scale

    def __repr__(self):
        kind = "minimum" if self.minimum else "saddle"
        return f"Stability({kind}, smallest eigenvalue {self.smallest:.4g} N/m)"


def free_hessian(potential, x):
    """The true Hessian of potential (an anisofem.physics.potential.Potential) at positions x (n, 3)
    over the free components: (k, k) scipy.sparse CSR, N/m."""
    layout = potential.scene.layout("csr")
    return layout.matrix(potential.hessian_data(x, layout, want_grad=False)[2])


def stability(potential, x):
    """The Stability of positions x (n, 3) for potential (see the module docstring)."""
    H = free_hessian(potential, x)
    if H.shape[0] < DENSE_MAX:
        return _dense(H)
    try:
        inverse = linsolve.SuperLU().factor(H, H.data.copy())  # H reads as its own layout
    except linsolve.FactorizationError:
        return negative_curvature(H)
    operator = spla.LinearOperator(H.shape, matvec=inverse, dtype=float)
    values, vectors = spla.eigsh(H, k=1, sigma=0.0, which="LM", OPinv=operator,
                                 v0=_start(H.shape[0]), tol=1e-6)
    return Stability(float(values[0]), _scale(H), vectors[:, 0], definite=True)


def negative_curvature(H, start=None):
    """The Stability of the free Hessian H (k, k) from its smallest eigenpair by Lanczos, started
    from start (an eigenvector guess, e.g. the last one) or a fixed pseudo-random vector."""
    if H.shape[0] < DENSE_MAX:
        return _dense(H)
    try:
        values, vectors = spla.eigsh(H, k=1, which="SA", tol=1e-6, maxiter=MAX_LANCZOS,
                                     v0=_start(H.shape[0]) if start is None else start)
    except spla.ArpackNoConvergence:
        return Stability(math.nan, _scale(H))
    return Stability(float(values[0]), _scale(H), vectors[:, 0])


def _dense(H):
    values, vectors = np.linalg.eigh(H.toarray())
    return Stability(float(values[0]), _scale(H), vectors[:, 0], definite=bool(values[0] > 0))


def _scale(H):
    return float(H.diagonal().max())


def _start(k):
    """A fixed pseudo-random start vector of length k (ARPACK's own is random: not repeatable)."""
    return np.random.default_rng(k).standard_normal(k)

