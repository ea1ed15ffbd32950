"""`python -m anisofem bench --robustness`: whether every solve reaches an equilibrium, over a
grid of soft cantilevers (0.02 x 0.02 m section) where Newton meets compressive instabilities:
lengths LENGTHS, cells CELLS, no fiber, fibers along the beam and at 40 degrees in x-z
(kappa = E), both base materials, the loads LOADS (multiples of g). For each static solve
(default method and load continuation, from rest): converged, iterations, seconds, load
increments (0 where the whole load was solved at once), whether the state is a minimum (the
smallest eigenvalue of the free Hessian, anisofem.solvers.stability) and physical (no element turned
inside out); with dynamics=True also ten backward-Euler steps at each of DTS at
DYNAMIC_LOADS. Prints a summary table and the failures, writes JSON."""
import itertools
import math
import sys
import time
import warnings

import numpy as np

from ..io.output import publish, scratch_path
from ..physics.material import Material
from ..physics.meshgen import box_beam
from ..physics.metrics import end_vertices
from ..physics.scene import Scene
from ..solvers.solve import simulate, solve

LENGTHS = (0.05, 0.1, 0.2)                       # m
CELLS = ((10, 2, 2), (20, 4, 4), (30, 6, 6))
FIBERS = {"none": None, "x": (1.0, 0.0, 0.0),
          "40 deg": (math.cos(math.radians(40)), 0.0, math.sin(math.radians(40)))}
BASES = ("stvk", "neohookean")
LOADS = (1, 2, 5, 10, 30, 100)                   # g
DYNAMIC_LOADS = (1, 10, 100)                     # g
DTS = (0.02, 0.2, 1.0)                           # s
STEPS = 10
G = 9.81                                         # m/s^2


def scene(length, cells, fiber, base, load):
    """The cantilever of the grid: held at x = 0, gravity load * G along -z."""
    mesh = box_beam(size=(length, 0.02, 0.02), cells=cells)
    direction = FIBERS[fiber]
    material = Material(1e5, 0.48, 1000.0, direction or (1.0, 0.0, 0.0),
                        0.0 if direction is None else 1e5, model=base)
    return Scene(mesh, material, fixed=end_vertices(mesh, 0, "min"),
                 gravity=(0.0, 0.0, -G * load))


def _cases(loads):
    return itertools.product(LENGTHS, CELLS, FIBERS, BASES, loads)


def static_row(length, cells, fiber, base, load):
    """One static solve of the grid (see the module docstring): a dict."""
    s = scene(length, cells, fiber, base, load)
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        r = solve(s)
    seconds = time.perf_counter() - t0
    st = r.stability
    return {"length": length, "cells": list(cells), "fiber": fiber, "base": base, "g": load,
            "converged": r.converged, "iterations": r.iterations, "seconds": seconds,
            "message": r.message, "minimum": st.minimum, "smallest_eigenvalue": st.smallest,
            "inverted": r.inversion.inverted, "increments": r.increments}


def dynamic_row(length, cells, fiber, base, load, dt):
    """STEPS backward-Euler steps of dt (s) of the grid's cantilever from rest: a dict."""
    s = scene(length, cells, fiber, base, load)
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        roll = simulate(s, STEPS, dt)
    last = roll.steps[-1].newton
    return {"length": length, "cells": list(cells), "fiber": fiber, "base": base, "g": load,
            "dt": dt, "converged": roll.converged, "steps": len(roll.positions) - 1,
            "iterations": float(np.mean([r.newton.iterations for r in roll.steps])),
            "seconds": time.perf_counter() - t0, "message": last.message}


def run(dynamics=False, out=scratch_path("robustness.json")):
    """Every static case (and with dynamics every rollout) of the grid; prints the tables,
    writes JSON to out (if given)."""
    cases = list(_cases(LOADS))
    statics = []
    for k, case in enumerate(cases, 1):
        statics.append(static_row(*case))
        print(f"\r  static {k}/{len(cases)}", end="", file=sys.stderr, flush=True)
    report = {"statics": statics}
    if dynamics:
        rollouts = list(itertools.product(_cases(DYNAMIC_LOADS), DTS))
        report["dynamics"] = []
        for k, (case, dt) in enumerate(rollouts, 1):
            report["dynamics"].append(dynamic_row(*case, dt))
            print(f"\r  dynamics {k}/{len(rollouts)}", end="", file=sys.stderr, flush=True)
    print(file=sys.stderr)
    return publish(report, print_report, out)


def print_report(report):
    """Per base material and load: solves reaching a minimum, converged, median iterations
    and seconds; then every case that did not reach a minimum."""
    rows = report["statics"]
    print("Static solves from rest (default method): per base and load, how many cantilevers")
    print(f"{'base':<11} {'g':>4} | {'minimum':>7} {'converged':>9} {'inverted':>8} "
          f"{'ramped':>6} | {'median its':>10} {'median s':>8} {'max s':>7}")
    for base, load in itertools.product(BASES, LOADS):
        group = [r for r in rows if r["base"] == base and r["g"] == load]
        if not group:
            continue
        good = [r for r in group if r["converged"] and r["minimum"]]
        print(f"{base:<11} {load:4g} | {len(good):4d}/{len(group):<2d} "
              f"{sum(r['converged'] for r in group):9d} "
              f"{sum(r['inverted'] > 0 for r in group):8d} "
              f"{sum(r['increments'] > 0 for r in group):6d} | "
              f"{np.median([r['iterations'] for r in group]):10.1f} "
              f"{np.median([r['seconds'] for r in group]):8.3f} "
              f"{max(r['seconds'] for r in group):7.2f}")
    for r in rows:
        if not (r["converged"] and r["minimum"]):
            print(f"  not a minimum: {_label(r)}: {r['message']}, {r['iterations']} its, "
                  f"smallest eigenvalue {r['smallest_eigenvalue']:.3g} N/m")
    if "dynamics" in report:
        dyn = report["dynamics"]
        print(f"\nBackward Euler, {STEPS} steps from rest: rollouts whose every step converged")
        for base, load, dt in itertools.product(BASES, DYNAMIC_LOADS, DTS):
            group = [r for r in dyn if r["base"] == base and r["g"] == load and r["dt"] == dt]
            if not group:
                continue
            print(f"{base:<11} {load:4g} g  dt {dt:<5g} | {sum(r['converged'] for r in group):3d}"
                  f" of {len(group)}, median {np.median([r['iterations'] for r in group]):.1f}"
                  f" iterations per step, {np.median([r['seconds'] for r in group]):.2f} s")
        for r in dyn:
            if not r["converged"]:
                print(f"  stopped: {_label(r)}, dt {r['dt']:g}: step {r['steps'] + 1}: "
                      f"{r['message']}")


def _label(row):
    cells = "x".join(map(str, row["cells"]))
    return f"{row['length']:g} m {cells} fiber {row['fiber']} {row['base']} {row['g']:g} g"
