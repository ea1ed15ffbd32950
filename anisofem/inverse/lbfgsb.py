"""L-BFGS-B (scipy.optimize) for objectives that are static solves: the objective is scaled so
that its gradient at the start has unit norm (L-BFGS-B's first step, steepest descent to the
bounds' Cauchy point, then has about unit length in the caller's variables), and a trial point
whose solve fails (raises RuntimeError) reads as a value above every one seen, so that the
line search steps back instead of stopping. Every trial solve ends: each may take at most
trial_limit() of the start's time (the solve stops there and the trial counts as failed)."""
from dataclasses import dataclass

import numpy as np
import scipy.optimize

#: A trial point's static solves may take this many times the start's, and at least
#: SHORTEST_LIMIT s, before the trial counts as failed.
TRIAL_FACTOR = 20.0
SHORTEST_LIMIT = 5.0


def trial_limit(start_seconds):
    """The time limit, s, of a trial point's solves when the start's took start_seconds."""
    return max(SHORTEST_LIMIT, TRIAL_FACTOR * start_seconds)


@dataclass
class Outcome:
    """How a minimization ended: iterations; evaluations (static solves, per load case);
    converged (L-BFGS-B met its tolerance); message (why it stopped); seconds; history, one
    row per iteration."""
    iterations: int
    evaluations: int
    converged: bool
    message: str
    seconds: float
    history: list


class _Scaled:
    def __init__(self, objective, scale, log):
        self.objective, self.scale, self.log = objective, scale, log
        self.largest, self.last = 0.0, float("nan")

    def __call__(self, z):
        try:
            J, g = self.objective(z)
        except RuntimeError as err:
            if self.log is not None:
                self.log(f"{err}; stepped back")
            return 10.0 * self.scale * max(self.largest, 1.0), np.zeros(len(z))
        self.last, self.largest = J, max(self.largest, J)
        return self.scale * J, self.scale * np.asarray(g)


def minimize(objective, z0, bounds, max_iter, callback=None, log=None):
    """scipy's OptimizeResult of L-BFGS-B on objective(z) -> (J, dJ/dz) from z0 within bounds
    [(low, high)] for at most max_iter iterations; callback(z, J) after each (J unscaled);
    log(message) for each trial whose solve failed. The start's solve must succeed (its error
    propagates)."""
    _, g0 = objective(z0)
    norm = float(np.linalg.norm(g0))
    scaled = _Scaled(objective, 1.0 / norm if norm > 0 else 1.0, log)
    report = None if callback is None else (lambda z: callback(z, scaled.last))
    return scipy.optimize.minimize(scaled, z0, jac=True, method="L-BFGS-B", bounds=bounds,
                                   callback=report, options={"maxiter": max_iter,
                                                             "ftol": 1e-12, "gtol": 1e-10})
