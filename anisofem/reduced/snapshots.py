"""A basis fitted to what a scene does: the full FEM's static equilibria under the loads a
model declares (anisofem.reduced.loads), reduced to their principal directions (proper
orthogonal decomposition in the lumped-mass inner product, Krysl, Lall and Marsden 2001).

Each equilibrium is scaled to unit mass-norm before the decomposition, so that the small
displacements of the scene's own loads count as much as the large ones of a full drag.
States with elements turned inside out are left out (StVK's energy there is unphysical).
"""
import time
import weakref
from dataclasses import dataclass

import numpy as np

from ..physics.inversion import volume_change
from ..solvers.solve import solve
from .loads import build_cases


@dataclass
class SnapshotReport:
    """What the build's static solves gave: states kept, inverted (left out), not converged
    (left out with the rest of their chain), and their time, s."""
    kept: int
    inverted: int
    failed: int
    seconds: float


#: Static states already solved, per scene and declaration: models of one scene with other
#: sizes (the trade's rungs) share them.
_SOLVED = weakref.WeakKeyDictionary()


def static_states(scene, loads):
    """The full FEM's static equilibria (s, n, 3), m, read-only, under the scene's loads and
    under each of the declaration's build cases (loads.build_cases, each chain solved in order
    from the last equilibrium, starting from the scene's own), with a SnapshotReport (its
    seconds: the solves' time when they ran). Solved once per scene and declaration."""
    solved = _SOLVED.setdefault(scene, {})
    if loads not in solved:
        solved[loads] = _solve_states(scene, loads)
    return solved[loads]


def _solve_states(scene, loads):
    t0 = time.perf_counter()
    own = solve(scene, warn=False)
    states, inverted, failed = [own.x], 0, 0
    for chain in build_cases(scene, loads):
        x = own.x
        for k, (extra, controls) in enumerate(chain):
            loaded = scene.plus_force(extra)
            result = solve(loaded.with_controls(controls) if controls else loaded, x0=x,
                           warn=False)
            if not result.converged:
                failed += len(chain) - k
                break
            x = result.x
            if (volume_change(scene.mesh, x) <= -1.0).any():
                inverted += 1
            else:
                states.append(x)
    report = SnapshotReport(len(states), inverted, failed, time.perf_counter() - t0)
    states = np.array(states)
    states.setflags(write=False)
    return states, report


def principal_directions(displacements, mass, count, against=None):
    """The `count` principal directions (N, count) of displacement snapshots (N, s) over the
    free unknowns, each scaled to unit mass-norm first (one that does not move left out),
    with the part along the columns of `against` (N, a; mass-orthonormal) removed;
    mass-orthonormal. Fewer where the snapshots span fewer."""
    norms = np.sqrt(np.einsum("i,is,is->s", mass, displacements, displacements))
    S = displacements[:, norms > 0] / norms[norms > 0]   # a state that does not move: none
    if against is not None:
        for _ in range(2):
            S = S - against @ (against.T @ (mass[:, None] * S))
    root = np.sqrt(mass)[:, None]
    u, sigma, _ = np.linalg.svd(root * S, full_matrices=False)
    keep = min(count, int((sigma > sigma[0] * 1e-10).sum()))
    return u[:, :keep] / root
