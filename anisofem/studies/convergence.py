"""`python -m anisofem bench --convergence`: how far the mesh is from the body, and the cheapest
mesh within 2% of it. The static tip sag of the trade's cantilever (0.1 x 0.02 x 0.02 m, fibers
at 40 degrees in x-z, kappa = E, nu = 0.48, gravity) with linear and quadratic tets, each cell
split into 5 or 6 tets (meshgen.box_beam), on 10 x 2 x 2 cells refined k times for each k of
the refinements; rows past max_unknowns are left out. The converged sag is Richardson's
extrapolation of the finest three quadratic 6-tet sags (each sequence's own estimate is
reported too, as the limit's spread). Each row: its error against that limit, unknowns, static
solve time, and the time of a backward-Euler step of the trade's dynamics (dt = 0.02 s from
rest, the default method). Then, for linear and for quadratic tets, the row with the cheapest
step among those within 2% of the limit. Prints a table and writes JSON (atomically). Run alone
(about ten minutes with the default refinements)."""
import math
import time

import numpy as np
from scipy.optimize import brentq

from ..io.output import publish, result_path
from ..physics.material import Material
from ..physics.meshgen import box_beam
from ..physics.metrics import end_vertices, tip_displacement
from ..physics.scene import Scene
from ..solvers.solve import Stepper, solve

BASE_CELLS = (10, 2, 2)
#: refinements of BASE_CELLS measured by default (cells k nx, k ny, k nz)
REFINEMENTS = (1, 2, 3, 4, 6, 8, 12)
#: rows with more unknowns are left out by default (the 12x linear meshes have 225,000; the 8x
#: quadratic ones 461,280 and 522,720 take minutes per solve)
MAX_UNKNOWNS = 250_000
ORDERS = (1, 2)
TETS_PER_CELL = (5, 6)
#: the sequence whose extrapolation is the limit: (order, tets per cell)
REFERENCE = (2, 6)
#: the error against the limit a mesh must be within to count for "cheapest"
WITHIN = 0.02
#: the trade's time step (s), and the steps timed after a first (untimed) one
DT = 0.02
TIMED_STEPS = 3
#: the convergence orders Richardson's extrapolation looks for
ORDER_RANGE = (1e-3, 20.0)


def cantilever(cells, order, tets_per_cell=5):
    """The trade's 0.1 m cantilever on box_beam(cells) with tets of `order`."""
    mesh = box_beam(size=(0.1, 0.02, 0.02), cells=cells, order=order,
                    tets_per_cell=tets_per_cell)
    angle = math.radians(40.0)
    material = Material(1e5, 0.48, 1000.0, (math.cos(angle), 0.0, math.sin(angle)), 1e5)
    return Scene(mesh, material, fixed=end_vertices(mesh, 0, "min"), gravity=(0.0, 0.0, -9.81))


def sag(scene):
    """(downward tip displacement in m, seconds, converged) of the static solve."""
    start = time.perf_counter()
    result = solve(scene, warn=False)
    seconds = time.perf_counter() - start
    return -float(tip_displacement(scene.mesh, result.x)[2]), seconds, bool(result.converged)


def step_time(scene, dt=DT, steps=TIMED_STEPS):
    """(ms per backward-Euler step, Newton iterations per step) from rest, the first step
    (compilation, set-up) not counted."""
    stepper = Stepper(scene, dt, warn=False)
    x = scene.initial_positions()
    v = np.zeros_like(x)
    res = stepper(x, v)
    start = time.perf_counter()
    iterations = 0
    for _ in range(steps):
        res = stepper(res.x, res.v)
        iterations += res.newton.iterations
    return 1e3 * (time.perf_counter() - start) / steps, iterations / steps


def richardson(refinements, values):
    """(limit, order p) of values converging as s(k) = limit - C k^-p in the refinement k,
    from the last three (k increasing). ValueError when they do not converge monotonically."""
    k1, k2, k3 = (float(k) for k in refinements[-3:])
    s1, s2, s3 = values[-3:]
    ratio = (s2 - s1) / (s3 - s2)
    if not (s2 - s1) * (s3 - s2) > 0:
        raise ValueError(f"richardson: {values[-3:]} do not converge monotonically")

    def mismatch(p):
        return (k1 ** -p - k2 ** -p) / (k2 ** -p - k3 ** -p) - ratio
    if mismatch(ORDER_RANGE[0]) * mismatch(ORDER_RANGE[1]) > 0:
        raise ValueError(f"richardson: {values[-3:]} converge at no order in {ORDER_RANGE} "
                         f"(not yet in the asymptotic range)")
    p = brentq(mismatch, *ORDER_RANGE)
    c = (s2 - s1) / (k1 ** -p - k2 ** -p)
    return s3 + c * k3 ** -p, p


def cheapest(rows, order, within=WITHIN):
    """The row of `order` with the fastest step among the converged ones within `within` of
    the limit, or None."""
    good = [r for r in rows if r["order"] == order and r["converged"]
            and abs(r["error"]) <= within]
    return min(good, key=lambda r: r["ms_per_step"]) if good else None


def run(out=result_path("convergence.json"), refinements=REFINEMENTS,
        max_unknowns=MAX_UNKNOWNS):
    refinements = sorted(set(int(k) for k in refinements))
    if len(refinements) < 3 or refinements[0] < 1:
        raise ValueError(f"refinements: at least three positive factors, got {refinements}")
    rows = []
    for order in ORDERS:
        for split in TETS_PER_CELL:
            for k in refinements:
                cells = tuple(k * c for c in BASE_CELLS)
                scene = cantilever(cells, order, split)
                if scene.n_free > max_unknowns:
                    break
                value, seconds, converged = sag(scene)
                ms, iterations = step_time(scene)
                rows.append({"order": order, "tets_per_cell": split, "refinement": k,
                             "cells": list(cells), "tets": scene.mesh.n_tets,
                             "unknowns": scene.n_free, "sag": value, "seconds": seconds,
                             "converged": converged, "ms_per_step": ms,
                             "iterations_per_step": iterations})
                print(f"  order {order}, {split} tets per cell, cells {cells}: "
                      f"{1e3 * value:.3f} mm, {ms:.1f} ms per step", flush=True)
    sequences = {}
    for order in ORDERS:
        for split in TETS_PER_CELL:
            seq = [r for r in rows if r["order"] == order and r["tets_per_cell"] == split]
            if len(seq) < 3:
                continue
            try:
                limit, p = richardson([r["refinement"] for r in seq], [r["sag"] for r in seq])
            except ValueError:
                limit = p = None
            sequences[f"order {order}, {split} tets per cell"] = {
                "order": order, "tets_per_cell": split, "limit": limit, "observed_order": p}
    name = f"order {REFERENCE[0]}, {REFERENCE[1]} tets per cell"
    if sequences.get(name, {}).get("limit") is None:
        raise ValueError(f"refinements, max_unknowns: the reference sequence ({name}) needs "
                         f"three rows converging at an order in {ORDER_RANGE}; got "
                         f"{[r['sag'] for r in rows if (r['order'], r['tets_per_cell']) == REFERENCE]}")
    limit = sequences[name]["limit"]
    for r in rows:
        r["error"] = (limit - r["sag"]) / limit
    report = {"reference": f"Richardson extrapolation of the finest three sags of {name}",
              "limit": limit, "sequences": sequences, "within": WITHIN, "rows": rows,
              "cheapest": {str(o): cheapest(rows, o) for o in ORDERS}}
    return publish(report, _print, out)


def _describe(r):
    return (f"{'x'.join(map(str, r['cells']))} cells, {r['tets_per_cell']} tets per cell "
            f"({r['tets']:,} tets, {r['unknowns']:,} unknowns), {r['ms_per_step']:.4g} ms per "
            f"step, {100 * abs(r['error']):.2f}% {'below' if r['error'] >= 0 else 'above'}")


def _print(report):
    print(f"{'order':>5} {'split':>5} {'cells':>10} {'tets':>7} {'unknowns':>9} {'sag mm':>8} "
          f"{'below limit':>12} {'solve s':>8} {'ms/step':>9}")
    for r in report["rows"]:
        cells = "x".join(map(str, r["cells"]))
        print(f"{r['order']:>5} {r['tets_per_cell']:>5} {cells:>10} {r['tets']:>7} "
              f"{r['unknowns']:>9} {1e3 * r['sag']:>8.3f} {100 * r['error']:>11.2f}% "
              f"{r['seconds']:>8.2f} {r['ms_per_step']:>9.4g}")
    print(f"limit {1e3 * report['limit']:.3f} mm ({report['reference']})")
    for name, s in report["sequences"].items():
        print(f"  {name}: " + ("not in the asymptotic range" if s["limit"] is None else
                               f"its own limit {1e3 * s['limit']:.3f} mm, observed order "
                               f"{s['observed_order']:.2f}"))
    for order, r in report["cheapest"].items():
        kind = "linear" if order == "1" else "quadratic"
        print(f"cheapest within {100 * report['within']:g}%, {kind} tets: "
              + (_describe(r) if r else "none of the meshes measured"))
    linear, quadratic = report["cheapest"]["1"], report["cheapest"]["2"]
    if linear and quadratic:
        print(f"quadratic tets: {linear['unknowns'] / quadratic['unknowns']:.3g}x fewer "
              f"unknowns, {linear['ms_per_step'] / quadratic['ms_per_step']:.3g}x the speed "
              f"per step")
