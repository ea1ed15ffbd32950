"""Pressure in a cavity by sfepy and by anisofem, same mesh, materials and load, in one run:
the example actuator's mesh (examples/scenes/actuator.msh: two regions, a cavity held shut at
the base) in Saint Venant-Kirchhoff without fibers (sfepy has no term for anisofem's fiber
energy kappa (I4 - 1)^2; its fiber terms are other laws), the layer 10x stiffer, the base
held, pressure in the cavity. sfepy lives in its own virtual environment:

    python3 -m venv /tmp/sfepy-venv && /tmp/sfepy-venv/bin/pip install sfepy pyamg
    python scripts/peer_sfepy_pressure.py --python /tmp/sfepy-venv/bin/python [--pressure 1e4]

sfepy: dw_tl_he_svk per region with dw_tl_surface_traction (the total-Lagrangian follower
traction of a pressure, sigma = -p I) on the cavity's walls, Newton stopped at anisofem's
absolute tolerance on the same residual, SuperLU. anisofem: its static solve, where the
pressure enters the potential as -p times the cavity's volume change. Prints the tip's mean
displacement and bending angle by both and their largest vertex difference; writes JSON
(--out, default results/peer_sfepy_pressure.json).
"""
import argparse
import json
import os
import subprocess
import sys
import tempfile

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
MESH = os.path.join(ROOT, "examples", "scenes", "actuator.msh")
YOUNG = {1: 1.0e5, 2: 1.0e6}   # body, layer, Pa
POISSON = 0.45


def sfepy_solve(mesh_file, cavity_file, lame, pressure, tol):
    """sfepy's static solve (runs in the sfepy environment): (displacements (n, 3), Newton
    iterations, the cavity region's facet count)."""
    from sfepy.base.base import IndexedStruct
    from sfepy.discrete import (Equation, Equations, FieldVariable, Function, Functions,
                                Integral, Material, Problem)
    from sfepy.discrete.conditions import Conditions, EssentialBC
    from sfepy.discrete.fem import FEDomain, Field, Mesh
    from sfepy.mechanics.matcoefs import stiffness_from_lame
    from sfepy.solvers.ls import ScipyDirect
    from sfepy.solvers.nls import Newton
    from sfepy.terms import Term

    mesh = Mesh.from_file(mesh_file)
    cavity = np.load(cavity_file)
    domain = FEDomain("domain", mesh)
    omega = domain.create_region("Omega", "all")
    functions = Functions([Function("cavity_vertices", lambda coors, domain=None: cavity)])
    walls = domain.create_region("Cavity", "vertices by cavity_vertices", "facet",
                                 functions=functions)
    held = domain.create_region("Held", "vertices in (z < 1e-12)", "facet")
    field = Field.from_args("fu", np.float64, "vector", omega, approx_order=1)
    u = FieldVariable("u", "unknown", field)
    v = FieldVariable("v", "test", field, primary_var_name="u")
    integral = Integral("i", order=1)
    surface = Integral("s", order=2)
    terms = []
    for group, (lam, mu) in lame.items():
        region = domain.create_region(f"Omega{group}", f"cells of group {group}")
        m = Material(f"m{group}", D=stiffness_from_lame(3, lam=lam, mu=mu))
        terms.append(Term.new(f"dw_tl_he_svk(m{group}.D, v, u)", integral, region,
                              **{f"m{group}": m, "v": v, "u": u}))
    load = Material("p", val=-pressure * np.eye(3))
    traction = Term.new("dw_tl_surface_traction(p.val, v, u)", surface, walls, p=load, v=v, u=u)
    balance = terms[0]
    for term in terms[1:]:
        balance = balance + term
    problem = Problem("actuator", equations=Equations([Equation("balance", balance - traction)]))
    problem.set_bcs(ebcs=Conditions([EssentialBC("held", held, {"u.all": 0.0})]))
    status = IndexedStruct()
    problem.set_solver(Newton({"i_max": 100, "eps_a": tol, "eps_r": 1.0, "ls_on": 1e10},
                              lin_solver=ScipyDirect({}), status=status))
    state = problem.solve(save_results=False)
    return (state.get_state_parts()["u"].reshape(-1, 3), int(status.n_iter),
            int(walls.facets.size))


def anisofem_scene(pressure):
    """The actuator's scene without fibers in StVK, its groups' Young's moduli, held at the
    base, `pressure` Pa in the cavity; with its cavity faces and groups."""
    import anisofem as af
    from anisofem.io.meshes import read_tagged_mesh
    mesh, tags = read_tagged_mesh(MESH)
    names = {n: tag for n, (tag, _) in tags.names.items()}
    young = np.vectorize(YOUNG.get)(tags.volumes)
    base = np.unique(tags.surfaces[names["base"]])
    cavity = tags.surfaces[names["cavity"]]
    scene = af.Scene(mesh, af.Material(young, POISSON), fixed=base,
                     pressure=af.Pressure(cavity, pressure))
    return scene, cavity, tags.volumes


def tip_report(scene, u):
    """The tip face's mean displacement (3,) m and bending angle, degrees (the angle of its
    best-fit plane's normal from z)."""
    X = scene.mesh.vertices
    tip = np.abs(X[:, 2] - X[:, 2].max()) < 1e-9 * scene.mesh.size
    x = X[tip] + u[tip]
    normal = np.linalg.svd(x - x.mean(0))[2][2]
    return u[tip].mean(0), float(np.degrees(np.arccos(abs(normal[2]))))


def main():
    p = argparse.ArgumentParser(description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--python", help="the Python of the sfepy environment")
    p.add_argument("--pressure", type=float, default=1e4, help="Pa")
    p.add_argument("--out", default=os.path.join("results", "peer_sfepy_pressure.json"))
    p.add_argument("--one", help=argparse.SUPPRESS)  # PROBLEM.json, internal
    args = p.parse_args()
    if args.one:
        with open(args.one) as fh:
            problem = json.load(fh)
        u, its, facets = sfepy_solve(**problem["sfepy"])
        np.save(problem["answer"], u)
        print(json.dumps({"newton_iterations": its, "cavity_facets": facets}))
        return
    if not args.python:
        p.error("--python: the Python of an environment with sfepy (see the docstring)")
    import meshio

    import anisofem as af
    from anisofem.solvers.methods import Method, gradient_tolerance
    from anisofem.physics.potential import Potential
    scene, cavity, groups = anisofem_scene(args.pressure)
    result = af.solve(scene)
    ours = result.x - scene.mesh.vertices
    with tempfile.TemporaryDirectory() as folder:
        mesh_file = os.path.join(folder, "actuator.vtk")
        meshio.write(mesh_file, meshio.Mesh(scene.mesh.vertices, [("tetra", scene.mesh.tets)],
                                            cell_data={"mat_id": [groups.astype(np.int32)]}))
        cavity_file = os.path.join(folder, "cavity.npy")
        np.save(cavity_file, np.unique(cavity))
        el = scene.elements
        lame = {int(g): (float(el.lam[groups == g][0]), float(el.mu[groups == g][0]))
                for g in np.unique(groups)}
        spec = os.path.join(folder, "problem.json")
        with open(spec, "w") as fh:
            json.dump({"answer": os.path.join(folder, "u.npy"),
                       "sfepy": {"mesh_file": mesh_file, "cavity_file": cavity_file,
                                 "lame": lame, "pressure": args.pressure,
                                 "tol": gradient_tolerance(Potential(scene), Method().rtol)}},
                      fh)
        done = subprocess.run([args.python, __file__, "--one", spec], capture_output=True,
                              text=True)
        if done.returncode:
            sys.exit(f"sfepy failed: {done.stderr.strip().splitlines()[-1]}")
        peer = json.loads(done.stdout.strip().splitlines()[-1])
        theirs = np.load(os.path.join(folder, "u.npy"))
    rows = []
    for name, u, its in (("anisofem", ours, result.iterations),
                         ("sfepy", theirs, peer["newton_iterations"])):
        mean, angle = tip_report(scene, u)
        rows.append({"code": name, "newton_iterations": its, "tip_displacement_m": mean.tolist(),
                     "tip_angle_degrees": angle})
    scale = float(np.abs(ours).max())
    report = {"mesh": os.path.relpath(MESH, ROOT), "tets": scene.mesh.n_tets,
              "pressure_pa": args.pressure, "cavity_faces": int(len(cavity)),
              "sfepy_cavity_facets": peer["cavity_facets"], "rows": rows,
              "largest_difference_over_largest_displacement":
                  float(np.abs(theirs - ours).max()) / scale,
              "angle_difference": rows[1]["tip_angle_degrees"] / rows[0]["tip_angle_degrees"]
              - 1.0}
    from anisofem.io.output import publish
    publish(report, print_report, args.out)


def print_report(report):
    print(f"Cavity pressure {report['pressure_pa']:g} Pa on the actuator's mesh "
          f"({report['tets']:,d} tets; {report['cavity_faces']} cavity faces, sfepy's region "
          f"{report['sfepy_cavity_facets']} facets), StVK without fibers")
    print(f"{'code':<10} {'Newton':>6} {'tip angle (deg)':>16} {'tip displacement (mm)':>28}")
    for r in report["rows"]:
        mm = " ".join(f"{1e3 * c:8.4f}" for c in r["tip_displacement_m"])
        print(f"{r['code']:<10} {r['newton_iterations']:6d} {r['tip_angle_degrees']:16.4f} "
              f"{mm:>28}")
    print(f"largest vertex difference over the largest displacement: "
          f"{report['largest_difference_over_largest_displacement']:.2e}; tip angle "
          f"{report['angle_difference']:+.2e}")


if __name__ == "__main__":
    main()
