"""The minimization loop every method shares (see anisofem.solvers.methods for the methods).

Unknowns are the free vertex components; fixed ones stay at their prescribed positions.
Converged means |dG/dx|_free <= max(rtol * scale, atol), with scale the problem's force scale
in N (Potential.force_scale: external, elastic and inertial forces at the problem's start, not
at the solve's first iterate, so a poor first guess cannot loosen the test). The default
atol is Scene.gradient_roundoff, a few times the level below which float64 cannot resolve the
gradient; pass atol=0 to insist on rtol alone. Each iteration line-searches the method's
directions in turn (backtracking to the Armijo condition on G) until one makes progress; a
trial point where G is +inf (a Neo-Hookean element with det F <= 0) is rejected like any
other that does not descend, so no iterate ever leaves the material's domain. The result is
never NaN: a failure returns the last iterate, converged=False, failed=True and a message
saying why.

Newton's Hessian choice (`projection`, see anisofem.solvers.methods.Newton): "adaptive" (default)
first tries the true Hessian; it is used when it is positive definite (the Cholesky-type
factorization succeeds) and its step makes progress in the line search; otherwise the
iteration uses the PSD-projected Hessian (see anisofem.physics.kernels). Near a stable equilibrium
the assembled true Hessian is positive definite even though compressed elements are indefinite on
their own, so convergence ends quadratically; and requiring definiteness keeps Newton from
converging to saddle points (a buckled beam's straight state).
"""
import math
import time
import warnings
from dataclasses import dataclass, field

import numpy as np

from . import methods
from ..physics.inversion import Inversion, inversion
from ..physics.potential import RESOLVED

ARMIJO = 1e-4
MIN_STEP = 1e-10
#: Energy changes below this share of |G| cannot rank two points: the line search then accepts
#: one where the gradient norm falls to NOISE_PROGRESS of its value or below
ENERGY_NOISE = 1e-13
#: 0.9: a Neo-Hookean step converging linearly (0.74 per iteration, the projected Hessian near
#: a saddle) lowered G by 2e-14 J of 0.2 J, below the noise level; asking the gradient to halve
#: stalled it at 1e-6 of the load
NOISE_PROGRESS = 0.9
#: A rise of G below this share of |G| (or Scene.energy_roundoff) with the gradient norm down
#: 100x is round-off too: a converging step of a small Neo-Hookean cantilever raised G by
#: 4e-13 of |G| while its gradient fell 20,000x (taking this as the noise level above made a
#: StVK cantilever at 10,000 g stall instead)
ENERGY_ROUNDOFF = 1e-11
#: The message of a solve with contact stopped where its line search stalled with the Newton
#: step a small share of the contact distance (Potential.contact_resolved)
CONTACT_RESOLVED = f"converged: the Newton step within {RESOLVED:g} of the contact distance"
#: The methods that take contact: those that assemble the Hessian at every iterate.
CONTACT_METHODS = ("newton", "cg")


class ConvergenceWarning(RuntimeWarning):
    """A solve stopped without reaching its tolerance (and not because of a fixed budget)."""


class InversionWarning(RuntimeWarning):
    """A result has elements turned inside out (det F <= 0): not a physical state."""


#: NewtonResult.message of a solve that spent its fixed iteration budget.
BUDGET_SPENT = "iteration budget spent"
#: The message of a solve stopped at its deadline.
TIME_SPENT = "time limit reached"


@dataclass
class NewtonResult:
    """Outcome of a minimization, whatever the method (see anisofem.solvers.methods).

    x: (n, 3) final positions, m. converged: whether the tolerance was met. iterations:
    iterations taken. residuals: relative free-gradient norms, one per iterate (the first is the
    start). energy: G(x), J. projected: directions from the PSD-projected Hessian.
    factorizations: sparse or dense factorizations. linear_iterations: conjugate-gradient
    iterations. method: the method's name. message: why it stopped. seconds: wall time.
    inversion: the anisofem.physics.inversion.Inversion of x (inverted and degenerate elements, the
    smallest det F); converged speaks of the equations, physical of the state. increments: the
    load increments of a solve by load continuation (anisofem.solvers.continuation; 0 where the
    whole load was solved at once).
    """
    x: np.ndarray
    converged: bool
    iterations: int
    residuals: list = field(default_factory=list)
    energy: float = float("nan")
    projected: int = 0
    factorizations: int = 0
    linear_iterations: int = 0
    method: str = "newton"
    message: str = ""
    seconds: float = 0.0
    inversion: Inversion = None
    increments: int = 0
    _stability: object = field(default=None, repr=False)

    @property
    def stability(self):
        """For a static solve, the anisofem.solvers.stability.Stability of x, computed on first
        access: the smallest eigenvalue of the free Hessian, .minimum False where x is a saddle.
        None for a step."""
        if callable(self._stability):
            self._stability = self._stability()
        return self._stability

    @property
    def physical(self):
        """No element is turned inside out."""
        return self.inversion is None or self.inversion.physical

    @property
    def failed(self):
        """Stopped short of the tolerance for a reason other than a fixed iteration budget."""
        return not self.converged and self.message != BUDGET_SPENT

    def __repr__(self):
        return (f"NewtonResult(method={self.method!r}, converged={self.converged}, "
                f"iterations={self.iterations}, residual={self.residuals[-1]:.3g}, "
                f"projected={self.projected}, factorizations={self.factorizations}, "
                f"message={self.message!r}"
                + ("" if self.physical else f", inverted={self.inversion.inverted}") + ")")


def minimize(potential, x0, method="auto", *, warn=True, accept=None, deadline=None,
             **options):
    """Minimize potential (an anisofem.physics.potential.Potential) from x0 (n, 3), fixed components
    already at their prescribed positions, by `method`: "auto" or a name of
    anisofem.solvers.methods.METHODS with its options, or a Method instance (which keeps its
    factorizations across calls). Returns a NewtonResult; warns (ConvergenceWarning) when it
    failed.

    accept(x, G(x)) -> bool: with an iteration budget, the solve stops at the budget only at an
    iterate accept approves, and otherwise goes on (to the tolerance, or max_iter iterations).
    deadline: a time.perf_counter() time after which it stops, not converged (TIME_SPENT).
    """
    method = methods.make(method, potential.scene.n_free, **options)
    if potential.coupled and method.name != "newton":
        raise ValueError(f"method: {method.name!r} cannot take self-contact or surface "
                         f"obstacles, whose pairs couple nodes no element joins; use 'newton'")
    if potential.contact is not None and method.name not in CONTACT_METHODS:
        raise ValueError(f"method: {method.name!r} keeps factors of earlier Hessians, which "
                         f"know nothing of a contact that has begun; with contact use "
                         f"{' or '.join(repr(m) for m in CONTACT_METHODS)}")
    t0 = time.perf_counter()
    method.start(potential)
    with method.threads():
        x, converged, it, res, energy, message = _iterate(potential, x0, method, accept,
                                                          deadline)
    result = NewtonResult(x=x, converged=converged, iterations=it, residuals=res, energy=energy,
                          method=method.name, message=message,
                          seconds=time.perf_counter() - t0,
                          inversion=inversion(potential.scene.mesh, x), **method.counts)
    if warn:
        report(result, potential.scene.mesh.n_tets, stacklevel=4)
    return result


def report(result, n_tets, stacklevel=3):
    """Warn about a NewtonResult of a mesh of n_tets elements that failed (ConvergenceWarning)
    or is not physical (InversionWarning); stacklevel: as warnings.warn's, from report."""
    if result.failed:
        warnings.warn(f"{result.method} did not converge: {result.message} after "
                      f"{result.iterations} iterations, relative residual "
                      f"{result.residuals[-1]:.3g}", ConvergenceWarning, stacklevel=stacklevel)
    if not result.physical:
        inv = result.inversion
        warnings.warn(f"{inv.inverted} of {n_tets} elements are turned inside out (det F "
                      f"<= 0, smallest {inv.min_volume_ratio:.3g}): the state is not physical",
                      InversionWarning, stacklevel=stacklevel)


def _iterate(potential, x0, method, accept, deadline=None):
    """The loop of minimize: (x, converged, iterations, residuals, energy, message)."""
    scene = potential.scene
    free = scene.free_dofs
    x = potential.feasible(np.array(x0, dtype=float))
    energy, grad = potential.energy_gradient(x)
    if not math.isfinite(energy):
        raise ValueError(f"x0: the potential is {energy} at the start (elements outside the "
                         f"material's domain, det F <= 0 for Neo-Hookean)")
    g = grad.ravel()[free]
    scale = potential.force_scale()
    tol = method.tolerance
    gnorm = _norm(g)
    res = [gnorm / scale if scale > 0 else 0.0]
    it = 0
    while True:
        if gnorm <= tol:
            escape = None if it >= method.max_iter else method.leave_saddle(x, g)
            step = escape and _line_search(potential, x, energy, g, gnorm, free, *escape)
            if not step:
                return x, True, it, res, energy, "converged"
            it += 1  # a saddle met at the tolerance, left along its negative curvature
        else:
            if it >= method.max_iter:
                return x, False, it, res, energy, "max_iter reached"
            if deadline is not None and time.perf_counter() > deadline:
                return x, False, it, res, energy, TIME_SPENT
            if method.budget and it >= method.iterations and (accept is None or
                                                              accept(x, energy)):
                return x, False, it, res, energy, BUDGET_SPENT
            it += 1
            step, tried = None, []
            for p in method.directions(x, g, res[-1]):
                tried.append(_curved(p)[0])
                step = _line_search(potential, x, energy, g, gnorm, free, *_curved(p))
                if step is not None:
                    break
            if step is None:
                if gnorm <= potential.contact_roundoff(x):   # the barrier's stiffness floor
                    return x, True, it - 1, res, energy, "converged"
                if tried and potential.contact_resolved(tried[0]):
                    return x, True, it - 1, res, energy, CONTACT_RESOLVED
                return x, False, it, res, energy, "no descent direction: the line search stalled"
        x, energy, grad, s = step
        g_new = grad.ravel()[free]
        norm_new = _norm(g_new)
        method.accepted(s, g_new - g, norm_new / gnorm)
        g, gnorm = g_new, norm_new
        res.append(gnorm / scale)


def _curved(direction):
    """(p, curvature) of a direction from Method.directions: an array p, or a pair (p, d^T H d
    < 0 in N m of its part d along negative curvature)."""
    return direction if isinstance(direction, tuple) else (direction, 0.0)


def _norm(v):
    """Euclidean norm of a 1-D float array (cheaper than np.linalg.norm on small ones)."""
    return math.sqrt(float(np.dot(v, v)))


def _line_search(potential, x, energy, g, gnorm, free, p, curvature=0.0):
    """Backtracking along direction p (unknown space) from x: (x_new, energy, gradient (n, 3),
    step taken (unknown space)) or None if p is no descent direction or nothing makes
    progress. curvature < 0 (N m): the second-order decrease p promises along negative
    curvature, for a p that descends by it where the slope does not (Armijo's condition on
    alpha slope + alpha^2 curvature / 2, as in More and Sorensen's curvilinear search)."""
    slope = float(np.dot(p, g))
    if not (math.isfinite(slope) and math.isfinite(curvature)) or (
            slope >= -1e-14 * _norm(p) * gnorm and not curvature < 0):
        return None
    noise = ENERGY_NOISE * max(abs(energy), 1e-300)
    alpha = potential.step_limit(x, p)    # contact: no node reaches an obstacle on the way
    while alpha >= MIN_STEP:
        xt = x.copy()
        xt.ravel()[free] += alpha * p
        et, gt = potential.energy_gradient(xt)
        if abs(et - energy) <= noise:
            # below round-off the energy cannot rank the points: the gradient norm must fall
            if _norm(gt.ravel()[free]) < NOISE_PROGRESS * gnorm:
                return xt, et, gt, alpha * p
        elif et <= energy + ARMIJO * alpha * (slope + 0.5 * alpha * curvature):
            return xt, et, gt, alpha * p
        elif et - energy <= max(ENERGY_ROUNDOFF * abs(energy),
                                potential.scene.energy_roundoff) and \
                _norm(gt.ravel()[free]) < 0.01 * gnorm:
            return xt, et, gt, alpha * p
        alpha *= 0.5
    return None
