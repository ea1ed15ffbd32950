"""Newton's method with backtracking line search on a scene's potential G.

Unknowns are the free vertex components; fixed ones stay at their prescribed positions.
Converged means |dG/dx|_free <= max(rtol * scale, atol), with scale = max(|dG/dx(x0)|_free,
|f_ext|_free) in N. The default atol is the round-off level of the gradient,
ROUNDOFF * E_max * l^2 * sqrt(unknowns) (l: mean rest edge length), below which the gradient
cannot be resolved; pass atol=0 to insist on rtol alone. The result is never NaN: a failure returns the last iterate, converged=False
and a message saying why.

Hessian choice (`projection`):
- "adaptive" (default): each iteration first tries the true Hessian; it is used when it is
  positive definite (the Cholesky-type factorization succeeds) and its step makes progress in
  the line search; otherwise the iteration uses the PSD-projected Hessian (see
  anisofem.kernels). Near a stable equilibrium the assembled true Hessian is positive definite
  even though compressed elements are indefinite on their own, so convergence ends
  quadratically; and requiring definiteness keeps Newton from converging to saddle points
  (a buckled beam's straight state).
- "always": the projected Hessian at every iteration (robust, but only linear convergence
  near equilibria that have compressed elements).
- "never": the true Hessian only (fails where it is indefinite).
"""
import math
import time
import warnings
from dataclasses import dataclass, field

import numpy as np

from . import linsolve

ROUNDOFF = 1e-14
ARMIJO = 1e-4
MIN_STEP = 1e-10


class ConvergenceWarning(RuntimeWarning):
    """Newton's method stopped without reaching its tolerance."""


@dataclass
class NewtonResult:
    """Outcome of a Newton solve.

    x: (n, 3) final positions, m. converged: whether the tolerance was met. iterations: Newton
    iterations taken. residuals: relative free-gradient norms, one per iterate (the first is the
    start). energy: G(x), J. projected: iterations that used the projected Hessian.
    message: why it stopped. seconds: wall time.
    """
    x: np.ndarray
    converged: bool
    iterations: int
    residuals: list = field(default_factory=list)
    energy: float = float("nan")
    projected: int = 0
    message: str = ""
    seconds: float = 0.0

    def __repr__(self):
        return (f"NewtonResult(converged={self.converged}, iterations={self.iterations}, "
                f"residual={self.residuals[-1]:.3g}, projected={self.projected}, "
                f"message={self.message!r})")


_PROJECTIONS = ("adaptive", "always", "never")


def minimize(potential, x0, *, rtol=1e-8, atol=None, max_iter=100, projection="adaptive",
             linear_solver="auto", warn=True):
    """Minimize potential (an anisofem.potential.Potential) from x0 (n, 3), fixed components
    already at their prescribed positions. Returns a NewtonResult."""
    if projection not in _PROJECTIONS:
        raise ValueError(f"projection: expected one of {_PROJECTIONS}, got {projection!r}")
    if not (rtol >= 0 and (atol is None or atol >= 0)) or rtol == atol == 0:
        raise ValueError(f"rtol, atol: must be >= 0 and not both 0, got {rtol}, {atol}")
    if int(max_iter) < 0:
        raise ValueError(f"max_iter: must be >= 0, got {max_iter}")
    t0 = time.perf_counter()
    solver = linsolve.make(linear_solver, potential.scene.n_free)
    with solver.threads():
        x, converged, it, res, energy, n_projected, message = _iterate(
            potential, x0, solver, rtol, atol, max_iter, projection)
    result = NewtonResult(x=x, converged=converged, iterations=it, residuals=res, energy=energy,
                          projected=n_projected, message=message,
                          seconds=time.perf_counter() - t0)
    if warn and not converged:
        warnings.warn(f"Newton did not converge: {message} after {it} iterations, relative "
                      f"residual {res[-1]:.3g}", ConvergenceWarning, stacklevel=3)
    return result


def _iterate(potential, x0, solver, rtol, atol, max_iter, projection):
    """The Newton loop of minimize: (x, converged, iterations, residuals, energy, projected
    iterations, message)."""
    scene = potential.scene
    layout = scene.layout(solver.layout)
    free = layout.dofs  # flat DOF index (3 i + c) of each unknown
    x = np.array(x0, dtype=float)
    energy, grad = potential.energy_gradient(x)
    g = grad.ravel()[free]
    scale = max(_norm(g), _norm(scene.external_force.ravel()[free]))
    if atol is None:
        atol = ROUNDOFF * scene.force_unit * math.sqrt(free.size)
    tol = max(rtol * scale, atol)
    res = [_norm(g) / scale if scale > 0 else 0.0]
    choices = {"adaptive": (False, True), "always": (True,), "never": (False,)}[projection]
    n_projected = 0
    message = "max_iter reached"
    converged = False
    it = 0
    while True:
        if _norm(g) <= tol:
            converged, message = True, "converged"
            break
        if it >= max_iter:
            break
        step = None
        for projected in choices:
            step = _newton_step(potential, x, energy, g, free, layout, solver, projected)
            if step is not None:
                break
        it += 1
        if step is None:
            message = "no descent direction: the line search stalled"
            break
        x, energy, grad, projected = step
        n_projected += projected
        g = grad.ravel()[free]
        res.append(_norm(g) / scale)
    return x, converged, it, res, energy, n_projected, message


def _norm(v):
    """Euclidean norm of a 1-D float array (cheaper than np.linalg.norm on small ones)."""
    return math.sqrt(float(np.dot(v, v)))


def _newton_step(potential, x, energy, g, free, layout, solver, projected):
    """One damped Newton step; (x, energy, gradient, projected) or None if no progress."""
    _, _, data = potential.hessian_data(x, layout, project=projected, want_grad=False)
    try:
        p = -solver.factor(layout, data)(g)
    except linsolve.FactorizationError:
        return None
    slope = float(np.dot(p, g))
    gnorm = _norm(g)
    if not math.isfinite(slope) or slope >= -1e-14 * _norm(p) * gnorm:
        return None
    noise = 1e-13 * max(abs(energy), 1e-300)
    alpha = 1.0
    while alpha >= MIN_STEP:
        xt = x.copy()
        xt.ravel()[free] += alpha * p
        et, gt = potential.energy_gradient(xt)
        if abs(et - energy) <= noise:
            # below round-off the energy cannot rank the points: accept if the gradient halves
            if _norm(gt.ravel()[free]) < 0.5 * gnorm:
                return xt, et, gt, projected
        elif et <= energy + ARMIJO * alpha * slope:
            return xt, et, gt, projected
        alpha *= 0.5
    return None
