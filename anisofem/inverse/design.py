"""Fiber layouts designed for a target: the winding angles of a region's helix fibers
(anisofem.physics.fibers), one per equal segment along its axis, chosen so that the static answer
brings a tip (the mean of some vertices) to a target position.

design minimizes

    J(alpha) = 1/2 |tip(x(alpha)) - target|^2 / L^2 + smooth/2 sum_s (alpha_s+1 - alpha_s)^2,

L the mesh's size (its bounding box diagonal), alpha in radians, by L-BFGS-B within bounds
(anisofem.inverse.lbfgsb); each evaluation is one static solve (warm-started from the last) and its
gradient one adjoint solve (anisofem.inverse.sensitivity), chained from each tet's fiber direction
to its segment's angle: dd/dalpha = -sin(alpha) a + cos(alpha) e_t.
"""
import math
import time
from dataclasses import dataclass

import numpy as np

from . import lbfgsb
from .._validate import as_float_array, as_index_array
from ..physics.fibers import helix_directions, helix_frame, helix_slopes, segments
from ..physics.scene import check_scene
from .sensitivity import static_sensitivity
from ..solvers.solve import solve


@dataclass
class Helix:
    """A region's helix fibers to design: tets (m,) bool, axis (3,) unit, origin (3,) m,
    count segments, crossed (alternate tets at -angle)."""
    tets: np.ndarray
    axis: np.ndarray
    origin: np.ndarray
    count: int
    crossed: bool = False


@dataclass
class DesignResult(lbfgsb.Outcome):
    """An Outcome (its history: (iteration, J, |dJ/dalpha|, angles)) and angles (count,)
    degrees per segment; tip (3,) m where the designed body's tip comes to rest; distance |tip
    - target|, m."""
    angles: np.ndarray
    tip: np.ndarray
    distance: float


def design(scene, helix, tip, target, start, bounds=(0.0, 90.0), smooth=1e-3, max_iter=100,
           progress=None, log=None):
    """Winding angles per segment of `helix` (a Helix of scene's tets) so that the mean of the
    vertices `tip` (k,) comes to rest at `target` (3,), m, from `start` (degrees: one for
    every segment, or one each), within bounds (low, high) degrees, with the smoothness
    weight `smooth` (per radian^2). progress(iteration, J, gradient norm, angles) after each
    iteration; log(message) for each trial whose solve failed or ran past its time limit
    (lbfgsb.trial_limit; the search steps back from it). Returns a DesignResult."""
    t0 = time.perf_counter()
    check_scene(scene)
    target = as_float_array(target, "target", shape=(3,))
    tip = as_index_array(tip, "tip", shape=(None,))
    if tip.size == 0 or tip.min() < 0 or tip.max() >= scene.mesh.n_vertices:
        raise ValueError(f"tip: vertex indices in [0, {scene.mesh.n_vertices}), got "
                         f"{tip.size} of them")
    start = np.broadcast_to(as_float_array(start, "start"), (helix.count,)).copy()
    low, high = bounds
    if not low < high or not ((start >= low) & (start <= high)).all():
        raise ValueError(f"bounds: need low < high around the start {start.tolist()} degrees, "
                         f"got ({low:g}, {high:g})")
    problem = _Problem(scene, helix, tip, target, smooth)
    history = []

    def report(z, J):
        g = problem.last_gradient
        history.append((len(history) + 1, J, float(np.linalg.norm(g)), np.degrees(z)))
        if progress is not None:
            progress(*history[-1])
    answer = lbfgsb.minimize(problem.objective, np.radians(start),
                             [(math.radians(low), math.radians(high))] * helix.count,
                             max_iter, report, log)
    x = problem.solved(answer.x)[1].x
    where = x[tip].mean(axis=0)
    return DesignResult(int(answer.nit), problem.evaluations, bool(answer.success),
                        str(answer.message), time.perf_counter() - t0, history,
                        np.degrees(answer.x), where, float(np.linalg.norm(where - target)))


def tip_at(scene, helix, tip, angles):
    """Where the mean of the vertices tip (k,) comes to rest, (3,) m, with the helix wound at
    `angles` (count,) degrees (one static solve)."""
    x = _Problem(scene, helix, np.asarray(tip), np.zeros(3), 0.0).solved(
        np.radians(np.asarray(angles, dtype=float)))[1].x
    return x[tip].mean(axis=0)


class _Problem:
    def __init__(self, scene, helix, tip, target, smooth):
        self.scene, self.helix, self.tip, self.target, self.smooth = (scene, helix, tip, target,
                                                                      smooth)
        el_tets = scene.mesh.tets[helix.tets]
        s, self.around = helix_frame(scene.mesh.vertices[el_tets].mean(axis=1), helix.axis,
                                     helix.origin)
        self.segment = segments(s, helix.count)
        empty = helix.count - np.unique(self.segment).size
        if empty:
            fits = max(k for k in range(1, helix.count) if np.unique(segments(s, k)).size == k)
            raise ValueError(f"segments: {empty} of the {helix.count} segments along the "
                             f"region's axis hold no element, so their angles change nothing; "
                             f"this mesh resolves at most {fits}")
        self.length = scene.mesh.size
        self.state = scene.initial_positions()
        self.evaluations, self.last_gradient = 0, np.zeros(helix.count)
        self.limit = None   # s per solve: none for the start's, lbfgsb.trial_limit after

    def solved(self, alpha):
        """(the scene with angles alpha (count,) radians, its static NewtonResult)."""
        fibers = np.array(self.scene.elements.fiber)
        fibers[self.helix.tets] = helix_directions(self.helix.axis, self.around,
                                                   alpha[self.segment], self.helix.crossed)
        moved = self.scene.with_material(self.scene.material.replaced(fiber_direction=fibers))
        result = solve(moved, x0=self.state, warn=False, time_limit=self.limit)
        if not result.converged:
            raise RuntimeError(f"design: the static solve failed at angles "
                               f"{np.degrees(alpha).round(2).tolist()} ({result.message} after "
                               f"{result.seconds:.3g} s)")
        if self.limit is None:
            self.limit = lbfgsb.trial_limit(result.seconds)
        self.state = result.x
        self.evaluations += 1
        return moved, result

    def objective(self, alpha):
        scene, result = self.solved(alpha)
        miss = result.x[self.tip].mean(axis=0) - self.target
        steps = np.diff(alpha)
        J = 0.5 * float(miss @ miss) / self.length ** 2 + 0.5 * self.smooth * float(steps @ steps)
        dJ = np.zeros_like(result.x)
        dJ[self.tip] = miss / (self.length ** 2 * self.tip.size)
        per_tet = static_sensitivity(scene, result, dJ).fiber_direction[self.helix.tets]
        slopes = helix_slopes(self.helix.axis, self.around, alpha[self.segment],
                              self.helix.crossed)
        g = np.bincount(self.segment, np.sum(per_tet * slopes, axis=1),
                        minlength=self.helix.count)
        g[:-1] -= self.smooth * steps
        g[1:] += self.smooth * steps
        self.last_gradient = g
        return J, g
