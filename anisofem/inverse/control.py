"""Controls in time that make a point of the body follow a path: trajectory optimization in a
reduced model (anisofem.reduced), by the adjoint of its backward-Euler rollout and L-BFGS-B.

The controls are piecewise linear in time through their values at knots, c (K, k), each within
its range; the rollout starts at the static equilibrium under the first knot's controls, at
rest, and takes N steps of dt. The objective is

    J(c) = 1/(2 N L^2) sum_n |e(q_n) - p(t_n)|^2 + smooth/2 sum_j |(c_{j+1} - c_j) / w|^2,

e = e0 + E q the effector (anisofem.reduced.reach.effector_rows), p the path, L the body's
size and w the controls' range widths. With the step's residual R_n = (q_n - 2 q_{n-1} +
q_{n-2}) / dt^2 + g(q_n, u_n) (q_{-1} = q_0: the start is at rest) and R_0 = g(q_0, u_0) (the
static start), the adjoints solve (H_n + I / dt^2) l_n = dj_n + (2 l_{n+1} - l_{n+2}) / dt^2
backwards, H_0 l_0 = dj_0 + (l_1 - l_2) / dt^2, and dJ/du_n = -l_n . dg/du_n, dg/du_k =
beta_k'(u_k) G_k(q) (anisofem.reduced.controls): one rollout and r x r solves per gradient.
"""
import math
import time
from dataclasses import dataclass

import numpy as np

from .._validate import as_float_array
from ..reduced.reach import control_force_slopes, effector_rows, model_bounds
from . import lbfgsb

#: The rollout's Newton tolerance (relative), tight so that the gradient is the objective's.
ROLLOUT_RTOL = 1e-12


@dataclass
class ControlResult(lbfgsb.Outcome):
    """What follow found: knot times (K,) s, controls (K, k) at them (in the order of the
    model's controls), the effector's path (N + 1, 3) m in the reduced rollout, its error at
    each step (N + 1,) m, and the largest, over the body's size (largest_error)."""
    knot_times: np.ndarray = None
    controls: np.ndarray = None
    path: np.ndarray = None
    errors: np.ndarray = None
    largest_error: float = math.nan

    def at(self, t):
        """The controls (k,) at time t, s (linear between knots)."""
        return np.array([np.interp(t, self.knot_times, c) for c in self.controls.T])


class _Trajectory:
    """The objective over the knot values scaled to [0, 1] by the bounds."""

    def __init__(self, model, effector, times, points, knots, steps, dt, low, high, smooth):
        self.model, self.dt, self.steps, self.smooth = model, dt, steps, smooth
        self.e0, self.E = effector_rows(model, effector)
        self.low, self.high, self.width = low, high, high - low
        t = dt * np.arange(steps + 1)
        self.targets = np.array([np.interp(t, times, points[:, a]) for a in range(3)]).T
        self.knots = knots
        # u_n = W[n] @ c: the hat functions of the knots at each step's time
        self.W = np.array([np.interp(t, knots, np.eye(len(knots))[j])
                           for j in range(len(knots))]).T                    # (N + 1, K)
        self.size = float(np.ptp(model.x0, axis=0).max())
        self.evaluations = 0

    def controls(self, z):
        """(K, k) knot values of the scaled variables z (K k,)."""
        return self.low + z.reshape(len(self.knots), -1) * self.width

    def rollout(self, c):
        """(q (N + 1, r), u (N + 1, k)): the reduced rollout under knot values c."""
        model, dt = self.model, self.dt
        u = self.W @ c
        q0, report = model.solve(rtol=ROLLOUT_RTOL, controls=u[0])
        if not report.converged:
            raise RuntimeError(f"control: the static start failed ({report.message})")
        q, w = [q0], np.zeros(model.r)
        for n in range(1, self.steps + 1):
            q_next, w, report = model.step(q[-1], w, dt, rtol=ROLLOUT_RTOL, controls=u[n])
            if not report.converged:
                raise RuntimeError(f"control: step {n} failed ({report.message})")
            q.append(q_next)
        return np.array(q), u

    def objective(self, z):
        """(J, dJ/dz)."""
        c = self.controls(z)
        q, u = self.rollout(c)
        self.evaluations += 1
        miss = q @ self.E.T + self.e0 - self.targets                          # (N + 1, 3)
        scale = 1.0 / (self.steps * self.size ** 2)
        jump = np.diff(c, axis=0) / self.width                                # (K - 1, k)
        J = 0.5 * scale * float(np.sum(miss[1:] ** 2)) + 0.5 * self.smooth * float(
            np.sum(jump ** 2))
        dj = scale * miss @ self.E                                            # (N + 1, r)
        dj[0] = 0.0
        du = self._adjoint(q, u, dj)                                          # (N + 1, k)
        dc = self.W.T @ du
        dc[:-1] -= self.smooth * jump / self.width
        dc[1:] += self.smooth * jump / self.width
        return J, (dc * self.width).ravel()

    def _adjoint(self, q, u, dj):
        """dJ/du_n (N + 1, k) from dJ/dq_n (N + 1, r) (module docstring)."""
        model, inertia = self.model, 1.0 / self.dt ** 2
        r, N = model.r, self.steps
        lam = np.zeros((N + 3, r))                                           # l_{N+1}, l_{N+2} = 0
        du = np.zeros((N + 1, len(model.parts)))
        for n in range(N, -1, -1):
            _, H = model.force(q[n], hessian=True, controls=u[n])
            if n > 0:
                rhs = dj[n] + inertia * (2 * lam[n + 1] - lam[n + 2])
                lam[n] = np.linalg.solve(H + inertia * np.eye(r), rhs)
            else:
                lam[0] = np.linalg.solve(H, dj[0] + inertia * (lam[1] - lam[2]))
            du[n] = -control_force_slopes(model, q[n], u[n]).T @ lam[n]
        return du


def follow(model, effector, times, points, dt, steps=None, knots=None, bounds=None,
           smooth=1e-4, start=None, max_iter=200, progress=None, log=None):
    """The controls in time, within bounds, that make `effector` (a vertex index or a rest
    point (3,) m) of a ReducedModel follow the path through `points` (P, 3) m at `times` (P,)
    s (linear between them), by L-BFGS-B on J (module docstring) over `steps` steps of dt s
    (default: to the path's last time). knots: the knot times, s (default: every 0.1 s over
    the rollout); bounds: {name: (low, high)} over the model's declared ranges; smooth: the
    weight of the knots' jumps; start: (K, k) knot values (default: each range's low end).
    progress(iteration, J, controls (K, k)) after each iteration; log(message) for a trial
    whose rollout failed (the search steps back from it). Returns a ControlResult."""
    t0 = time.perf_counter()
    if not model.parts:
        raise ValueError("model: it has no controls to set")
    times = as_float_array(times, "times", shape=(None,))
    points = as_float_array(points, "points", shape=(times.size, 3))
    if times.size < 2 or (np.diff(times) <= 0).any():
        raise ValueError("times: at least two path points at increasing times, s")
    if not dt > 0:
        raise ValueError(f"dt: the time step must be > 0 s, got {dt}")
    steps = int(round(times[-1] / dt)) if steps is None else int(steps)
    if steps < 1:
        raise ValueError(f"steps: at least one step, got {steps}")
    knots = (np.linspace(0.0, steps * dt, max(2, int(round(steps * dt / 0.1)) + 1))
             if knots is None else as_float_array(knots, "knots", shape=(None,)))
    if knots.size < 2 or (np.diff(knots) <= 0).any():
        raise ValueError("knots: at least two increasing times, s")
    low, high = model_bounds(model, bounds)
    problem = _Trajectory(model, effector, times, points, knots, steps, dt, low, high, smooth)
    c0 = (np.tile(low, (knots.size, 1)) if start is None
          else as_float_array(start, "start", shape=(knots.size, len(low))))
    history = []

    def report(z, J):
        history.append((len(history) + 1, J, problem.controls(z)))
        if progress is not None:
            progress(*history[-1])
    z0 = np.clip((c0 - low) / (high - low), 0.0, 1.0).ravel()
    answer = lbfgsb.minimize(problem.objective, z0, [(0.0, 1.0)] * z0.size, max_iter, report,
                             log)
    c = problem.controls(answer.x)
    q, _ = problem.rollout(c)
    path = q @ problem.E.T + problem.e0
    errors = np.linalg.norm(path - problem.targets, axis=1)
    return ControlResult(int(answer.nit), problem.evaluations, bool(answer.success),
                         str(answer.message), time.perf_counter() - t0, history, knots, c,
                         path, errors, float(errors[1:].max() / problem.size))
