"""Inverse statics in a reduced model: the controls, within bounds, that bring a point of the
body (the effector) to a target at static equilibrium (the job of SOFA SoftRobots.Inverse,
solved here in the model's r coordinates).

The effector is a weighted sum of nodes, e(q) = e0 + E q (a vertex; a material point in a
tet, its shape function weights; a region's mean), linear in q. The equilibrium q(u) under
the controls u solves g(q, u) = dV/dq - f = 0, so dq/du = -H^-1 dg/du with dg/du_k =
beta_k'(u_k) G_k(q), G_k the gradient of control k's part (anisofem.reduced.controls). A
Levenberg-Marquardt iteration on |e(q(u)) - target|^2 in the controls scaled to [0, 1] by
their bounds takes each step from a small bounded least-squares problem
(bounded_least_squares), its damping cut after a step that brings the effector closer and
raised after one that does not (controls that act alike, a push and a curl that bend the
same way, leave J short of rank). It stops where the effector is within `tolerance` of the
target (reached), or where no step within the bounds brings it closer: the target is out of
reach and the effector is at the nearest point it can reach from there. Where the first start
(the given controls) ends short of the target, a second starts from the middle of the bounds
(a pressure bends a finger both ways: the distance has a minimum at each sign), and the
nearer of the two is kept.
"""
import math
from dataclasses import dataclass

import numpy as np

from .._validate import as_float_array

#: The first damping of a step, over the largest diagonal entry of J^T J; it is divided by
#: SOFTER after a step that brings the effector closer, multiplied by STIFFER after one that
#: does not, and the reach stops, out of reach, beyond LARGEST.
DAMPING = 1e-3
SOFTER, STIFFER, LARGEST = 3.0, 4.0, 1e8

#: The reach stops, out of reach, after a step that shrinks the squared distance by less than
#: this share of it (a crawl into a minimum short of the target).
CRAWL = 1e-6

#: The reach stops, out of reach, where the gradient of the squared distance along the
#: directions the bounds leave open is below this share of |J| |e - target|.
STATIONARY = 1e-9

#: The default tolerance on the effector's distance to the target, over the body's size (the
#: largest extent of its rest shape).
TOLERANCE = 1e-4

#: The equilibria's Newton tolerance (relative, as ReducedModel.solve's rtol).
SOLVE_RTOL = 1e-8


@dataclass
class Reach:
    """What reach found: controls (k,) in the order of the model's controls, q (r,) the
    equilibrium there, position (3,) m, the effector there, distance (m) to the target,
    reached (within the tolerance), iterations (Gauss-Newton steps) and a message saying
    which."""
    controls: np.ndarray
    q: np.ndarray
    position: np.ndarray
    distance: float
    reached: bool
    iterations: int
    message: str


def effector_rows(model, effector):
    """(e0 (3,), E (3, r)) of an effector: a vertex index, a list of them (their mean), or a
    rest point (3,) of the body (interpolated in the tet holding it)."""
    n = model.scene.mesh.n_vertices
    many = (isinstance(effector, (list, tuple, np.ndarray)) and len(effector) > 0
            and all(isinstance(v, (int, np.integer)) and not isinstance(v, bool)
                    for v in effector))
    if many or (isinstance(effector, (int, np.integer)) and not isinstance(effector, bool)):
        vertices = np.atleast_1d(np.asarray(effector, dtype=np.int64))
        outside = vertices[(vertices < 0) | (vertices >= n)]
        if outside.size:
            raise ValueError(f"effector: vertex {int(outside[0])} is not one of the mesh's {n}")
        return (model.x0[vertices].mean(axis=0),
                model.basis.reshape(n, 3, -1)[vertices].mean(axis=0))
    point = as_float_array(effector, "effector", shape=(3,))
    return point, model.basis_at(point[None])[0]


def model_bounds(model, bounds):
    """(low (k,), high (k,)) of the controls: bounds (a mapping name -> (low, high)) over the
    ranges the model was built for (its Loads); ValueError naming a control with neither, an
    unknown one, or an activation bound outside [0, 1)."""
    ranges = dict(model.loads.controls) if model.loads is not None else {}
    given = dict(bounds or {})
    unknown = [name for name in given if name not in model.controls]
    if unknown:
        raise ValueError(f"bounds: no control {unknown[0]!r}; the model has: "
                         f"{', '.join(model.controls) or 'none'}")
    ranges.update(given)
    low, high = np.zeros(len(model.parts)), np.zeros(len(model.parts))
    for k, part in enumerate(model.parts):
        if part.name not in ranges:
            raise ValueError(f"bounds: control {part.name!r} has no range (give bounds, or "
                             f"build the model with Loads(controls=...))")
        low[k], high[k] = (float(v) for v in ranges[part.name])
        within = {"activation": " in [0, 1)", "tension": " at >= 0 N"}.get(part.kind, "")
        if not low[k] < high[k] or (part.kind == "activation" and
                                    not 0.0 <= low[k] < high[k] < 1.0) or (
                part.kind == "tension" and low[k] < 0):
            raise ValueError(f"bounds: {part.name!r}: expected low < high{within}, got "
                             f"({low[k]:g}, {high[k]:g})")
    return low, high


def reach(model, effector, target, bounds=None, tolerance=None, controls=None, q0=None,
          max_iter=50):
    """The controls within bounds that bring `effector` (a vertex index, or a rest point
    (3,) m) of a ReducedModel to `target` (3,), m, at static equilibrium under the scene's
    loads (module docstring), from controls (default: the model's written values, clipped to
    the bounds) and their equilibrium's Newton from q0 (in a control loop, the last Reach's q
    with its controls; default 0). tolerance: the distance counted as reached, m (default
    TOLERANCE times the body's size). Returns a Reach."""
    if not model.parts:
        raise ValueError("model: it has no controls (named pressures, activations) to set")
    e0, E = effector_rows(model, effector)
    target = as_float_array(target, "target", shape=(3,))
    low, high = model_bounds(model, bounds)
    size = float(np.ptp(model.x0, axis=0).max())
    tolerance = TOLERANCE * size if tolerance is None else float(tolerance)
    start = np.clip(model.control_values(controls), low, high)
    q0 = None if q0 is None else as_float_array(q0, "q0", shape=(model.r,))
    first = _descend(model, e0, E, target, low, high, start, q0, tolerance, max_iter)
    if first.reached:
        return first
    second = _descend(model, e0, E, target, low, high, 0.5 * (low + high), None, tolerance,
                      max_iter)
    best = second if second.distance < first.distance else first
    best.iterations = first.iterations + second.iterations
    return best


def _descend(model, e0, E, target, low, high, u, q0, tolerance, max_iter):
    """reach from the controls u (k,) within the bounds, their equilibrium's Newton from q0
    (None: 0): a Reach."""
    width = high - low
    q = _equilibrium(model, u, q0)
    residual = e0 + E @ q - target
    damping = None
    for it in range(max_iter + 1):
        distance = math.sqrt(float(residual @ residual))
        if distance <= tolerance or it == max_iter:
            break
        slopes = _control_slopes(model, q, u)                            # dq/du (r, k)
        J = (E @ slopes) * width                                         # (3, k), scaled
        s = (u - low) / width
        if _stationary(J, residual, s):
            break
        scale = max(float((J * J).sum(axis=0).max()), np.finfo(float).tiny)
        damping = DAMPING * scale if damping is None else damping
        while damping <= LARGEST * scale:
            trial = np.clip(low + (s + bounded_least_squares(J, residual, -s, 1.0 - s,
                                                             damping)) * width, low, high)
            q_trial = _equilibrium(model, trial, q + slopes @ (trial - u))  # from its tangent
            moved = e0 + E @ q_trial - target
            if moved @ moved < residual @ residual:
                damping /= SOFTER
                break
            damping *= STIFFER
        else:
            break
        crawled = residual @ residual - moved @ moved <= CRAWL * (residual @ residual)
        u, q, residual = trial, q_trial, moved
        if crawled:
            distance = math.sqrt(float(residual @ residual))
            break
    position = e0 + E @ q
    reached = distance <= tolerance
    message = (f"reached: {distance:.3g} m from the target" if reached else
               f"out of reach: the nearest point found is {distance:.3g} m from the target "
               f"(the controls' bounds, or the body, stop it)" if it < max_iter else
               f"not reached in {max_iter} iterations: {distance:.3g} m from the target")
    return Reach(u, q, position, distance, reached, it, message)


def _equilibrium(model, u, q0):
    """The static equilibrium q (r,) under controls u (k,), Newton from q0 (None: 0; where
    that fails, from 0 again)."""
    q, report = model.solve(q0=q0, rtol=SOLVE_RTOL, controls=u)
    if not report.converged and q0 is not None:
        q, report = model.solve(rtol=SOLVE_RTOL, controls=u)
    return q


def _stationary(J, residual, s):
    """Whether the squared distance has no descent within the bounds at scaled controls s
    (k,) in [0, 1]: its gradient J^T residual, less the parts pushing out through a bound
    already reached, below STATIONARY |J| |residual|."""
    g = J.T @ residual
    g = np.where((s <= 0.0) & (g > 0), 0.0, np.where((s >= 1.0) & (g < 0), 0.0, g))
    return float(np.linalg.norm(g)) <= STATIONARY * float(np.linalg.norm(J)) * float(
        np.linalg.norm(residual))


def _control_slopes(model, q, u):
    """dq/du (r, k) at the equilibrium q under controls u: -H^-1 dg/du."""
    _, H = model.force(q, hessian=True, controls=u)
    return -np.linalg.solve(H, control_force_slopes(model, q, u))


def control_force_slopes(model, q, u):
    """dg/du (r, k), N per unit of each control, of the reduced force at q under controls u
    (k,): beta_k'(u_k) G_k(q), G_k the gradient of control k's part (d beta / du: 1 for a
    pressure, 2 - 2 a for an activation; a cable's: dL/dq)."""
    columns = []
    for part, value in zip(model.parts, u):
        if part.kind == "tension":
            columns.append(part.slope(q))
            continue
        G = part.c1 + part.C2 @ q
        if part.S3 is not None:
            G = G + 3.0 * np.einsum("abc,b,c->a", part.S3, q, q)
        columns.append((1.0 if part.kind == "pressure" else 2.0 - 2.0 * value) * G)
    return np.column_stack(columns)


def bounded_least_squares(J, r, low, high, damping):
    """The step d (k,) minimizing |r + J d|^2 + damping |d|^2 with low <= d <= high (low <= 0
    <= high): a primal active-set method from d = 0 (convex: it ends in at most a few passes
    over the k variables)."""
    A = J.T @ J
    k = A.shape[0]
    A = A + damping * np.eye(k)
    b = J.T @ r
    d = np.zeros(k)
    bound = np.zeros(k, dtype=np.int8)                # -1 at low, +1 at high, 0 free
    for _ in range(4 * k + 4):
        free = bound == 0
        target = d.copy()
        if free.any():
            rhs = -(b[free] + A[np.ix_(free, ~free)] @ d[~free])
            target[free] = np.linalg.solve(A[np.ix_(free, free)], rhs)
        step = target - d
        t, hit = 1.0, -1
        for i in np.flatnonzero(free):
            if step[i] < 0 and d[i] + step[i] < low[i]:
                ratio = (low[i] - d[i]) / step[i]
            elif step[i] > 0 and d[i] + step[i] > high[i]:
                ratio = (high[i] - d[i]) / step[i]
            else:
                continue
            if ratio < t:
                t, hit = ratio, i
        d = d + t * step
        if hit >= 0:
            bound[hit] = -1 if step[hit] < 0 else 1
            d[hit] = low[hit] if bound[hit] < 0 else high[hit]
            continue
        gradient = A @ d + b                          # at a bound: release where it pulls in
        pulls = np.where(bound < 0, -gradient, np.where(bound > 0, gradient, 0.0))
        if not (pulls > 0).any():
            return d
        bound[int(np.argmax(pulls))] = 0
    return d
