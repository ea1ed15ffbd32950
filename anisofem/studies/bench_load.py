"""`python -m anisofem bench --under-load`: every rung of the trade on the trade's 200-tet and
12,800-tet cantilevers, idle and beside K busy processes (K: the cores this process may run on
by default), each rung's ms per step in both and the slowdown.

Each rung is timed idle, then again while K processes that spin in a Python loop share the
cores (started before and stopped after that rung's timing, by this command), then the next
rung: a drift of the machine's speed over the run reaches both timings of a rung alike. A
rung's time is the median over its steps from rest (the first, which compiles and builds,
left out) and over `repeats` rollouts. The busy cores that anisofem.threads measured beside each
timing are reported with it.
"""
import math
import os
import subprocess
import sys
import time

import numpy as np

from .rungs import fem_rungs, registered_rungs, select_rungs
from .. import threads
from ..io.output import result_path, write_json
from ..physics.material import Material
from ..physics.meshgen import box_beam
from ..physics.metrics import end_vertices
from ..physics.scene import Scene

#: name -> (cells, steps per rollout, rollouts per timing)
SCENES = {"200": ((10, 2, 2), 20, 3), "12800": ((40, 8, 8), 5, 1)}
#: the trade's cantilever: 0.1 x 0.02 x 0.02 m, fibers at 40 degrees in x-z, kappa = E
FIBER = (math.cos(math.radians(40)), 0.0, math.sin(math.radians(40)))
DT = 0.02
#: A rollout goes on (up to 50 times its steps) until it has lasted this long, s
MIN_SECONDS = 0.3


def cantilever(cells):
    """The trade cantilever of the README's table with `cells` hex cells (5 tets each)."""
    mesh = box_beam((0.1, 0.02, 0.02), cells)
    material = Material(1e5, 0.48, 1000.0, FIBER, 1e5)
    return Scene(mesh, material, fixed=end_vertices(mesh, 0, "min"), gravity=(0, 0, -9.81))


class Busy:
    """K processes that keep a core each busy (a Python loop), while in the with block."""

    def __init__(self, k):
        self.k = k
        self.procs = []

    def __enter__(self):
        self.procs = [subprocess.Popen([sys.executable, "-c", "while True: pass"])
                      for _ in range(self.k)]
        time.sleep(0.3)  # let them start
        return self

    def __exit__(self, *exc):
        for p in self.procs:
            p.terminate()
        for p in self.procs:
            p.wait()
        time.sleep(0.3)  # the cores free again before the next idle timing


def time_rung(rung, scene, steps):
    """Median ms per step of dt of rung rolled out `steps` steps from rest (the first step
    left out; a fast rung steps on until MIN_SECONDS have passed), and the cores other
    processes kept busy meanwhile (anisofem.threads.LoadMeter)."""
    advance = rung.make(scene, DT * rung.dt_factor)
    x = scene.initial_positions()
    v = np.zeros_like(x)
    seconds = []
    meter = threads.LoadMeter()
    own_steps = max(2, steps // rung.dt_factor)
    start = time.perf_counter()
    # a fast rung (the reduced models) steps on, to at most 50 times as many steps, until
    # MIN_SECONDS have passed: a few steps of 0.1 ms are no measurement
    while len(seconds) < own_steps or (time.perf_counter() - start < MIN_SECONDS
                                       and len(seconds) < 50 * own_steps):
        t0 = time.perf_counter()
        x, v, info = advance(x, v)
        seconds.append(time.perf_counter() - t0)
        if info["failed"]:
            break
    return 1e3 * float(np.median(seconds[1:])) / rung.dt_factor, meter.others(wait=True) or 0.0


def _timing(rung, scene, steps, repeats):
    runs = [time_rung(rung, scene, steps) for _ in range(repeats)]
    return float(np.median([r[0] for r in runs])), float(np.mean([r[1] for r in runs]))


def run(busy=None, scenes=tuple(SCENES), rungs=None, out=result_path("bench_under_load.json"),
        progress=True):
    """Time every rung idle and beside `busy` busy processes (default: the cores this process
    may run on) on each scene of SCENES; print the table and write the JSON to out.
    rungs: names to keep (default all, the surrogates' where installed)."""
    cores = len(threads.cores())
    busy = cores if busy is None else int(busy)
    if busy < 1:
        raise ValueError(f"busy: at least one busy process, got {busy}")
    rows = []
    for name in scenes:
        cells, steps, repeats = SCENES[name]
        scene = cantilever(cells)
        notes = []
        chosen = fem_rungs() + registered_rungs(scene, DT, notes)
        if rungs:
            chosen = select_rungs(chosen, rungs)
        for i, rung in enumerate(chosen, 1):
            if progress and sys.stderr.isatty():
                print(f"\r{name} tets [{i}/{len(chosen)}] {rung.name}" + " " * 20,
                      end="", file=sys.stderr, flush=True)
            idle, idle_busy = _timing(rung, scene, steps, repeats)
            with Busy(busy):
                loaded, loaded_busy = _timing(rung, scene, steps, repeats)
            rows.append({"tets": scene.mesh.n_tets, "rung": rung.name, "kind": rung.kind,
                         "idle_ms": idle, "loaded_ms": loaded, "slowdown": loaded / idle,
                         "idle_busy_cores": idle_busy, "loaded_busy_cores": loaded_busy})
        for note in notes:
            print(f"note ({name} tets): {note}", file=sys.stderr)
    if progress and sys.stderr.isatty():
        print(file=sys.stderr)
    report = {"cores": cores, "busy_processes": busy, "load_average": os.getloadavg(),
              "user_threads": threads.fixed(), "rows": rows}
    print(table(report))
    write_json(out, report)
    print(f"-> {out}")
    return report


def table(report):
    """The report of run() as a text table."""
    head = (f"{'tets':>6} {'rung':<30} {'idle ms':>9} {'busy ms':>9} {'slowdown':>9} "
            f"{'others idle':>12} {'others busy':>12}")
    lines = [f"ms per step idle and beside {report['busy_processes']} busy processes, "
             f"{report['cores']} cores (others: cores the other processes kept busy, measured)",
             head, "-" * len(head)]
    for r in report["rows"]:
        lines.append(f"{r['tets']:>6} {r['rung']:<30} {r['idle_ms']:9.3g} {r['loaded_ms']:9.3g} "
                     f"{r['slowdown']:8.2f}x {r['idle_busy_cores']:12.2f} "
                     f"{r['loaded_busy_cores']:12.2f}")
    return "\n".join(lines)
