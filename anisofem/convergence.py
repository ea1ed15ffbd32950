"""`python -m anisofem bench --convergence`: how far the mesh is from the body. The static tip
sag of the trade's cantilever (0.1 x 0.02 x 0.02 m, fibers at 40 degrees in x-z, kappa = E,
nu = 0.48, gravity) with linear and quadratic tets on 10 x 2 x 2 cells refined 1, 2 and 4
times; the converged sag estimated by Richardson extrapolation of the quadratic sequence (its
observed order from the three sags); each row's error against it, unknowns and solve time,
and the observed order of each sequence. Prints a table and writes JSON (atomically). Run
alone (about two minutes)."""
import math
import time

import numpy as np

from .files import publish, result_path
from .material import Material
from .meshgen import box_beam
from .metrics import end_vertices, tip_displacement
from .scene import Scene
from .solve import solve

BASE_CELLS = (10, 2, 2)
REFINEMENTS = (1, 2, 4)
ORDERS = (1, 2)


def cantilever(cells, order):
    """The trade's 0.1 m cantilever on box_beam(cells) with tets of `order`."""
    mesh = box_beam(size=(0.1, 0.02, 0.02), cells=cells, order=order)
    angle = math.radians(40.0)
    material = Material(1e5, 0.48, 1000.0, (math.cos(angle), 0.0, math.sin(angle)), 1e5)
    return Scene(mesh, material, fixed=end_vertices(mesh, 0, "min"), gravity=(0.0, 0.0, -9.81))


def sag(scene):
    """(downward tip displacement in m, seconds, converged) of the static solve."""
    start = time.perf_counter()
    result = solve(scene, warn=False)
    seconds = time.perf_counter() - start
    return -float(tip_displacement(scene.mesh, result.x)[2]), seconds, bool(result.converged)


def observed_order(s1, s2, s4):
    """The convergence order p of three values at h, h/2, h/4: (s1 - s2) / (s2 - s4) = 2^p."""
    return math.log2((s1 - s2) / (s2 - s4))


def extrapolated(s2, s4, p):
    """Richardson's limit of values at h/2 and h/4 converging with order p."""
    return s4 + (s4 - s2) / (2.0 ** p - 1.0)


def run(out=result_path("convergence.json")):
    rows = []
    for order in ORDERS:
        for k in REFINEMENTS:
            cells = tuple(k * c for c in BASE_CELLS)
            scene = cantilever(cells, order)
            value, seconds, converged = sag(scene)
            rows.append({"order": order, "cells": list(cells), "tets": scene.mesh.n_tets,
                         "unknowns": scene.n_free, "sag": value, "seconds": seconds,
                         "converged": converged})
            print(f"  order {order}, cells {cells}: {1e3 * value:.3f} mm", flush=True)
    sags = {o: [r["sag"] for r in rows if r["order"] == o] for o in ORDERS}
    orders = {o: observed_order(*sags[o]) for o in ORDERS}
    limit = extrapolated(sags[2][1], sags[2][2], orders[2])
    for r in rows:
        r["error"] = (limit - r["sag"]) / limit
    report = {"reference": "Richardson extrapolation of the quadratic sags at 2x and 4x",
              "limit": limit, "observed_order": {str(o): orders[o] for o in ORDERS},
              "rows": rows}
    return publish(report, _print, out)


def _print(report):
    print(f"{'order':>5} {'cells':>10} {'tets':>7} {'unknowns':>9} {'sag mm':>8} "
          f"{'below limit':>12} {'solve s':>8}")
    for r in report["rows"]:
        cells = "x".join(map(str, r["cells"]))
        print(f"{r['order']:>5} {cells:>10} {r['tets']:>7} {r['unknowns']:>9} "
              f"{1e3 * r['sag']:>8.3f} {100 * r['error']:>11.2f}% {r['seconds']:>8.2f}")
    orders = ", ".join(f"order {o} tets {p:.2f}" for o, p in report["observed_order"].items())
    print(f"limit {1e3 * report['limit']:.3f} mm ({report['reference']}); observed orders: "
          f"{orders}")
