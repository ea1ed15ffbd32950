"""How many threads the library's parallel kernels run on: all of numba's while the cores are
free, fewer while other processes keep them busy.

A parallel kernel (the assembly, the sparse products of the CG and multigrid iterations) ends
at a barrier: its threads wait for the slowest. On a machine whose cores other work keeps busy,
the operating system deschedules one of them for a time slice (milliseconds) at most barriers,
and a step that launches hundreds of kernels waits that long hundreds of times: measured on 2
cores beside 2 busy processes, a 12,800-tet multigrid step 4-7x slower than idle on 2 threads
and 2.5-3x on one, a 200-tet one up to 300x (docs/fem.md, "On a busy machine").

So before parallel work (`parallel_threads()`, called by anisofem.physics.kernels and
anisofem.physics.sparse), at most every SAMPLE_SECONDS, the library reads from /proc/stat how much
CPU time the cores this process may run on gave to other processes since the last look, and sets
numba's thread count (numba.set_num_threads, for the calling thread) to the cores the others
left free, rounded, at least 1. An idle machine keeps every thread. Where the user chose
(NUMBA_NUM_THREADS or OMP_NUM_THREADS in the environment when anisofem was imported, or
`set_threads`), the library never changes the count; where /proc/stat is missing (not Linux),
it keeps numba's default.
"""
import os
import threading
import time

import numba

#: Shortest interval (s) over which the other processes' CPU time is measured: /proc/stat
#: counts in ticks of 10 ms, so over 0.1 s on 2 cores a reading is good to 0.1 core.
SAMPLE_SECONDS = 0.1

_USER_VARIABLES = ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS")


def _user_choice():
    """The thread count the environment names (NUMBA_NUM_THREADS first), or None."""
    for name in _USER_VARIABLES:
        value = os.environ.get(name, "").strip()
        if value:
            try:
                return max(1, min(int(value), numba.config.NUMBA_NUM_THREADS))
            except ValueError:
                return None
    return None


def cores():
    """The CPUs this process may run on (indices)."""
    try:
        return sorted(os.sched_getaffinity(0))
    except AttributeError:  # not Linux
        return list(range(os.cpu_count() or 1))


_TICK = 1.0 / os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 0.01


def _busy_seconds(cpus):
    """CPU seconds the CPUs (indices) spent busy since boot (every process: user, nice, system,
    irq, softirq, steal), or None where /proc/stat cannot be read."""
    wanted = {f"cpu{c}" for c in cpus}
    try:
        with open("/proc/stat", "rb") as f:
            text = f.read().decode()
    except OSError:
        return None
    busy = 0
    for line in text.splitlines()[1:]:
        fields = line.split()
        if not fields or not fields[0].startswith("cpu"):
            break
        if fields[0] in wanted:
            ticks = [int(v) for v in fields[1:9]]
            busy += sum(ticks) - ticks[3] - ticks[4]  # all but idle and iowait
    return busy * _TICK


class LoadMeter:
    """The other processes' use of this process's cores, measured between readings:

        meter = LoadMeter()
        ...                       # work
        meter.others()            # cores the other processes kept busy meanwhile
    """

    def __init__(self):
        self.cores = cores()
        self.last = self._sample()

    def _sample(self):
        busy = _busy_seconds(self.cores)
        return None if busy is None else (time.monotonic(), busy, time.process_time())

    def others(self, wait=False):
        """Cores (a float) the other processes kept busy since the meter was made or last
        returned a value; None without /proc/stat, and while less than SAMPLE_SECONDS has
        passed unless wait (then it sleeps until they have)."""
        if self.last is None:
            return None
        now = time.monotonic()
        if now - self.last[0] < SAMPLE_SECONDS:
            if not wait:
                return None
            time.sleep(SAMPLE_SECONDS - (now - self.last[0]))
        sample = self._sample()
        t0, busy0, own0 = self.last
        self.last = sample
        return max(0.0, (sample[1] - busy0) - (sample[2] - own0)) / (sample[0] - t0)


_sampler = LoadMeter()
_ENVIRONMENT = _user_choice()  # read once: the user's choice when the library was imported
_fixed = _ENVIRONMENT
_local = threading.local()
_lock = threading.Lock()
_others = [0.0]  # the latest reading of _sampler


def free_threads(others, cores, most):
    """Threads for parallel work when other processes keep `others` of `cores` cores busy: the
    free cores rounded to the nearest whole, between 1 and most."""
    return max(1, min(most, int(cores - others + 0.5)))


def available():
    """The thread count for parallel work the calling thread starts now: the user's where they
    chose one, else the cores the other processes left free (module docstring), measured at
    most every SAMPLE_SECONDS. Costs well under a microsecond between samples."""
    if _fixed is not None:
        return _fixed
    now = time.monotonic()
    if now < getattr(_local, "next", 0.0):
        return _local.available
    with _lock:
        others = _sampler.others()
        if others is not None:
            _others[0] = others
    _local.available = free_threads(_others[0], len(_sampler.cores),
                                    numba.config.NUMBA_NUM_THREADS)
    _local.next = now + SAMPLE_SECONDS
    return _local.available


def parallel_threads():
    """Set numba's thread count for the calling thread to available() and return it."""
    threads = available()
    if threads != getattr(_local, "numba", None):
        numba.set_num_threads(threads)
        _local.numba = threads
    return threads


def fixed():
    """The thread count the user chose (environment or set_threads), or None: chosen by load."""
    return _fixed


def set_threads(n=None):
    """Run the library's parallel kernels on n threads from now on (None: as at import: the
    count the environment named then, or chosen by the load)."""
    global _fixed
    if n is not None and not 1 <= int(n) <= numba.config.NUMBA_NUM_THREADS:
        raise ValueError(f"n: threads between 1 and {numba.config.NUMBA_NUM_THREADS}, got {n}")
    _fixed = _ENVIRONMENT if n is None else int(n)
    _local.__dict__.clear()
