"""The Method interface every way of minimizing a potential implements, and "newton" (Newton):
a fresh factorization of the true or PSD-projected Hessian every iteration, with steps along
negative curvature out of saddles; anisofem.solvers.methods says what each method is for."""
import contextlib
import inspect
import math

from . import linsolve
from .stability import free_hessian, negative_curvature

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


def option_names(cls):
    """Names of the keyword options of a method class (its own and Method's)."""
    names = []
    for klass in cls.__mro__:
        if "__init__" in vars(klass) and klass is not object:
            names += [p for p in inspect.signature(klass.__init__).parameters
                      if p not in ("self", "stopping", "newton") and p not in names]
    return names


#: The safety cap on a tolerance-driven solve's iterations, and on one with contact (an impact
#: at a large step can take hundreds of projected Newton iterations, as IPC's do: a 100 g drop
#: of the T onto a rod at dt = 0.02 s took 245 with ipctk's tight-inclusion CCD, where 100 and
#: then load continuation failed; 78 with its additive CCD)
MAX_ITER, CONTACT_MAX_ITER = 100, 500


class Method:
    """Shared stopping rule and bookkeeping of every method.

    rtol: stop when the free-gradient norm is at most rtol times the load scale (see
    anisofem.solvers.newton). atol: absolute floor in N (default: the round-off level). max_iter:
    safety cap for tolerance-driven solves (reaching it is a failure; default MAX_ITER, or
    CONTACT_MAX_ITER with contact). iterations: a fixed
    budget of iterations per solve instead (None: iterate to the tolerance). warm_start: where
    a rollout starts each step, "previous" (the previous step's acceleration) or "inertial"
    (zero acceleration: x_n + dt v_n); default "inertial" with a budget, else "previous".
    """

    name = ""

    WARM_STARTS = ("previous", "inertial")

    def __init__(self, rtol=1e-8, atol=None, max_iter=None, iterations=None, warm_start=None):
        if not (rtol >= 0 and (atol is None or atol >= 0)) or rtol == atol == 0:
            raise ValueError(f"rtol, atol: must be >= 0 and not both 0, got {rtol}, {atol}")
        if max_iter is not None and int(max_iter) < 0:
            raise ValueError(f"max_iter: must be >= 0, got {max_iter}")
        if iterations is not None and int(iterations) < 1:
            raise ValueError(f"iterations: a budget of at least 1 iteration, got {iterations}")
        if warm_start is not None and warm_start not in self.WARM_STARTS:
            raise ValueError(f"warm_start: expected one of {self.WARM_STARTS}, got "
                             f"{warm_start!r}")
        self.rtol, self.atol = float(rtol), atol
        self.cap = None if max_iter is None else int(max_iter)   # as given
        self.max_iter = MAX_ITER if max_iter is None else int(max_iter)
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
        """Prepare to minimize potential (an anisofem.physics.potential.Potential); self.tolerance
        is the free-gradient norm (N) at which the solve converges."""
        self.potential = potential
        if self.cap is None:
            self.max_iter = CONTACT_MAX_ITER if potential.contact is not None else MAX_ITER
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
        knobs = ", ".join(f"{k}={getattr(self, k)!r}" for k in option_names(type(self)))
        return f"{type(self).__name__}({knobs})"


class Newton(Method):
    """Newton's method: a fresh factorization per iteration (see the module docstring).

    projection: "adaptive" (default) tries the true Hessian and uses the PSD-projected one only
    when the true one is not positive definite or its step makes no progress; "always" projects
    every iteration (robust, linear convergence near equilibria with compressed elements);
    "never" uses the true Hessian only. linear_solver: see anisofem.solvers.linsolve.NAMES.
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
        self.solver = linsolve.make(self.linear_solver, potential.scene.n_free,
                                    coupled=potential.coupled)
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
        coupled = self.potential.coupled_hessian(x, self.layout, projected)
        try:
            return self.solver.factor(self.layout, data, coupled)
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
