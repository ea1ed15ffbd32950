"""Load continuation: the load ramped from none to the whole in increments, each solved from
the last equilibrium (as Abaqus and FEBio do for statics), for loads that Newton cannot take
in one go. A static solve ramps the external force and the displacements the scene prescribes
(Scene.loaded); a backward-Euler step ramps the external force only (its prescribed positions
are the step's own), each increment's minimizer a step of the same length from the same state,
so the last one is the step asked for. The increments adapt: the first is FIRST of the load; one that converges in
at most EASY iterations doubles the next; one that fails is halved and tried again from the
last equilibrium, down to SMALLEST. Each increment starts from a secant predictor (the last
two equilibria extrapolated), or from the last equilibrium where that prediction leaves the
Neo-Hookean domain.
"""
import time

import numpy as np

from .newton import TIME_SPENT, minimize

#: The first increment, a share of the whole load.
FIRST = 0.25
#: An increment that converged in at most this many iterations doubles the next one.
EASY = 8
#: Increments below this share of the load give up.
SMALLEST = 1.0 / 1024

COUNTS = ("iterations", "projected", "factorizations", "linear_iterations")


def worth_ramping(potential, result):
    """Whether a solve of potential that ended in result calls for load continuation: it
    failed (not a spent budget) short of round-off (more than 100 times
    Scene.gradient_roundoff from the tolerance it could reach)."""
    scale = potential.force_scale()
    return result.failed and result.residuals[-1] * scale > 100.0 * \
        potential.scene.gradient_roundoff


def ramp(potential, x0, method, spent=(), deadline=None):
    """The minimizer of potential (an anisofem.physics.potential.Potential) by load continuation
    from x0 (n, 3), m: each increment minimizes potential.loaded(share); x0's fixed components
    are set by each increment's scene. method: an anisofem.solvers.methods.Method
    that iterates to its tolerance. spent: NewtonResults of earlier attempts, whose
    iterations, counts and seconds the result includes.

    Returns a NewtonResult for the whole load with increments set (the increments that
    converged); its iterations, counts and seconds sum every solve tried, failed increments
    included. Where an increment below SMALLEST fails, the result is that failed solve (x its
    last iterate), its message naming the share of the load reached. Raises ValueError where
    an increment's prescribed positions leave Neo-Hookean elements inverted at every size.
    deadline: a time.perf_counter() time past which no increment runs on (the result says
    so: newton.TIME_SPENT)."""
    t0 = time.perf_counter()
    totals = dict.fromkeys(COUNTS, 0)
    seconds = 0.0
    for r in spent:
        _add(totals, r)
        seconds += r.seconds
    done, x, previous = 0.0, np.array(x0, dtype=float), None
    increment, increments = FIRST, 0
    while True:
        share = min(1.0, done + increment)
        loaded = potential if share == 1.0 else potential.loaded(share)
        start = _predict(loaded.scene, x, previous, share - done)
        result = None if start is None else minimize(loaded, start, method, warn=False,
                                                     deadline=deadline)
        if result is not None:
            _add(totals, result)
        if result is not None and result.message == TIME_SPENT:
            result.message = f"load continuation stopped at {done:.3g} of the load: {TIME_SPENT}"
            break
        if result is not None and result.converged:
            increments += 1
            previous, x, done = (x, share - done), result.x, share
            if done == 1.0:
                break
            if result.iterations <= EASY:
                increment *= 2.0
            continue
        increment /= 2.0
        if increment >= SMALLEST:
            continue
        if result is None:
            raise ValueError(f"fixed_positions: at {share:.3g} of the load, Neo-Hookean "
                             f"elements start turned inside out or flat (det F <= 0); "
                             f"move the prescribed positions in smaller steps")
        result.message = (f"load continuation stopped at {done:.3g} of the load: "
                          f"{result.message}")
        break
    result.increments = increments
    result.seconds = seconds + time.perf_counter() - t0
    for name, value in totals.items():
        setattr(result, name, value)
    return result


def _add(totals, result):
    for name in COUNTS:
        totals[name] += getattr(result, name)


def _predict(scene, x, previous, increment):
    """The start of an increment of size increment (share of the load) of scene from the
    last equilibrium x (n, 3): extrapolated along the secant from the equilibrium before it
    (previous: (positions, the increment that led from them to x), or None), with the fixed
    components where scene holds them. Falls back on x where the extrapolation leaves the
    material's domain (det F <= 0 in a Neo-Hookean element); None where that does too."""
    if previous is not None:
        before, step = previous
        guess = scene.with_fixed(x + (x - before) * (increment / step))
        if not scene.outside_domain(guess):
            return guess
    start = scene.with_fixed(x)
    return None if scene.outside_domain(start) else start
