"""The ways to minimize a step's (or a static scene's) potential G, from exact to fast.

Every method is a source of search directions inside one loop (anisofem.newton.minimize): the
loop tests convergence, asks the method for directions and runs the backtracking line search
on G, so every method descends G, stops when the free-gradient norm meets the tolerance, and
reports failure instead of returning NaN. The methods differ in what a direction costs:

- "newton" (Newton): a fresh factorization of the Hessian every iteration (the true Hessian
  when it is positive definite, else the PSD-projected one). To rtol = 1e-8 it is the exact
  reference every other method is measured against.
- "reuse" (FactorReuse): keeps the last factorization across iterations and steps and
  refactors when a step with the kept factor leaves more than `refactor` of the gradient norm
  or fails to descend. The Hessian of a backward-Euler potential does not depend on x_hat, so
  a factor from a previous step is as good as one from an earlier iteration of the same step:
  what fixed-Hessian real-time FEM engines exploit. The kept factor is applied in each
  vertex's frame as it has turned since the factorization (anisofem.frames), so a bending
  body does not wear it out: on the trade cantilevers it refactors 3-4x less often than
  unturned (docs/experiments.md).
- "lbfgs" (LBFGS): limited-memory BFGS whose initial inverse Hessian is a factorized Hessian
  (Liu, Bouaziz and Kavan 2017, "Quasi-Newton methods for real-time simulation of
  hyperelastic materials"). Departures from the paper: the initial Hessian starts as the exact
  (PSD-projected) Hessian of G at rest instead of a Laplacian-like matrix, and is refactored
  at the current state as in "reuse" when a step makes too little progress. Kept constant, the
  rest Hessian of this anisotropic, nearly incompressible material is not rotation invariant:
  once a cantilever has bent, a full step with it raised G by 8x the predicted decrease, and a
  10-iteration L-BFGS stalled at step 68 of the 200-tet cantilever. The curvature pairs are
  kept across steps (valid for the same reason as in "reuse"), not restarted each frame, and
  pairs that violate the curvature condition are skipped.
- "cg" (NewtonCG): inexact Newton, preconditioned conjugate gradients on the assembled
  Hessian, stopped at a forcing tolerance eta times the gradient norm or after cg_iter
  iterations, and truncated at negative curvature (Steihaug); a first-iteration negative
  curvature retries with the projected Hessian. It does not step along negative curvature
  itself (measured: docs/experiments.md); where its solve fails, load continuation takes over
  (anisofem.continuation). eta follows how well the last iteration's
  quadratic model predicted the gradient it led to (Eisenstat and Walker 1996, choice 1):
  loose while the nonlinearity limits what a step can gain, tight once the model is good, so
  a solve spends its CG iterations where they buy progress (at 10^5 tets a backward-Euler
  step took 6.3 instead of 8.3 Newton and 85 instead of 108 CG iterations). The
  preconditioner is the Hessian's diagonal ("jacobi": no factorization, the rung that fits any
  memory) or a kept factorization of an earlier Hessian ("factor", renewed when CG needs more
  than refactor_after iterations): a lagged factor is a good preconditioner long after it has
  stopped being a good Hessian. With "amg" (a kept smoothed-aggregation multigrid hierarchy)
  neither time nor memory grows faster than the mesh: the large-mesh method.
- "auto" (the default of anisofem.solve, step and simulate): "newton" up to
  AUTO_MULTIGRID_MIN unknowns or wherever a linear_solver is named, "cg" with preconditioner
  "amg" above (choose).

Each method stops either at the tolerance (rtol, atol; max_iter a safety cap whose reaching is
a failure) or, with `iterations=k`, after a fixed budget of k iterations per solve: reaching
the budget is then the method working as asked (the result says converged=False, failed=False),
and rollouts continue. A rollout starts a tolerance-driven solve from the previous step's
acceleration, and a budgeted one from the inertial predictor x_n + dt v_n (zero acceleration;
option warm_start): truncated from an extrapolated start, one Newton iteration per step
diverged on the 200-tet cantilever and three L-BFGS iterations on the 12,800-tet one, while
from the predictor one Newton iteration is the linearly implicit Euler method, which is stable.
"""
import contextlib
import inspect
import math

import numpy as np

from . import linsolve, multigrid
from .frames import VertexFrames
from .stability import free_hessian, negative_curvature

#: Curvature pairs of L-BFGS with s.y below this times |s| |y| are skipped.
CURVATURE_MIN = 1e-10
#: An iteration that leaves more than this share of the gradient norm counts as stalling (0.5,
#: 0.7, 0.95, 0.99 measured: docs/experiments.md)
STALLING = 0.9
#: After this many projected iterations in a row Newton looks for negative curvature even
#: where each leaves less than STALLING of the gradient: a StVK cantilever converged to a saddle
#: at 0.81 per iteration for 80 iterations
PROJECTED_RUN = 10
#: A step at least this share of the squared length of its direction counts as a whole step.
FULL_STEP = 0.98
#: The first length of a step along negative curvature, as a share of the mesh's diagonal.
SADDLE_STEP = 1e-3


def gradient_tolerance(potential, rtol, atol=None):
    """The free-gradient norm (N) at which a solve of potential converges:
    max(rtol * force_scale, atol), atol defaulting to Scene.gradient_roundoff."""
    if atol is None:
        atol = potential.scene.gradient_roundoff
    return max(rtol * potential.force_scale(), atol)


class Method:
    """Shared stopping rule and bookkeeping of every method.

    rtol: stop when the free-gradient norm is at most rtol times the load scale (see
    anisofem.newton). atol: absolute floor in N (default: the round-off level). max_iter:
    safety cap for tolerance-driven solves (reaching it is a failure). iterations: a fixed
    budget of iterations per solve instead (None: iterate to the tolerance). warm_start: where
    a rollout starts each step, "previous" (the previous step's acceleration) or "inertial"
    (zero acceleration: x_n + dt v_n); default "inertial" with a budget, else "previous".
    """

    name = ""

    WARM_STARTS = ("previous", "inertial")

    def __init__(self, rtol=1e-8, atol=None, max_iter=100, iterations=None, warm_start=None):
        if not (rtol >= 0 and (atol is None or atol >= 0)) or rtol == atol == 0:
            raise ValueError(f"rtol, atol: must be >= 0 and not both 0, got {rtol}, {atol}")
        if int(max_iter) < 0:
            raise ValueError(f"max_iter: must be >= 0, got {max_iter}")
        if iterations is not None and int(iterations) < 1:
            raise ValueError(f"iterations: a budget of at least 1 iteration, got {iterations}")
        if warm_start is not None and warm_start not in self.WARM_STARTS:
            raise ValueError(f"warm_start: expected one of {self.WARM_STARTS}, got "
                             f"{warm_start!r}")
        self.rtol, self.atol, self.max_iter = float(rtol), atol, int(max_iter)
        self.iterations = None if iterations is None else int(iterations)
        if warm_start is None:
            warm_start = "inertial" if self.iterations is not None else "previous"
        self.warm_start = warm_start
        self.counts = {}

    @property
    def budget(self):
        """True when the method spends a fixed number of iterations per solve."""
        return self.iterations is not None

    def start(self, potential):
        """Prepare to minimize potential (an anisofem.potential.Potential); self.tolerance is
        the free-gradient norm (N) at which the solve converges."""
        self.potential = potential
        self.tolerance = gradient_tolerance(potential, self.rtol, self.atol)
        self.counts = {"factorizations": 0, "linear_iterations": 0, "projected": 0}

    def threads(self):
        """Context the solve runs in."""
        return contextlib.nullcontext()

    def directions(self, x, g, residual):
        """Candidate descent directions (unknown space) at positions x (n, 3) with free
        gradient g (k,) and relative residual |g| / scale, best first: the loop line-searches
        each in turn until one makes progress."""
        raise NotImplementedError

    def accepted(self, s, y, progress):
        """Told after each accepted step: s = x_new - x, y = g_new - g (unknown space),
        progress = |g_new| / |g|."""

    def leave_saddle(self, x, g):
        """At positions x that meet the tolerance (free gradient g): None at a minimum (or
        where the method cannot tell), else (d, d^T H d < 0), a step along negative curvature
        that the loop line-searches before it calls the solve converged."""
        return None

    def __repr__(self):
        knobs = ", ".join(f"{k}={getattr(self, k)!r}" for k in _knobs(type(self)))
        return f"{type(self).__name__}({knobs})"


class Newton(Method):
    """Newton's method: a fresh factorization per iteration (see the module docstring).

    projection: "adaptive" (default) tries the true Hessian and uses the PSD-projected one only
    when the true one is not positive definite or its step makes no progress; "always" projects
    every iteration (robust, linear convergence near equilibria with compressed elements);
    "never" uses the true Hessian only. linear_solver: see anisofem.linsolve.NAMES.
    """

    name = "newton"
    _CHOICES = {"adaptive": (False, True), "always": (True,), "never": (False,)}

    def __init__(self, projection="adaptive", linear_solver="auto", **stopping):
        super().__init__(**stopping)
        self._solve = None
        if projection not in self._CHOICES:
            raise ValueError(f"projection: expected one of {tuple(self._CHOICES)}, got "
                             f"{projection!r}")
        if linear_solver not in linsolve.NAMES:
            raise ValueError(f"linear_solver: expected one of {linsolve.NAMES}, got "
                             f"{linear_solver!r}")
        self.projection, self.linear_solver = projection, linear_solver

    def start(self, potential):
        super().start(potential)
        self.solver = linsolve.make(self.linear_solver, potential.scene.n_free)
        self.layout = potential.scene.layout(self.solver.layout)
        self.stalling = False    # the last iteration left more than STALLING of the gradient
        self.run = 0             # whole projected steps in a row since the last escape tried
        self._plain, self._projected = None, False  # the last Newton direction offered
        self.indefinite = False  # the last true Hessian was not positive definite
        self.curvature = None    # the last Stability computed (its eigenvector starts the next)
        # length of the next step along negative curvature, m; grows and shrinks as a trust
        # radius by how far the line search takes each one (self._escape: the one on offer)
        self.escape_length = SADDLE_STEP * potential.scene.mesh.size
        self._escape = None

    def threads(self):
        return self.solver.threads()

    def refresh(self, x, projected, data=None):
        """Factor the Hessian at x (assembled unless its data in self.layout is given) and keep
        it as self._solve; False when it cannot be factored."""
        solve = self._factor(x, projected, data)
        if solve is None:
            return False
        self._solve = solve
        return True

    def _factor(self, x, projected, data=None):
        """The solve of the Hessian at x factored (see refresh), or None where the factorization
        fails (the true Hessian not positive definite)."""
        if data is None:
            data = self.potential.hessian_data(x, self.layout, project=projected,
                                               want_grad=False)[2]
        self.counts["factorizations"] += 1
        try:
            return self.solver.factor(self.layout, data)
        except linsolve.FactorizationError:
            return None

    def apply(self, g):
        """The inverse-Hessian approximation applied to g."""
        return self._solve(g)

    def forget(self):
        """Called when a direction failed to make progress."""

    def accepted(self, s, y, progress):
        if self._escape is not None:  # a step along negative curvature went this far of it
            share = math.sqrt(float(s @ s) / float(self._escape @ self._escape))
            self.escape_length *= 2.0 if share > 0.99 else share
            self._escape = None
            self.stalling, self.run = progress > STALLING, 0
            return
        # only whole steps say the iteration is in Newton's local regime: far from an
        # equilibrium, damped steps that leave most of the gradient are the globalization's
        whole = float(s @ s) >= FULL_STEP * float(self._plain @ self._plain)
        self.stalling = whole and progress > STALLING
        self.run = self.run + 1 if whole and self._projected else 0

    def directions(self, x, g, residual):
        for projected in self._CHOICES[self.projection]:
            factored = self.refresh(x, projected)
            if not projected:
                self.indefinite = not factored
            if factored:
                self.counts["projected"] += projected
                p = -self.apply(g)
                self._plain, self._projected = p, projected
                if projected and self.projection == "adaptive" and (
                        self.stalling or self.run > PROJECTED_RUN):
                    self.run = 0
                    escape = self._negative_curvature(
                        x, g, max(math.sqrt(float(p @ p)), self.escape_length))
                    if escape is not None:
                        self._escape = p + escape[0]
                        yield self._escape, escape[1]
                        self._escape = None
                yield p
                self.forget()

    def _negative_curvature(self, x, g, length):
        """(d, d^T H d) for the unit eigenvector of the true Hessian's most negative eigenvalue
        at x scaled to length and pointed downhill, or None where the Hessian has none."""
        previous = None if self.curvature is None else self.curvature.vector
        self.curvature = negative_curvature(free_hessian(self.potential, x), previous)
        if self.curvature.minimum or self.curvature.vector is None:
            return None  # a minimum, or Lanczos did not converge
        d = self.curvature.vector * length
        return (-d if float(d @ g) > 0 else d), self.curvature.smallest * length ** 2

    def leave_saddle(self, x, g):
        if self.projection != "adaptive" or not self.indefinite:
            return None
        self.indefinite = False  # asked once per indefinite Hessian met
        if self._factor(x, projected=False) is not None:
            return None  # the true Hessian at x factors: positive definite, no Lanczos needed
        escape = self._negative_curvature(x, g, self.escape_length)
        if escape is not None:
            self._escape = escape[0]
        return escape


def _key(potential):
    """What a factor of G's Hessian is valid for: the scene and dt (None: statics)."""
    return potential.scene, getattr(potential, "dt", None)


class _KeptFactor(Newton):
    """Newton variants that keep a factorization (`_solve`, None when there is none or it is
    to be renewed) from one solve to the next of the same scene and dt."""

    def __init__(self, **newton):
        super().__init__(**newton)
        self._owner = None

    def start(self, potential):
        super().start(potential)
        scene, dt = _key(potential)
        if self._owner is None or self._owner[0] is not scene or self._owner[1] != dt:
            self._owner, self._solve = (scene, dt), None
            self.first_factor(potential)

    def first_factor(self, potential):
        """Set up the factor the first iteration uses (default none: it factors at once)."""


class FactorReuse(_KeptFactor):
    """Newton with the factorization kept across iterations and steps (see the module
    docstring), applied in each vertex's frame rotated since it was made (anisofem.frames).
    refactor: a step with the kept factor that leaves more than this fraction of the gradient
    norm triggers a fresh factorization at the next iteration."""

    name = "reuse"

    def __init__(self, refactor=0.5, **newton):
        super().__init__(**newton)
        if not 0 < refactor < 1:
            raise ValueError(f"refactor: a fraction in (0, 1), got {refactor}")
        self.refactor = float(refactor)
        self._frames = self._built = None

    def first_factor(self, potential):
        scene = potential.scene
        self._frames = VertexFrames(scene.mesh, scene.free_dofs)

    def refresh(self, x, projected, data=None):
        made = super().refresh(x, projected, data)
        if made and self._frames is not None:  # L-BFGS turns nothing
            self._built = self._frames.rotations(x)
        return made

    def kept(self, x):
        """g -> the kept inverse-Hessian approximation at x applied to g: the kept factor
        turned by the vertex rotations since it was made."""
        return self._frames.carry(self._solve, self._built, x)

    def directions(self, x, g, residual):
        if self._solve is not None:
            self._fresh = False
            yield -self.kept(x)(g)
            self.forget()
        self._fresh = True
        yield from super().directions(x, g, residual)

    def accepted(self, s, y, progress):
        if self._fresh:
            super().accepted(s, y, progress)
        elif progress > self.refactor:
            self._solve = None


class LBFGS(FactorReuse):
    """L-BFGS (see the module docstring): `history` curvature pairs on top of an initial
    inverse Hessian that starts as the factorized rest Hessian and, as in "reuse", is
    refactored at the current state when a step leaves more than `refactor` of the gradient
    norm or fails to make progress."""

    name = "lbfgs"

    def __init__(self, history=5, refactor=0.9, **newton):
        super().__init__(refactor=refactor, **newton)
        if int(history) < 1:
            raise ValueError(f"history: must be >= 1, got {history}")
        self.history = int(history)
        self._pairs = []

    def first_factor(self, potential):
        with self.solver.threads():
            self.refresh(potential.scene.initial_positions(), projected=True)
        self._pairs = []

    def kept(self, x):
        """The L-BFGS inverse Hessian, on the factor as made: turned by the vertex rotations
        it refactored more often and lost accuracy on the 200-tet trade cantilever
        (docs/experiments.md)."""
        return self.apply

    def apply(self, g):
        """H g for the L-BFGS inverse Hessian H (Nocedal and Wright, Algorithm 7.4)."""
        q = g.copy()
        alphas = []
        for s, y, rho in reversed(self._pairs):
            a = rho * float(np.dot(s, q))
            q -= a * y
            alphas.append(a)
        r = self._solve(q)
        for (s, y, rho), a in zip(self._pairs, reversed(alphas)):
            r += (a - rho * float(np.dot(y, r))) * s
        return r

    def forget(self):
        self._pairs = []

    def accepted(self, s, y, progress):
        super().accepted(s, y, progress)
        sy = float(np.dot(s, y))
        if sy > CURVATURE_MIN * math.sqrt(float(np.dot(s, s)) * float(np.dot(y, y))):
            self._pairs.append((s, y, 1.0 / sy))
            del self._pairs[:-self.history]


class NewtonCG(_KeptFactor):
    """Inexact Newton by truncated, preconditioned conjugate gradients (see the module
    docstring). cg_iter: most CG iterations per Newton iteration. forcing: largest relative
    CG tolerance, the first iteration's (with a small budget of iterations, a small forcing
    such as 0.01 keeps each iteration close to a Newton step); see forcing_tolerance.
    preconditioner: "jacobi" (the Hessian's diagonal: no factorization at all), "factor" (a
    kept factorization of an earlier Hessian) or "amg" (a kept smoothed-aggregation
    multigrid hierarchy of an earlier Hessian, with the rigid-body modes at the current
    positions: no factorization, memory linear in the mesh, the rung for large meshes;
    anisofem.multigrid; applied in each vertex's frame rotated since it was
    built, anisofem.frames). A kept factor or hierarchy is renewed at the current state when a
    CG solve with it needs more than refactor_after iterations (default 10 with "factor", 60
    with "amg"), unless it was built for that solve. linear_solver: for "factor".
    """

    name = "cg"
    PRECONDITIONERS = ("jacobi", "factor", "amg")

    def __init__(self, cg_iter=1000, forcing=0.1, preconditioner="jacobi", refactor_after=None,
                 **newton):
        super().__init__(**newton)
        if int(cg_iter) < 1:
            raise ValueError(f"cg_iter: must be >= 1, got {cg_iter}")
        if not 0 < forcing < 1:
            raise ValueError(f"forcing: a fraction in (0, 1), got {forcing}")
        if preconditioner not in self.PRECONDITIONERS:
            raise ValueError(f"preconditioner: expected one of {self.PRECONDITIONERS}, got "
                             f"{preconditioner!r}")
        if refactor_after is None:
            refactor_after = 60 if preconditioner == "amg" else 10
        if int(refactor_after) < 1:
            raise ValueError(f"refactor_after: must be >= 1, got {refactor_after}")
        self.cg_iter, self.forcing = int(cg_iter), float(forcing)
        self.preconditioner, self.refactor_after = preconditioner, int(refactor_after)
        self._frames = self._built = self._nested = None

    def start(self, potential):
        super().start(potential)
        self.csr = potential.scene.layout("csr")
        self._eta = self._miss = self._model = None

    def first_factor(self, potential):
        """With "amg", the vertex frames the hierarchies of this scene are carried by."""
        if self.preconditioner == "amg":
            scene = potential.scene
            self._frames = VertexFrames(scene.mesh, scene.free_dofs)
            self._nested = (multigrid.corner_prolongation(scene.mesh, scene.free_dofs)
                            if scene.mesh.order == 2 else (None, scene.free_dofs))

    def threads(self):
        """One BLAS thread unless a factorization is kept (anisofem.linsolve.one_blas_thread):
        the iterations' vector products would otherwise slow the parallel assembly."""
        if self.preconditioner == "factor":
            return super().threads()
        return linsolve.one_blas_thread()

    def directions(self, x, g, residual):
        gnorm = math.sqrt(float(np.dot(g, g)))
        self._eta = eta = forcing_tolerance(self.forcing, self._eta, self._miss, gnorm,
                                            self.tolerance)
        for projected in self._CHOICES[self.projection]:
            data = self.potential.hessian_data(x, self.csr, project=projected,
                                               want_grad=False)[2]
            fresh = self._solve is None
            precondition = self._preconditioner(x, data, projected)
            if precondition is None:
                continue
            hessian = self.csr.operator(data)
            p, its = truncated_cg(hessian, g, precondition, eta, self.cg_iter)
            self.counts["linear_iterations"] += its
            # one built at this very iterate is as fresh as a renewal would be
            if self.preconditioner != "jacobi" and its > self.refactor_after and not fresh:
                self._solve = None
            if p is not None:
                self.counts["projected"] += projected
                self._model = hessian, gnorm
                yield p

    def accepted(self, s, y, progress):
        """Keep how far the quadratic model of the last iterate missed the new gradient,
        |y - H s| / |g|: the next forcing tolerance's measure."""
        hessian, gnorm = self._model
        miss = y - hessian @ s
        self._miss = math.sqrt(float(np.dot(miss, miss))) / gnorm

    def _preconditioner(self, x, data, projected):
        """r -> M^-1 r, or None when there is none for this Hessian."""
        if self.preconditioner == "jacobi":
            diagonal = data[self.csr.diag]
            return (lambda r: r / diagonal) if (diagonal > 0).all() else None
        if self.preconditioner == "amg":
            if self._solve is None:
                if not projected:  # multigrid wants a positive definite matrix: the projected
                    data = self.potential.hessian_data(x, self.csr, project=True,
                                                       want_grad=False)[2]
                self.counts["factorizations"] += 1  # hierarchies built
                nested, coarse_dofs = self._nested
                modes = multigrid.rigid_body_modes(x, coarse_dofs)
                self._solve = multigrid.preconditioner(self.csr.matrix(data), modes, nested)
                self._built = self._frames.rotations(x)
                return self._solve  # made here: nothing to carry
            return self._frames.carry(self._solve, self._built, x)
        if self._solve is None:
            # the factorization may overwrite its input
            same = self.layout is self.csr
            if not self.refresh(x, projected, data.copy() if same else None):
                return None
        return self._solve


#: Eisenstat and Walker's safeguard exponent: the golden ratio, the order of the forcing
#: choice's convergence.
_GOLDEN = (1.0 + math.sqrt(5.0)) / 2.0


def forcing_tolerance(forcing, previous, miss, gnorm, tolerance):
    """The relative CG tolerance of a Newton iteration (Eisenstat and Walker 1996, choice 1,
    with their safeguard, and Kelley's lower bound). forcing: the largest, a solve's first
    iteration's (previous None). previous: the last iteration's. miss: the relative error
    |g - g_prev - H_prev s| / |g_prev| of the last iteration's quadratic model, kept from
    falling faster than previous^1.618 while that is above 0.1. The result is no smaller than
    0.5 tolerance / gnorm: no CG digits past the Newton tolerance (N) at a gradient of norm
    gnorm (N)."""
    eta = forcing
    if previous is not None:
        eta = miss
        if previous ** _GOLDEN > 0.1:
            eta = max(eta, previous ** _GOLDEN)
    return min(forcing, max(eta, 0.5 * tolerance / gnorm))


def truncated_cg(A, g, precondition, eta, max_iter):
    """Approximate solution p of A p = -g by preconditioned CG (precondition: r -> M^-1 r for
    a positive definite M), stopped when |A p + g| <= eta |g|, after max_iter iterations, or
    at the first direction of non-positive curvature (Steihaug). Returns (p, or None if the
    first direction already has non-positive curvature; iterations)."""
    p = np.zeros_like(g)
    r = -g
    z = precondition(r)
    d = z.copy()
    rz = float(np.dot(r, z))
    stop = (eta * math.sqrt(float(np.dot(g, g)))) ** 2
    for it in range(max_iter):
        Ad = A @ d
        curvature = float(np.dot(d, Ad))
        if not curvature > 0:
            return (p if it else None), it
        alpha = rz / curvature
        p += alpha * d
        r -= alpha * Ad
        if float(np.dot(r, r)) <= stop:
            return p, it + 1
        z = precondition(r)
        rz, rz_old = float(np.dot(r, z)), rz
        d = z + (rz / rz_old) * d
    return p, max_iter


METHODS = {cls.name: cls for cls in (Newton, FactorReuse, LBFGS, NewtonCG)}


def _knobs(cls):
    """Names of the keyword options of a method class (its own and Method's)."""
    names = []
    for klass in cls.__mro__:
        if "__init__" in vars(klass) and klass is not object:
            names += [p for p in inspect.signature(klass.__init__).parameters
                      if p not in ("self", "stopping", "newton") and p not in names]
    return names


#: What method="auto" solves with: exact Newton up to this many unknowns, inexact Newton with
#: the multigrid preconditioner ("cg", preconditioner "amg") above. Exact Newton's sparse
#: factorization grows faster than the mesh. Box cantilevers at nu = 0.48 and 0.499, static
#: solve and step (`python -m anisofem bench --crossover`): 3,780 unknowns, multigrid up to
#: 3.4x faster at nu = 0.48, exact Newton 1.5x faster at the nearly incompressible step;
#: 7,425, multigrid 1.7-5.9x faster, as fast at the nearly incompressible step; 13,728,
#: multigrid 2.5-7.9x faster; 66,150 (10^5 tets), multigrid 49x faster (`bench --large`).
AUTO_MULTIGRID_MIN = 5_000


def choose(n_unknowns, linear_solver=None):
    """The method "auto" picks for a problem of n_unknowns free components, given the
    linear_solver option or not: (name, options)."""
    if linear_solver is None and n_unknowns > AUTO_MULTIGRID_MIN:
        return "cg", {"preconditioner": "amg"}
    return "newton", {}


def make(method="auto", n_unknowns=None, **options):
    """A Method from a name ("auto" or one of METHODS) and its options, or a Method instance as
    is. n_unknowns: the problem's free components, which "auto" chooses by (see choose).
    "auto" takes Newton's options, which "cg" reads the same way; a linear_solver names a
    factorization and so makes it exact Newton at any size."""
    if isinstance(method, Method):
        if options:
            raise TypeError(f"{sorted(options)}: give options to the Method's constructor, "
                            f"not beside an instance")
        return method
    if method == "auto":
        knobs = _knobs(Newton)
        unknown = sorted(set(options) - set(knobs))
        if unknown:
            raise TypeError(f"{unknown[0]}: not an option of method 'auto' (its options: "
                            f"{', '.join(knobs)}); name the method to set its own")
        if n_unknowns is None:
            raise ValueError("method 'auto' chooses by the problem's size: pass n_unknowns")
        method, chosen = choose(n_unknowns, options.get("linear_solver"))
        options = {**chosen, **options}
    if method not in METHODS:
        raise ValueError(f"method: expected one of {('auto',) + tuple(METHODS)} or an "
                         f"anisofem.methods.Method, got {method!r}")
    cls = METHODS[method]
    unknown = sorted(set(options) - set(_knobs(cls)))
    if unknown:
        raise TypeError(f"{unknown[0]}: not an option of method {method!r} (its options: "
                        f"{', '.join(_knobs(cls))})")
    return cls(**options)
