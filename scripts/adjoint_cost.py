"""What one gradient costs next to the computation it differentiates, in one run, on the
trade's cantilever (fibers at 40 degrees, kappa = E, gravity) on 1,600 and 12,800 tets (or
--cells), J the tip's height:
- statics: the static solve by anisofem.solve, then anisofem.inverse.sensitivity.static_sensitivity
  (one Hessian assembly, one factorization with its definiteness check, one back-substitution,
  the parameter derivatives of every element);
- a 20-step rollout: anisofem.simulate, then sensitivity.rollout_sensitivity (one
  factorization per step);
- the same rollout by the scene's reduced model (4 modes + 16 fitted), then
  reduced.sensitivity.rollout_sensitivity, timed again after its one-time build of the
  derivative polynomials (what a design loop pays per gradient).

    python scripts/adjoint_cost.py [--cells 20x4x4 40x8x8] [--out results/adjoint_cost.json]

Prints a table and writes JSON. Run it alone: a test suite beside it slows either part 2-5x;
the JSON holds the load average at the start and the end.
"""
import argparse
import os
import time

import numpy as np

import anisofem as af
from anisofem.io.output import publish
from anisofem.reduced import ReducedModel
from anisofem.reduced.sensitivity import rollout_sensitivity as reduced_rollout_sensitivity
from anisofem.inverse.sensitivity import rollout_sensitivity, static_sensitivity

#: the rollout: backward-Euler steps of DT s from rest
STEPS, DT = 20, 0.02


def measure(cells):
    """One row: the static solve, the rollout and their gradients of the tip height, full and
    reduced, on box cells (nx, ny, nz)."""
    mesh = af.box_beam((0.1, 0.02, 0.02), cells)
    fiber = np.array([0.766, 0.0, 0.643])
    scene = af.Scene(mesh, af.Material(1e5, 0.48, 1000.0, fiber / np.linalg.norm(fiber), 1e5),
                     fixed=af.metrics.end_vertices(mesh, 0, "min"), gravity=(0, 0, -9.81))
    af.solve(af.default_scene(af.box_beam(cells=(2, 1, 1))))  # compile the kernels first
    tip = af.metrics.end_vertices(mesh, 0, "max")
    gradient = np.zeros_like(mesh.vertices)
    gradient[tip, 2] = 1.0 / tip.size
    rollout_gradient = np.zeros((STEPS + 1,) + mesh.vertices.shape)
    rollout_gradient[STEPS] = gradient
    row = {"tets": mesh.n_tets, "unknowns": scene.n_free}
    result = _timed(row, "solve_s", lambda: af.solve(scene))
    row["newton_iterations"] = result.iterations
    _timed(row, "gradient_s", lambda: static_sensitivity(scene, result, gradient))
    rollout = _timed(row, "rollout_s", lambda: af.simulate(scene, STEPS, DT, warn=False))
    full = _timed(row, "rollout_gradient_s",
                  lambda: rollout_sensitivity(scene, rollout, rollout_gradient, DT))
    model = ReducedModel(scene, modes=4, snapshots=16, validate=False)
    positions, _ = _timed(row, "reduced_rollout_s", lambda: model.rollout(((None, STEPS),), DT))
    _timed(row, "reduced_first_gradient_s",
           lambda: reduced_rollout_sensitivity(model, positions, rollout_gradient, DT))
    reduced = _timed(row, "reduced_gradient_s",
                     lambda: reduced_rollout_sensitivity(model, positions, rollout_gradient, DT))
    row["ratio"] = row["gradient_s"] / row["solve_s"]
    row["reduced_dJdE_vs_full"] = reduced["young"] / float(full.young.sum()) - 1.0
    return row


def _timed(row, key, work):
    """work()'s answer, its seconds in row[key]."""
    t0 = time.perf_counter()
    answer = work()
    row[key] = time.perf_counter() - t0
    return answer


def print_report(report):
    print(f"Gradients of the tip height next to what they differentiate, same run "
          f"(load average {report['load_average_start'][0]:.2f} at the start, "
          f"{report['load_average_end'][0]:.2f} at the end)")
    print(f"{'tets':>7} {'solve s':>8} {'Newton':>6} {'gradient s':>10} {'ratio':>6} | "
          f"{'rollout s':>9} {'gradient s':>10} | {'reduced s':>9} {'gradient s':>10} "
          f"{'(first)':>8} {'dJ/dE vs full':>13}")
    for r in report["rows"]:
        print(f"{r['tets']:7,d} {r['solve_s']:8.2f} {r['newton_iterations']:6d} "
              f"{r['gradient_s']:10.2f} {r['ratio']:6.2f} | {r['rollout_s']:9.2f} "
              f"{r['rollout_gradient_s']:10.2f} | {r['reduced_rollout_s']:9.4f} "
              f"{r['reduced_gradient_s']:10.4f} {r['reduced_first_gradient_s']:8.2f} "
              f"{r['reduced_dJdE_vs_full']:+13.2%}")


def main():
    p = argparse.ArgumentParser(description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--cells", nargs="+", default=["20x4x4", "40x8x8"])
    p.add_argument("--out", default=os.path.join("results", "adjoint_cost.json"))
    args = p.parse_args()
    start = os.getloadavg()
    rows = [measure(tuple(int(c) for c in spec.split("x"))) for spec in args.cells]
    publish({"rows": rows, "steps": STEPS, "dt": DT, "load_average_start": list(start),
             "load_average_end": list(os.getloadavg())}, print_report, args.out)


if __name__ == "__main__":
    main()
