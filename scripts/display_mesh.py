"""Physics on a fine mesh, display on a coarse one: the trade's 0.1 m cantilever (fibers at 40
degrees in x-z, kappa = E, nu = 0.48, gravity, dt = 0.02 s, 100 steps from rest) drawn on its
200-tet mesh, moved by a reduced model built on the 12,800-tet mesh, against the exact
rollouts on both meshes.

    python scripts/display_mesh.py [--modes 5 8] [--json results/display_mesh.json]

For each rollout: the tip's vertical displacement (the mean over the vertices of the free end
face, which both meshes share) at t = 0.2, 0.6, 1 and 2 s, its difference from the 12,800-tet
exact rollout over that rollout's static tip deflection, and the mean ms per step (the step
and the display positions). The reduced rows: the library (numba) with the fine mesh's own
projected gravity, and runtime.ReducedSimulator (numpy) with the file `python -m export
reduced --display` writes, its gravity the display vertices' lumped masses times g. The
framed model of the fine mesh (anisofem.reduced.FramedModel) written likewise (`--framed
--display`), stepped by framed_runtime.FramedSimulator (numpy) and, where a C compiler is, by
the C runtime. Run alone (about two minutes).
"""
import argparse
import os
import tempfile
import time

import numpy as np

import anisofem as af
from anisofem.io.output import publish, result_path
from anisofem.studies.convergence import cantilever
from anisofem.reduced import FramedModel, ReducedModel
from export import native
from export.writers import reduced as writer
from export.framed_runtime import FramedSimulator
from export.runtime import ReducedSimulator

FINE, COARSE = (40, 8, 8), (10, 2, 2)
STEPS, DT = 100, 0.02
CHECKED = (10, 30, 50, 100)


def tip(mesh):
    return af.metrics.end_vertices(mesh, 0, "max")


def exact(scene):
    """(tip z displacement per checked step, ms per step) of the exact rollout."""
    stepper = af.Stepper(scene, DT)
    x, v = scene.initial_positions(), np.zeros((scene.mesh.n_vertices, 3))
    end, out, seconds = tip(scene.mesh), [], []
    for k in range(1, STEPS + 1):
        t0 = time.perf_counter()
        result = stepper(x, v)
        seconds.append(time.perf_counter() - t0)
        x, v = result.x, result.v
        if k in CHECKED:
            out.append(float((x[end] - scene.mesh.vertices[end])[:, 2].mean()))
    return out, 1e3 * float(np.mean(seconds[1:]))


def rollout(step, positions, state, rest, end):
    """(tip z per checked step, ms per step) of a reduced rollout from `state` drawn at `rest`
    points: step(state) -> the next state, positions(state) -> (p, 3)."""
    out, seconds = [], []
    for k in range(1, STEPS + 1):
        t0 = time.perf_counter()
        state = step(state)
        x = positions(state)
        seconds.append(time.perf_counter() - t0)
        if k in CHECKED:
            out.append(float((x[end] - rest[end])[:, 2].mean()))
    return out, 1e3 * float(np.mean(seconds[1:]))


def run(modes, out):
    fine, coarse = cantilever(FINE, 1), cantilever(COARSE, 1)
    reference, fine_ms = exact(fine)
    static = af.solve(fine)
    end_fine = tip(fine.mesh)
    deflection = abs(float((static.x[end_fine] - fine.mesh.vertices[end_fine])[:, 2].mean()))
    rows = [{"name": f"exact, {fine.mesh.n_tets} tets", "tip": reference, "ms": fine_ms}]
    tips, ms = exact(coarse)
    rows.append({"name": f"exact, {coarse.mesh.n_tets} tets", "tip": tips, "ms": ms})
    display = coarse.mesh
    end = tip(display)
    with tempfile.TemporaryDirectory() as folder:
        for m in modes:
            model = ReducedModel(fine, modes=m, validate=False)
            U = model.basis_at(display.vertices)

            def library(state):
                q, w, report = model.step(*state, DT)
                if not report.converged:
                    raise RuntimeError(report.message)
                return q, w
            rest = (np.zeros(model.r), np.zeros(model.r))
            tips, ms = rollout(library, lambda state: display.vertices + U @ state[0], rest,
                               display.vertices, end)
            rows.append({"name": f"reduced m{m} (r = {model.r}) of {fine.mesh.n_tets} tets on "
                                 f"{display.n_tets}, library", "tip": tips, "ms": ms})
            path = os.path.join(folder, f"m{m}")
            writer.write(model, path, display=display)
            sim = ReducedSimulator(path, display.vertices, display.tets)
            force = sim.masses[:, None] * np.array([0.0, 0.0, -9.81])
            tips, ms = rollout(lambda state: sim.step(*state, force, DT),
                               lambda state: sim.positions(state[0]), rest, display.vertices,
                               end)
            rows.append({"name": f"reduced m{m} (r = {model.r}) of {fine.mesh.n_tets} tets on "
                                 f"{display.n_tets}, runtime file", "tip": tips, "ms": ms})
        rows += framed_rows(fine, display, end, folder)
    for row in rows:
        row["error"] = [abs(a - b) / deflection for a, b in zip(row["tip"], reference)]
    report = {"times": [k * DT for k in CHECKED], "static_deflection": deflection, "rows": rows}
    return publish(report, _print, out)


def framed_rows(fine, display, end, folder):
    """The framed model of the fine scene written for the display mesh, stepped by the numpy
    runtime and (with a C compiler) the C runtime: rows as run() makes them."""
    model = FramedModel(fine, validate=False)
    path = os.path.join(folder, "framed")
    writer.write_framed(model, path, display=display)
    sims = [("runtime file", FramedSimulator(path, display.vertices, display.tets))]
    if native.compiler():
        sims.append(("C runtime", native.CFramedSimulator(path, native.build(folder))))
    force = sims[0][1].masses[:, None] * np.array([0.0, 0.0, -9.81])
    rows = []
    for label, sim in sims:
        tips, ms = rollout(lambda states: (sim.step(*states, force, DT), states[0]),
                           lambda states: sim.positions(states[0]), (sim.rest_state(),) * 2,
                           display.vertices, end)
        rows.append({"name": f"framed (r = {model.r}) of {fine.mesh.n_tets} tets on "
                             f"{display.n_tets}, {label}", "tip": tips, "ms": ms})
    return rows


def _print(report):
    times = " / ".join(f"{t:g}" for t in report["times"])
    print(f"{'rollout':<56} {'tip z mm at t = ' + times + ' s':<34} {'error':<30} ms/step")
    for row in report["rows"]:
        tips = " / ".join(f"{1e3 * z:.1f}" for z in row["tip"])
        errors = " / ".join(f"{e:.2g}" for e in row["error"])
        print(f"{row['name']:<56} {tips:<34} {errors:<30} {row['ms']:.3g}")
    print(f"errors: tip difference from the {FINE[0] * FINE[1] * FINE[2] * 5:,}-tet exact "
          f"rollout over its static deflection ({1e3 * report['static_deflection']:.1f} mm)")


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--modes", type=int, nargs="+", default=[5, 8])
    parser.add_argument("--json", default=result_path("display_mesh.json"))
    args = parser.parse_args()
    run(args.modes, args.json)


if __name__ == "__main__":
    main()
