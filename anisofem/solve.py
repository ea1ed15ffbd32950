"""Static equilibrium, one backward-Euler step, and rollouts."""
from dataclasses import dataclass

import numpy as np

from ._validate import as_scalar
from .material import Material
from .mesh import TetMesh
from .newton import NewtonResult, minimize
from .potential import Potential, check_positions
from .scene import Scene

#: Gravity used by solve(mesh): m/s^2 along -z.
GRAVITY = (0.0, 0.0, -9.81)


def default_scene(mesh):
    """The scene solve(mesh) uses: the paper's material (E = 100 kPa, nu = 0.48, 1000 kg/m^3,
    no fibers), the vertices at the minimum x held fixed, gravity 9.81 m/s^2 along -z."""
    x = mesh.vertices[:, 0]
    fixed = np.flatnonzero(x <= x.min() + 1e-9 * mesh.size)
    return Scene(mesh, Material.paper(), fixed=fixed, gravity=GRAVITY)


def solve(scene, x0=None, **newton):
    """Static equilibrium of a Scene (or of a TetMesh with default_scene's defaults).

    x0: (n, 3) start, m (default: rest positions with fixed vertices at their prescribed
    positions). newton: rtol, atol, max_iter, projection, linear_solver (see anisofem.newton).
    Returns a NewtonResult; .x is the (n, 3) equilibrium. Raises ValueError if the scene holds
    too little to have a unique equilibrium.
    """
    if isinstance(scene, TetMesh):
        scene = default_scene(scene)
    if not isinstance(scene, Scene):
        raise TypeError(f"scene: expected an anisofem.Scene or TetMesh, got "
                        f"{type(scene).__name__}")
    scene.check_static()
    x0 = scene.initial_positions() if x0 is None else scene.with_fixed(check_positions(
        scene, x0, "x0"))
    return minimize(Potential(scene), x0, **newton)


@dataclass
class StepResult:
    """One backward-Euler step: x, v (n, 3) at the end of the step and the Newton outcome."""
    x: np.ndarray
    v: np.ndarray
    newton: NewtonResult

    @property
    def converged(self):
        return self.newton.converged


def step(scene, x, v, dt, a_guess=None, **newton):
    """One backward-Euler step of length dt (s) from positions x and velocities v (n, 3).

    Minimizes G(y) = 1/(2 dt^2) |y - x - dt v|_M^2 + elastic(y) - f_ext . y, starting from
    y = x + dt v + dt^2 a_guess (a_guess: (n, 3) expected acceleration in m/s^2, default 0;
    simulate passes the previous step's). Returns StepResult with v_new = (x_new - x) / dt.
    Fixed components end at their prescribed positions.
    """
    if not isinstance(scene, Scene):
        raise TypeError(f"scene: expected an anisofem.Scene, got {type(scene).__name__}")
    x = check_positions(scene, x, "x")
    v = check_positions(scene, v, "v")
    dt = as_scalar(dt, "dt")
    if dt <= 0:
        raise ValueError(f"dt: the time step must be > 0 s, got {dt}")
    x_hat = x + dt * v
    start = x_hat if a_guess is None else x_hat + dt ** 2 * check_positions(scene, a_guess,
                                                                           "a_guess")
    result = minimize(Potential(scene, x_hat, dt), scene.with_fixed(start), **newton)
    return StepResult(result.x, (result.x - x) / dt, result)


@dataclass
class Rollout:
    """positions, velocities: (k + 1, n, 3) states from the start through the last converged
    step; steps: the StepResults. converged: all requested steps converged."""
    positions: np.ndarray
    velocities: np.ndarray
    steps: list
    converged: bool


def simulate(scene, steps, dt=0.02, x0=None, v0=None, callback=None, **newton):
    """Roll out `steps` backward-Euler steps from x0 (default rest), v0 (default 0).

    callback(k, StepResult) is called after each step. Stops early, with converged=False, at
    the first step whose Newton solve fails; what came before is kept.
    """
    steps = int(steps)
    if steps < 0:
        raise ValueError(f"steps: must be >= 0, got {steps}")
    x = scene.with_fixed(scene.initial_positions() if x0 is None
                    else check_positions(scene, x0, "x0"))
    v = np.zeros_like(x) if v0 is None else check_positions(scene, v0, "v0")
    xs, vs, results = [x], [v], []
    a = None
    for k in range(steps):
        res = step(scene, x, v, dt, a, **newton)
        results.append(res)
        if not res.converged:
            break
        a = (res.v - v) / dt
        x, v = res.x, res.v
        xs.append(x)
        vs.append(v)
        if callback is not None:
            callback(k, res)
    return Rollout(np.stack(xs), np.stack(vs), results, len(xs) == steps + 1)
