"""What one gradient of a static objective costs next to the solve it differentiates, in one
run: the trade's cantilever (fibers at 40 degrees, kappa = E, gravity) on 12,800 tets (and
smaller), its static solve by anisofem.solve, then anisofem.sensitivity.static_sensitivity of
the tip's height (one Hessian assembly, one factorization with its definiteness check, one
back-substitution, the parameter derivatives of every element).

    python scripts/adjoint_cost.py [--cells 40x8x8 20x4x4] [--out results/adjoint_cost.json]

Prints a table (seconds of each, their ratio, the forward's Newton iterations) and writes JSON.
Run it alone: a test suite beside it slows either part 2-5x.
"""
import argparse
import os
import time

import numpy as np

import anisofem as af
from anisofem.files import publish
from anisofem.sensitivity import static_sensitivity


def measure(cells):
    """One row: the static solve and the gradient of the tip height on box cells (nx, ny, nz)."""
    mesh = af.box_beam((0.1, 0.02, 0.02), cells)
    fiber = np.array([0.766, 0.0, 0.643])
    scene = af.Scene(mesh, af.Material(1e5, 0.48, 1000.0, fiber / np.linalg.norm(fiber), 1e5),
                     fixed=af.metrics.end_vertices(mesh, 0, "min"), gravity=(0, 0, -9.81))
    af.solve(af.default_scene(af.box_beam(cells=(2, 1, 1))))  # compile the kernels first
    t0 = time.perf_counter()
    result = af.solve(scene)
    forward = time.perf_counter() - t0
    tip = af.metrics.end_vertices(mesh, 0, "max")
    gradient = np.zeros_like(mesh.vertices)
    gradient[tip, 2] = 1.0 / tip.size
    t0 = time.perf_counter()
    sensitivity = static_sensitivity(scene, result, gradient)
    backward = time.perf_counter() - t0
    return {"tets": mesh.n_tets, "unknowns": scene.n_free, "solve_s": forward,
            "newton_iterations": result.iterations, "method": result.method,
            "gradient_s": backward, "ratio": backward / forward,
            "dtip_dkappa_total": float(sensitivity.kappa.sum())}


def print_report(report):
    print("Static solve and one adjoint gradient of the tip height, same run")
    print(f"{'tets':>7} {'unknowns':>9} {'solve s':>8} {'Newton':>6} {'gradient s':>10} "
          f"{'gradient / solve':>16}")
    for r in report["rows"]:
        print(f"{r['tets']:7,d} {r['unknowns']:9,d} {r['solve_s']:8.2f} "
              f"{r['newton_iterations']:6d} {r['gradient_s']:10.2f} {r['ratio']:16.2f}")


def main():
    p = argparse.ArgumentParser(description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--cells", nargs="+", default=["20x4x4", "40x8x8"])
    p.add_argument("--out", default=os.path.join("results", "adjoint_cost.json"))
    args = p.parse_args()
    rows = [measure(tuple(int(c) for c in spec.split("x"))) for spec in args.cells]
    publish({"rows": rows}, print_report, args.out)


if __name__ == "__main__":
    main()
