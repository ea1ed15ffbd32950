"""`python -m export bench-reduced`: what a reduced model costs on the trade's cantilever
(0.1 x 0.02 x 0.02 m, fibers at 40 degrees in x-z, kappa = E, nu = 0.48, gravity) at 200,
12,800 and 102,400 tets, for 5, 8 and 10 vibration modes (r = 20, 44, 65): its build time
(basis and polynomial; the validation's full static solve apart), the size of its arrays
files, the mean time of a backward-Euler step (dt = 0.02 s, 100 steps from rest, the first left
out) in the library (numba) and in runtime.ReducedSimulator (numpy), and its static tip error
against the full FEM. Prints a table and writes JSON (atomically). Run alone."""
import os
import tempfile
import time

import numpy as np

from anisofem.convergence import cantilever
from anisofem.files import publish
from anisofem.reduced import ReducedModel

from . import reduced
from .runtime import ReducedSimulator

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


def measure(cells, modes, folder):
    """One row: the model of cantilever(cells) with `modes` modes."""
    scene = cantilever(cells, 1)
    model = ReducedModel(scene, modes=modes)
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
    zero = (np.zeros(model.r), np.zeros(model.r))
    v = model.validation
    return {"tets": scene.mesh.n_tets, "unknowns": scene.n_free, "modes": modes, "r": model.r,
            "build_s": model.build_seconds, "validation_s": v.full_seconds,
            "file_mb": size / 1e6, "library_ms": 1e3 * _step_times(library, zero),
            "runtime_ms": 1e3 * _step_times(runtime, zero),
            "static_tip_error": v.tip_error}


def run(sizes=tuple(MESHES), modes=MODES, out=None):
    """Measure every (size, modes) pair; print the table, write JSON to out."""
    rows = []
    with tempfile.TemporaryDirectory() as folder:
        for size in sizes:
            for m in modes:
                rows.append(measure(MESHES[size], m, folder))
                print(f"  {size} tets, {m} modes done", flush=True)
    return publish({"steps": STEPS, "dt": DT, "rows": rows}, _print, out)


def _print(report):
    print(f"{'tets':>7} {'r':>3} {'build s':>8} {'file MB':>8} {'library ms':>11} "
          f"{'runtime ms':>11} {'static tip err':>15}")
    for r in report["rows"]:
        print(f"{r['tets']:>7} {r['r']:>3} {r['build_s']:>8.3g} {r['file_mb']:>8.3g} "
              f"{r['library_ms']:>11.3g} {r['runtime_ms']:>11.3g} "
              f"{r['static_tip_error']:>15.2g}")
    print(f"(ms per backward-Euler step of {report['dt']} s, mean of {report['steps'] - 1} after "
          f"the first; the build leaves out the validation's full static solve)")
