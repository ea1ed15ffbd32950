"""Static equilibrium, one backward-Euler step, and rollouts."""
import copy
import time
from dataclasses import dataclass

import numpy as np

from . import methods
from .._validate import as_count, as_scalar
from .continuation import ramp, worth_ramping
from .newton import TIME_SPENT, NewtonResult, minimize, report
from ..physics.contact import advance
from ..physics.curves import LoadCurve
from ..physics.potential import Potential, check_positions
from ..physics.scene import check_scene
from .stability import stability

#: solve's continuation choices (see solve)
CONTINUATION = ("auto", "always", "never")


def solve(scene, x0=None, method="auto", warn=True, continuation="auto", time_limit=None,
          **options):
    """Static equilibrium of a Scene.

    x0: (n, 3) start, m (default: rest positions with fixed vertices at their prescribed
    positions). method: "auto" (default: exact Newton, or multigrid-preconditioned inexact
    Newton on large meshes; anisofem.solvers.methods.choose), "newton", "reuse", "lbfgs", "cg" or an
    anisofem.solvers.methods.Method; options: the method's (rtol, atol, max_iter, iterations,
    projection, linear_solver, ...; see anisofem.solvers.methods). warn: a ConvergenceWarning when
    the solve fails. continuation: "auto" (default) solves the whole load from x0 and, where that
    fails short of round-off or where only the prescribed positions turn Neo-Hookean
    elements of x0 inside out, ramps the load up from x0 in increments, each from the last
    equilibrium (anisofem.solvers.continuation); "always" ramps from the start; "never" does not.
    Returns a NewtonResult; .x is the (n, 3) equilibrium, .increments the load increments
    taken (0: none), .stability says whether it is a minimum or a saddle (computed when
    asked). time_limit: seconds after which the solve stops where it is, not converged (its
    message says so; for the trial solves of an optimization that must end). Raises
    ValueError if the scene holds too little to have a unique equilibrium.
    """
    check_scene(scene)
    scene.check_static()
    deadline = None if time_limit is None else time.perf_counter() + as_scalar(time_limit,
                                                                                "time_limit")
    if continuation not in CONTINUATION:
        raise ValueError(f"continuation: expected one of {CONTINUATION}, got "
                         f"{continuation!r}")
    x0 = scene.initial_positions() if x0 is None else scene.with_fixed(check_positions(
        scene, x0, "x0"))
    potential = Potential(scene)
    method = methods.make(method, scene.n_free, **options)
    if continuation == "always" and method.budget:
        raise ValueError(f"continuation: 'always' needs a method that iterates to its "
                         f"tolerance, not a fixed budget of {method.iterations} iterations; "
                         f"pass continuation='never'")
    bad = scene.outside_domain(x0)
    ramped = continuation == "always" or (bad and continuation == "auto" and not method.budget
                                          and _in_domain_at_rest(scene, x0))
    if bad and not ramped:
        raise ValueError(f"x0: {bad} Neo-Hookean elements start turned inside out or flat "
                         f"(det F <= 0), where their energy is infinite; start from a state "
                         f"with det F > 0 (prescribed positions far from rest: reach them in "
                         f"steps, continuation='auto' or scene.held_at)")
    if ramped:
        result = ramp(potential, x0, method, deadline=deadline)
    else:
        result = minimize(potential, x0, method, warn=False, deadline=deadline)
        if (continuation == "auto" and result.message != TIME_SPENT
                and worth_ramping(potential, result)):
            result = ramp(potential, x0, method, spent=[result], deadline=deadline)
    if warn:
        report(result, scene.mesh.n_tets)
    result._stability = lambda: stability(potential, result.x)
    return result


def _in_domain_at_rest(scene, x):
    """Whether positions x (n, 3) with the fixed components at rest leave every Neo-Hookean
    element in its domain (so that only the prescribed positions take x out of it)."""
    unloaded = scene.loaded(0.0)
    return not unloaded.outside_domain(unloaded.with_fixed(x))


@dataclass
class StepResult:
    """One backward-Euler step: x, v (n, 3) at the end of the step and the Newton outcome."""
    x: np.ndarray
    v: np.ndarray
    newton: NewtonResult

    @property
    def converged(self):
        return self.newton.converged


def step(scene, x, v, dt, a_guess=None, method="auto", warn=True, start=None, **options):
    """One backward-Euler step of length dt (s) from positions x and velocities v (n, 3).

    Minimizes G(y) = 1/(2 dt^2) |y - x - dt v|_M^2 + elastic(y) - f_ext . y, starting from
    y = x + dt v + dt^2 a_guess (a_guess: (n, 3) expected acceleration in m/s^2, default 0;
    simulate passes the previous step's when the method iterates to its tolerance), by
    `method` with `options` (see solve and anisofem.solvers.methods; pass a Method instance to keep
    its factorizations from one call to the next). A step with an iteration budget that would
    end with more mechanical energy than it started with iterates on until it does not (or
    converges). Where the step's solve fails short of round-off, its external force is ramped
    up in increments, each solved from the last (anisofem.solvers.continuation): the step is the
    same, only the path to it changes. start (n, 3): the first iterate instead, clear of the
    obstacles (Stepper's pushes start each from the last). Returns StepResult with v_new =
    (x_new - x) / dt. Fixed components end at their prescribed positions.
    """
    check_scene(scene)
    x = check_positions(scene, x, "x")
    v = check_positions(scene, v, "v")
    dt = as_scalar(dt, "dt")
    if dt <= 0:
        raise ValueError(f"dt: the time step must be > 0 s, got {dt}")
    x_hat = x + dt * v
    if start is None:
        start = x_hat if a_guess is None else x_hat + dt ** 2 * check_positions(
            scene, a_guess, "a_guess")
    else:
        start = check_positions(scene, start, "start")
    potential = Potential(scene, x_hat, dt, x_start=x)
    method = methods.make(method, scene.n_free, **options)
    accept = _no_energy_gain(potential) if method.budget else None
    first = _start_in_domain(scene, start, x)
    result = minimize(potential, first, method, warn=False, accept=accept)
    if worth_ramping(potential, result):
        result = ramp(potential, first, method, spent=[result])
    if warn:
        report(result, scene.mesh.n_tets)
    return StepResult(result.x, (result.x - x) / dt, result)


def _start_in_domain(scene, start, x):
    """The step's first iterate: start (n, 3) with the fixed components at their prescribed
    positions, or x (the state at the start of the step) so moved where that start leaves the
    Neo-Hookean elements' domain (det F > 0); a ValueError where neither is in it."""
    first = scene.with_fixed(start)
    if not scene.outside_domain(first):
        return first
    first = scene.with_fixed(x)
    bad = scene.outside_domain(first)
    if bad:
        raise ValueError(f"fixed_positions: {bad} Neo-Hookean elements would start the step "
                         f"turned inside out or flat (det F <= 0), where their energy is "
                         f"infinite; move the prescribed positions in smaller steps")
    return first


def _no_energy_gain(potential):
    """accept(y, G(y)) for a budgeted step of potential (from its x_start = x_n): whether the
    step to y ends with no more mechanical energy H = 1/2 v^T M v + elastic - f_ext . x than it
    started with (up to round-off). The exact backward-Euler step never gains energy where the
    elastic energy is convex; a step cut short can, and a budget must not buy a blow-up."""
    mass_over_dt2 = potential.mass_over_dt2[:, None]  # kg/s^2

    def kinetic(displacement):
        """1/2 |displacement / dt|^2_M in J: the kinetic energy of moving that far in dt."""
        return 0.5 * float((mass_over_dt2 * displacement * displacement).sum())

    x, x_hat = potential.x_start, potential.x_hat
    start_energy = potential.start_energy()
    slack = 1e-12 * (abs(start_energy) + abs(float((potential.scene.external_force * x).sum())))

    def accept(y, g):
        return g - kinetic(y - x_hat) + kinetic(y - x) <= start_energy + slack
    return accept


#: The most solves of one step whose obstacles move into the body, each from the last: each
#: moves them as far as the body, where the last solve left it, lets them.
PUSHES = 20


@dataclass
class Rollout:
    """positions, velocities: (k + 1, n, 3) states from the start through the last step that
    did not fail; steps: the StepResults. completed: all requested steps were taken, none
    failed. converged: completed, and every step met its tolerance (False for a method with
    a fixed iteration budget that stopped short of it). physical: no step ended with an
    element turned inside out; inverted: the most inverted elements of any step. obstacles:
    with contact, (k + 1, o, 3) where each obstacle was (Obstacle.position), m."""
    positions: np.ndarray
    velocities: np.ndarray
    steps: list
    completed: bool
    obstacles: np.ndarray = None

    @property
    def converged(self):
        return self.completed and all(s.converged for s in self.steps)

    @property
    def inverted(self):
        return max((s.newton.inversion.inverted for s in self.steps), default=0)

    @property
    def physical(self):
        return self.inverted == 0


class Stepper:
    """Backward-Euler steps of length dt (s) of one scene by one method, carrying what the
    method keeps from step to step (factorizations, curvature pairs) and the warm start.

    stepper(x, v, a_guess=None) -> StepResult. Without a_guess (m/s^2, (n, 3)), a method
    that iterates to its tolerance starts each step from the previous step's acceleration, one
    with a fixed iteration budget from the inertial predictor (see anisofem.solvers.methods).
    """

    def __init__(self, scene, dt, method="auto", warn=True, **options):
        self.scene, self.dt, self.warn = scene, dt, warn
        self.method = methods.make(method, scene.n_free, **options)
        self._a = None
        #: the Contact whose obstacles the last step had (a moving obstacle starts each step
        #: there and goes toward where the scene has it as far as the body lets it)
        self.placed = scene.contact

    def __call__(self, x, v, a_guess=None):
        a = self._a if a_guess is None else a_guess
        if self.scene.contact is None or self.placed is None:
            res = step(self.scene, x, v, self.dt, a, self.method, self.warn)
        else:
            res = self._pushed(x, v, a)
        if self.method.warm_start == "previous" and not res.newton.failed:
            self._a = (res.v - v) / self.dt
        return res

    def _pushed(self, x, v, a):
        """A step whose obstacles go from where the last step left them (placed) to where the
        scene has them: moved as far as the body lets it, the step solved, again from there,
        up to PUSHES times (an obstacle still short of its place goes on at the next step)."""
        placed, start = self.placed, None
        for _ in range(PUSHES):
            now, arrived = advance(self.scene.contact, placed, self.scene.mesh,
                                   x if start is None else start, self.placed)
            scene = copy.copy(self.scene)
            scene.contact = now
            res = step(scene, x, v, self.dt, a, self.method, False, start=start)
            if res.newton.failed:
                break
            placed, start = now, res.x
            if arrived:
                break
        self.placed = placed
        if self.warn:
            report(res.newton, self.scene.mesh.n_tets)
        return res


def simulate(scene, steps, dt=0.02, x0=None, v0=None, callback=None, method="auto",
             warn=True, controls=None, **options):
    """Roll out `steps` backward-Euler steps from x0 (default rest), v0 (default 0).

    method, options: how each step is solved (see step); one Method serves the whole rollout
    (a Stepper), so "reuse" and "lbfgs" keep their factorizations and curvature pairs from
    step to step. A scene whose loads follow load curves (Scene.following) is taken at the end
    of each step, Scene.at((k + 1) dt). controls: the scene's controls in time, over what
    its curves give them: a callable t -> values (a mapping name -> value, or one value per
    control; a controller), or a mapping name -> anisofem.LoadCurve or (times, values) whose
    values are the control's (Pa, activation); each step takes them at its end.
    callback(k, StepResult) is called after each step. Stops early, with completed=False, at
    the first step whose solve fails (a step that spends a fixed iteration budget does not
    fail); what came before is kept.
    """
    check_scene(scene)
    steps = as_count(steps, "steps")
    set_controls = controls_in_time(scene, controls)
    start = set_controls(scene.at(0.0), 0.0)
    x = start.with_fixed(start.initial_positions() if x0 is None
                         else check_positions(scene, x0, "x0"))
    v = np.zeros_like(x) if v0 is None else check_positions(scene, v0, "v0")
    stepper = Stepper(scene, dt, method, warn, **options)
    stepper.placed = start.contact
    xs, vs, results = [x], [v], []
    where = [] if start.contact is None else [_positions(start.contact)]
    for k in range(steps):
        stepper.scene = set_controls(scene.at((k + 1) * dt), (k + 1) * dt)
        res = stepper(x, v)
        results.append(res)
        if res.newton.failed:
            break
        x, v = res.x, res.v
        xs.append(x)
        vs.append(v)
        if where:
            where.append(_positions(stepper.placed))
        if callback is not None:
            callback(k, res)
    return Rollout(np.stack(xs), np.stack(vs), results, len(xs) == steps + 1,
                   np.array(where) if where else None)


def _positions(contact):
    """(o, 3) where a Contact's obstacles are, m."""
    return np.array([o.position for o in contact.obstacles])


def controls_in_time(scene, controls):
    """set(scene_at_t, t) -> that scene with simulate's `controls` at time t (the scene as it
    is where controls is None); its values at t = 0 checked here, so that an unknown name or
    a bad value fails before the first step."""
    if controls is None:
        return lambda at, t: at
    if callable(controls):
        def values(t):
            return controls(t)
    elif isinstance(controls, dict):
        unknown = [k for k in controls if k not in scene.controls]
        if unknown:
            raise ValueError(f"controls: no control {unknown[0]!r}; the scene has: "
                             f"{', '.join(scene.controls) or 'none'}")
        curves = {name: _control_curve(name, c) for name, c in controls.items()}

        def values(t):
            return {name: curve(t) for name, curve in curves.items()}
    else:
        raise TypeError(f"controls: expected a callable t -> values or a mapping name -> "
                        f"curve, got {type(controls).__name__}")
    scene.with_controls(values(0.0))
    return lambda at, t: at.with_controls(values(t))


def _control_curve(name, curve):
    """A control's LoadCurve from a LoadCurve or (times, values)."""
    if isinstance(curve, LoadCurve):
        return curve
    if not isinstance(curve, (tuple, list)) or len(curve) != 2:
        raise ValueError(f"controls: {name}: expected an anisofem.LoadCurve or (times, "
                         f"values), got {curve!r}")
    return LoadCurve(*curve, name=f"controls: {name}")
