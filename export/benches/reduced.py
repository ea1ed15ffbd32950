"""`python -m export bench-reduced`: what a reduced model costs on the trade's cantilever
(0.1 x 0.02 x 0.02 m, fibers at 40 degrees in x-z, kappa = E, nu = 0.48, gravity) at 200,
12,800 and 102,400 tets, for 5, 8 and 10 vibration modes (r = 20, 44, 65): its build time
(basis and polynomial; the validation's full static solve apart), the size of its arrays
files, the mean time of a backward-Euler step (dt = 0.02 s, 100 steps from rest, the first left
out) in the library (numba), in runtime.ReducedSimulator (numpy) and in the C runtime (export/c,
built with the system C compiler; left out without one), and its validation's tip error against
the full FEM (static for a modal basis; with --snapshots S, bases of the modes and S directions
fitted to the default declared loads, the largest over 3 unseen drags' rollouts); with
--framed, also the framed model (anisofem.reduced.FramedModel) of each mesh, its runtimes
export/framed_runtime.py and the C runtime's af_framed_step ("framed" in the fitted column).
Prints a table and writes JSON (atomically). Run alone."""
import os
import tempfile
import time

import numpy as np

from anisofem.studies.convergence import cantilever
from anisofem.io.output import publish
from anisofem.reduced import FramedModel, ReducedModel

from .. import native
from ..writers import reduced
from ..framed_runtime import FramedSimulator
from ..runtime import ReducedSimulator

#: mesh label -> box_beam cells of the 0.1 m cantilever (5 tets per cell)
MESHES = {"200": (10, 2, 2), "12800": (40, 8, 8), "102400": (80, 16, 16)}
MODES = (5, 8, 10)
STEPS = 100
DT = 0.02


def _step_times(step, state):
    """Mean seconds of STEPS - 1 steps after the first; step(state) -> state."""
    state = step(state)
    t0 = time.perf_counter()
    for _ in range(STEPS - 1):
        state = step(state)
    return (time.perf_counter() - t0) / (STEPS - 1)


def measure(cells, modes, folder, snapshots=0, lib=None):
    """One row: the model of cantilever(cells) with `modes` modes (and `snapshots` fitted
    directions); lib, the C runtime's shared library (None: no C column)."""
    scene = cantilever(cells, 1)
    model = ReducedModel(scene, modes=modes, snapshots=snapshots)
    path = os.path.join(folder, "model")
    reduced.write(model, path)
    size = sum(os.path.getsize(path + ext) for ext in (".json", ".bin"))

    def library(state):
        q, v, report = model.step(*state, DT)
        if not report.converged:
            raise RuntimeError(f"reduced step failed: {report.message}")
        return q, v
    sim = ReducedSimulator(path)
    force = np.asarray(scene.external_force)

    def runtime(state):
        return sim.step(*state, force, DT)

    def c_runtime(state):
        c_sim.step(*state, force, DT)
        return state
    zero = (np.zeros(model.r), np.zeros(model.r))
    c_ms = None
    if lib is not None:
        c_sim = native.CReducedSimulator(path, lib)
        c_ms = 1e3 * _step_times(c_runtime, (np.zeros(model.r), np.zeros(model.r)))
    v = model.validation
    return {"tets": scene.mesh.n_tets, "unknowns": scene.n_free, "modes": modes,
            "snapshots": snapshots, "r": model.r, "build_s": model.build_seconds,
            "snapshot_s": model.snapshots.seconds if model.snapshots else 0.0,
            "validation_s": v.full_seconds, "file_mb": size / 1e6,
            "library_ms": 1e3 * _step_times(library, zero),
            "runtime_ms": 1e3 * _step_times(runtime, zero), "c_ms": c_ms,
            "tip_error": v.tip_error, "validation_cases": v.cases}


def measure_framed(cells, folder, lib=None):
    """One row: the framed model (anisofem.reduced.FramedModel, its defaults) of
    cantilever(cells); lib, the C runtime's shared library (None: no C column)."""
    scene = cantilever(cells, 1)
    model = FramedModel(scene)
    path = os.path.join(folder, "framed")
    reduced.write_framed(model, path)
    size = sum(os.path.getsize(path + ext) for ext in (".json", ".bin"))
    force = np.asarray(scene.external_force)

    def library(states):
        after, report = model.step(*states, DT)
        if not report.converged:
            raise RuntimeError(f"framed step failed: {report.message}")
        return after, states[0]
    sim = FramedSimulator(path)

    def runtime(states):
        return sim.step(*states, force, DT), states[0]
    c_ms = None
    if lib is not None:
        c_sim = native.CFramedSimulator(path, lib)

        def c_runtime(states):
            return c_sim.step(*states, force, DT), states[0]
        c_ms = 1e3 * _step_times(c_runtime, (c_sim.rest_state(),) * 2)
    v = model.validation
    return {"tets": scene.mesh.n_tets, "unknowns": scene.n_free, "modes": None,
            "snapshots": "framed", "r": model.r, "build_s": model.build_seconds,
            "snapshot_s": model.snapshots.seconds, "validation_s": v.full_seconds,
            "file_mb": size / 1e6, "library_ms": 1e3 * _step_times(library, (model.rest(),) * 2),
            "runtime_ms": 1e3 * _step_times(runtime, (sim.rest_state(),) * 2), "c_ms": c_ms,
            "tip_error": v.tip_error, "validation_cases": v.cases}


def run(sizes=tuple(MESHES), modes=MODES, out=None, snapshots=0, framed=False):
    """Measure every (size, modes) pair, and with framed the framed model of each size; print
    the table, write JSON to out."""
    rows = []
    with tempfile.TemporaryDirectory() as folder:
        lib = native.build(folder) if native.compiler() else None
        for size in sizes:
            for m in modes:
                rows.append(measure(MESHES[size], m, folder, snapshots, lib))
                print(f"  {size} tets, {m} modes done", flush=True)
            if framed:
                rows.append(measure_framed(MESHES[size], folder, lib))
                print(f"  {size} tets, framed done", flush=True)
    return publish({"steps": STEPS, "dt": DT, "rows": rows}, _print, out)


def _print(report):
    print(f"{'tets':>7} {'r':>3} {'fitted':>6} {'build s':>8} {'file MB':>8} {'library ms':>11} "
          f"{'runtime ms':>11} {'C ms':>8} {'tip err':>8}")
    for r in report["rows"]:
        c_ms = "-" if r["c_ms"] is None else f"{r['c_ms']:.3g}"
        print(f"{r['tets']:>7} {r['r']:>3} {r['snapshots']:>6} {r['build_s']:>8.3g} "
              f"{r['file_mb']:>8.3g} {r['library_ms']:>11.3g} {r['runtime_ms']:>11.3g} "
              f"{c_ms:>8} {r['tip_error']:>8.2g}")
    print(f"(ms per backward-Euler step of {report['dt']} s, mean of {report['steps'] - 1} after "
          f"the first; the build, snapshots included, leaves out the validation's full FEM; "
          f"tip err: static for modal bases, the largest over 3 unseen drags' rollouts for "
          f"fitted and framed ones)")
