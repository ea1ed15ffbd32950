"""The static box cantilever by sfepy and by anisofem, same mesh, material and tolerance, in one
run (docs/fem.md, "Large meshes"). sfepy lives in its own virtual environment:

    python3 -m venv /tmp/sfepy-venv && /tmp/sfepy-venv/bin/pip install sfepy pyamg
    python scripts/peer_sfepy.py --python /tmp/sfepy-venv/bin/python [--cells 50x20x20]
        [--solvers "sfepy superlu"] [--order 2]

The problem: default_scene's (Saint Venant-Kirchhoff, E = 100 kPa, nu = 0.48, 1000 kg/m^3,
gravity, the face at the minimum x held), sfepy's total-Lagrangian Saint Venant-Kirchhoff term
dw_tl_he_svk with one-point quadrature (exact for linear tets; with --order 2 quadratic tets,
sfepy's own P2 field on the same linear mesh, and a degree-4 rule, exact for them; the
comparison is then on the mesh's vertices), its Newton solver stopped at
anisofem's absolute tolerance on the same residual (N), with sfepy's direct solver (SuperLU)
and with its pyamg CG (smoothed aggregation, sfepy's defaults). Each solver runs in a fresh
process; the time is the nonlinear solve's alone (mesh and problem set-up excluded on both
sides). Prints a table and writes JSON (--out).
"""
import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

import numpy as np

#: sfepy Newton line-searches when the residual grows by this factor; its default (0.99999)
#: stalled at the first iteration (the residual of a bending beam grows along the way to
#: equilibrium, as anisofem's residual histories show), so plain Newton steps
LS_ON = 1e10
SFEPY_SOLVERS = {"sfepy superlu": {"name": "ls.scipy_direct", "method": "superlu"},
                 "sfepy pyamg cg": {"name": "ls.pyamg", "accel": "cg", "eps_r": 1e-3,
                                    "i_max": 1000}}


def sfepy_solve(mesh_file, lam, mu, load, x_fixed, tol, solver, order):
    """sfepy's static solve (runs in the sfepy environment): (displacements (n, 3), seconds,
    Newton iterations)."""
    from sfepy.base.base import IndexedStruct
    from sfepy.discrete import (Equation, Equations, FieldVariable, Integral, Material,
                                Problem)
    from sfepy.discrete.conditions import Conditions, EssentialBC
    from sfepy.discrete.fem import FEDomain, Field, Mesh
    from sfepy.mechanics.matcoefs import stiffness_from_lame
    from sfepy.solvers import Solver
    from sfepy.solvers.nls import Newton
    from sfepy.terms import Term

    mesh = Mesh.from_file(mesh_file)
    domain = FEDomain("domain", mesh)
    omega = domain.create_region("Omega", "all")
    held = domain.create_region("Held", f"vertices in (x < {x_fixed})", "facet")
    field = Field.from_args("fu", np.float64, "vector", omega, approx_order=order)
    u = FieldVariable("u", "unknown", field)
    v = FieldVariable("v", "test", field, primary_var_name="u")
    m = Material("m", D=stiffness_from_lame(3, lam=lam, mu=mu))
    f = Material("f", val=np.asarray(load, dtype=float).reshape(3, 1))
    integral = Integral("i", order=1 if order == 1 else 4)
    elastic = Term.new("dw_tl_he_svk(m.D, v, u)", integral, omega, m=m, v=v, u=u)
    body = Term.new("dw_volume_lvf(f.val, v)", integral, omega, f=f, v=v)
    problem = Problem("cantilever", equations=Equations([Equation("balance", elastic - body)]))
    problem.set_bcs(ebcs=Conditions([EssentialBC("held", held, {"u.all": 0.0})]))
    status = IndexedStruct()
    linear = Solver.any_from_conf(_conf(SFEPY_SOLVERS[solver]))
    problem.set_solver(Newton({"i_max": 100, "eps_a": tol, "eps_r": 1.0, "ls_on": LS_ON},
                              lin_solver=linear, status=status))
    t0 = time.perf_counter()
    state = problem.solve(save_results=False)
    seconds = time.perf_counter() - t0
    # a P2 field's DOFs: the mesh's vertices first, then its edges
    u = state.get_state_parts()["u"].reshape(-1, 3)[:mesh.n_nod]
    return u, seconds, int(status.n_iter)


def _conf(options):
    from sfepy.base.base import Struct
    return Struct(kind=options["name"], **{k: v for k, v in options.items() if k != "name"})


def anisofem_solve(cells, path, order):
    """anisofem's static solve of the same cantilever: (row dict, displacements (n, 3) of the
    linear mesh's vertices)."""
    from anisofem.studies.bench_large import measure
    from anisofem.physics.meshgen import box_beam
    linear = box_beam(cells=cells)
    if order == 1:
        row, x = measure(cells, path)
        return row, x - linear.vertices
    from anisofem import default_scene, solve
    scene = default_scene(box_beam(cells=cells, order=2))
    t0 = time.perf_counter()
    result = solve(scene)
    row = {"solve_s": time.perf_counter() - t0, "newton_iterations": result.iterations}
    return row, result.x[:linear.n_vertices] - linear.vertices


def main():
    p = argparse.ArgumentParser(description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--python", required=False, help="the Python of the sfepy environment")
    p.add_argument("--cells", default="50x20x20", help="box cantilever cells (5 tets each)")
    p.add_argument("--solvers", nargs="+", default=list(SFEPY_SOLVERS),
                   choices=list(SFEPY_SOLVERS), help="sfepy's linear solvers to run")
    p.add_argument("--order", type=int, choices=(1, 2), default=1,
                   help="1: linear tets; 2: quadratic tets on the same mesh")
    p.add_argument("--out", default=os.path.join("results", "peer_sfepy.json"))
    p.add_argument("--one", nargs=2, help=argparse.SUPPRESS)  # SOLVER PROBLEM.json, internal
    args = p.parse_args()
    if args.one:
        solver, spec = args.one
        with open(spec) as fh:
            problem = json.load(fh)
        u, seconds, its = sfepy_solve(solver=solver, **problem["sfepy"])
        np.save(problem["answer"], u)
        print(json.dumps({"path": solver, "solve_s": seconds, "newton_iterations": its}))
        return
    if not args.python:
        p.error("--python: the Python of an environment with sfepy (see the docstring)")
    cells = tuple(int(c) for c in args.cells.split("x"))
    rows = [_anisofem_row(cells, "cg amg" if args.order == 1 else "auto", args.order)]
    with tempfile.TemporaryDirectory() as folder:
        spec = _write_problem(cells, folder, args.order)
        for solver in args.solvers:
            print(f"  {solver} ...", file=sys.stderr, flush=True)
            done = subprocess.run([args.python, __file__, "--one", solver, spec],
                                  capture_output=True, text=True)
            if done.returncode:
                rows.append({"path": solver, "error": done.stderr.strip().splitlines()[-1]})
                continue
            row = json.loads(done.stdout.strip().splitlines()[-1])
            with open(spec) as fh:
                u = np.load(json.load(fh)["answer"])
            rows.append(row | {"u": u})
    reference = rows[0].pop("u")
    scale = float(np.abs(reference).max())
    for row in rows[1:]:
        if "u" in row:
            row["difference_to_anisofem"] = float(np.abs(row.pop("u") - reference).max()) / scale
    report = {"cells": list(cells), "tets": 5 * int(np.prod(cells)), "order": args.order,
              "rows": rows}
    from anisofem.io.output import publish
    publish(report, print_report, args.out)


def _anisofem_row(cells, path, order):
    print(f"  anisofem {path} ...", file=sys.stderr, flush=True)
    row, u = anisofem_solve(cells, path, order)
    return {"path": f"anisofem {path}", "solve_s": row["solve_s"],
            "newton_iterations": row["newton_iterations"], "u": u}


def _write_problem(cells, folder, order):
    """The mesh file and the sfepy arguments of default_scene's cantilever with tets of
    `order`; the spec's path."""
    import meshio

    from anisofem.physics.meshgen import box_beam
    from anisofem.solvers.methods import Method, gradient_tolerance
    from anisofem.physics.potential import Potential
    from anisofem.physics.scene import GRAVITY, default_scene
    mesh = box_beam(cells=cells)
    scene = default_scene(box_beam(cells=cells, order=order))
    mesh_file = os.path.join(folder, "beam.vtk")
    meshio.write(mesh_file, meshio.Mesh(mesh.vertices, [("tetra", mesh.tets)]))
    tol = gradient_tolerance(Potential(scene), Method().rtol)
    spec = os.path.join(folder, "problem.json")
    with open(spec, "w") as fh:
        json.dump({"answer": os.path.join(folder, "u.npy"),
                   "sfepy": {"mesh_file": mesh_file, "lam": float(scene.elements.lam[0]),
                             "mu": float(scene.elements.mu[0]),
                             "load": (float(scene.material.density)
                                      * np.asarray(GRAVITY)).tolist(),
                             "x_fixed": float(mesh.vertices[:, 0].min() + 1e-9 * mesh.size),
                             "tol": tol, "order": order}}, fh)
    return spec


def print_report(report):
    kind = "quadratic" if report.get("order") == 2 else "linear"
    print(f"Static box cantilever, {report['tets']:,d} {kind} tets, one process per row")
    print(f"{'path':<16} {'solve s':>8} {'Newton':>6} {'s/iteration':>11} {'vs anisofem':>11}")
    for r in report["rows"]:
        if "error" in r:
            print(f"{r['path']:<16} failed: {r['error']}")
            continue
        diff = r.get("difference_to_anisofem")
        print(f"{r['path']:<16} {r['solve_s']:8.1f} {r['newton_iterations']:6d} "
              f"{r['solve_s'] / max(r['newton_iterations'], 1):11.2f} "
              f"{'-' if diff is None else f'{diff:.1e}':>11}")


if __name__ == "__main__":
    main()
