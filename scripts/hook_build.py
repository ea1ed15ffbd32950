"""What building a reduced model costs and says on a body of a few thousand tets that bends far:
a J-shaped hook (a 2 x 2 cm bar 0.3 m long along its axis, the last 0.15 m curled into a half
circle of radius 5 cm, StVK, nu = 0.45, density 1000 kg/m^3, fibers along x with kappa = E),
held at its straight end under gravity, built as a new user would (4 modes + 16 fitted, the
default drags), for each Young's modulus.

    python scripts/hook_build.py [--young 1e6 3e5 1e5] [--json results/hook_build.json]

Per row: the full FEM's static sag (largest displacement) and its Newton iterations, the
build's time (modes, the static snapshots, the polynomial; the snapshots alone beside it),
snapshots kept and turned inside out, r, and the validation against the full FEM on unseen
loads (tip error), or why there is none. Run alone (about three minutes).
"""
import argparse
import time
import warnings

import numpy as np

import anisofem as af
from anisofem.io.output import publish, result_path
from anisofem.reduced import ReducedModel

CELLS, LENGTH, SECTION = (55, 4, 3), 0.3, 0.02
STRAIGHT, RADIUS = 0.15, 0.05


def hook_mesh():
    """The hook's TetMesh: a box beam along x whose part beyond STRAIGHT is wound about an
    axis along y, a half circle of RADIUS, then straight back along -x."""
    beam = af.box_beam(size=(LENGTH, SECTION, SECTION), cells=CELLS)
    X = beam.vertices
    s, depth = X[:, 0], X[:, 2] - SECTION / 2
    turned = np.clip((s - STRAIGHT) / (np.pi * RADIUS), 0.0, 1.0) * np.pi
    bent = s > STRAIGHT
    Y = X.copy()
    Y[bent, 0] = STRAIGHT + (RADIUS - depth[bent]) * np.sin(turned[bent])
    Y[bent, 2] = SECTION / 2 + RADIUS - (RADIUS - depth[bent]) * np.cos(turned[bent])
    beyond = s > STRAIGHT + np.pi * RADIUS
    Y[beyond, 0] = STRAIGHT - (s[beyond] - STRAIGHT - np.pi * RADIUS)
    return af.TetMesh(Y, beam.tets)


def row(mesh, young):
    """One row of the table for Young's modulus `young`, Pa."""
    material = af.Material(young, 0.45, 1000.0, np.array([1.0, 0.0, 0.0]), young)
    scene = af.Scene(mesh, material, fixed=mesh.vertices[:, 0] <= 1e-9,
                     gravity=(0.0, 0.0, -9.81))
    own = af.solve(scene, warn=False)
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        t0 = time.perf_counter()
        model = ReducedModel(scene, modes=4, snapshots=16, validate=False)
        build = time.perf_counter() - t0
    validation = model.validate()
    report = model.snapshots
    return {"young": young, "sag": float(np.linalg.norm(own.x - mesh.vertices, axis=1).max()),
            "iterations": int(own.iterations), "build_s": build,
            "snapshots_s": report.seconds, "kept": report.kept, "inverted": report.inverted,
            "r": model.r, "tip_error": validation.tip_error if validation.cases else None,
            "validation_inverted": validation.inverted,
            "warned": any(issubclass(w.category, af.InversionWarning) for w in said)}


def _print(report):
    print(f"hook: {report['tets']:,} tets, 4 modes + 16 fitted")
    print(f"{'E kPa':>7} {'sag mm':>7} {'Newton':>6} {'build s':>8} {'solves s':>8} "
          f"{'kept':>5} {'inverted':>8} {'r':>3}  validation")
    for r in report["rows"]:
        checked = (f"tip {100 * r['tip_error']:.2g}% off" if r["tip_error"] is not None else
                   f"none: all {r['validation_inverted']} drawn cases turn elements inside out")
        print(f"{r['young'] / 1e3:7.0f} {1e3 * r['sag']:7.1f} {r['iterations']:6d} "
              f"{r['build_s']:8.1f} {r['snapshots_s']:8.1f} {r['kept']:5d} {r['inverted']:8d} "
              f"{r['r']:3d}  {checked}{'; the build warned' if r['warned'] else ''}")


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--young", type=float, nargs="+", default=[1e6, 3e5, 1e5])
    parser.add_argument("--json", default=result_path("hook_build.json"))
    args = parser.parse_args()
    mesh = hook_mesh()
    report = {"tets": mesh.n_tets, "rows": [row(mesh, e) for e in args.young]}
    publish(report, _print, args.json)


if __name__ == "__main__":
    main()
