"""Wall-time measurement for the benchmarks."""
import time

import numpy as np


def best_time(fn, repeat, budget=2.0):
    """Least wall time in s of fn() over up to `repeat` runs (stops early past budget seconds;
    the least is the measure least disturbed by other load on a shared machine)."""
    best, start = np.inf, time.perf_counter()
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
        if time.perf_counter() - start > budget:
            break
    return best
