"""Contact's checks in numbers: Coulomb's slope, drops at 1 to 100 g, and what contact costs a
step.

    python scripts/contact_checks.py [--json results/contact_checks.json]

Slope: a stiff 2 cm cube (E = 10 MPa, Neo-Hookean) on a plane obstacle under gravity tilted by
atan(0.5), the tilt turned on over 0.3 s, 1 s at dt = 0.01 s: its slide and its acceleration
(a parabola fitted after 0.4 s) against g (sin t - mu cos t); and the same cube on a held slab
of the same mesh by self-contact (ipctk) at mu = 0.3 (tilt over 0.1 s, fitted after 0.15 s).
Drops: the 0.2 m beam (Neo-Hookean, 20 x 2 x 2 cells, fibers along it) dropped from 2 cm onto
the ground with a 4 x 10 x 1 cm block on it, at 1, 10 and 100 g and dt 0.005, 0.02 and 0.05
s: the nearest any surface node came to an obstacle, Newton iterations, converged. Cost: the
0.2 m beam (40 x 4 x 4 cells) clamped at one end sagging onto the ground 1 cm below, 40 steps
of dt = 0.01 s, against the same scene without the ground: ms per step and per Newton
iteration. Reduced: the tentacle of examples/scenes/tentacle.toml (960 tets, held at its base)
over the ground 7 mm below its lowest point, its "up" band activated to 0.05 over 0.5 s, 50
steps of 0.02 s: its static rest shape and the rollout's last state, reduced model (4 modes +
14 fitted, built with the ground) against the FEM, as the largest node distance over the
largest displacement; ms per step of the FEM, the library's reduced step and the C runtime's.
Runtime: the T (anisofem.physics.meshgen.t_shape, held at its foot) with four obstacles (a
wall at one arm's end, a rotated box and a capsule under its arms, a ball over one), its
reduced model (6 modes + 10 fitted) written and stepped 200 times by the C runtime under
gravity with the ball moved every step: ms per step. Hertz: the quarter of a 10 mm ball of
tests/data/hemisphere_quarter_2.msh (Gmsh, curved quadratic tets) pressed 0.1 mm onto a
plane (anisofem.studies.hertz), at contact distances 1e-5 to 3e-7 m: its force over Hertz's.
Run alone (about two minutes).
"""
import argparse
import itertools
import os
import tempfile
import time

import numpy as np

import anisofem as af
from anisofem.io.output import publish, result_path
from anisofem.physics.contact import ContactTerm, body_size
from anisofem.physics.curves import Timed

G = 9.81
THETA = np.arctan(0.5)


def slide(scene, x0, v0, steps, dt, moving, start):
    """(slide (steps,) m of the moving nodes' centre of mass along x, fitted acceleration after
    `start` s, converged) of a rollout."""
    roll = af.simulate(scene, steps, dt=dt, x0=x0, v0=v0, warn=False)
    w = scene.masses[moving]
    x = np.array([w @ (s.x[moving, 0] - x0[moving, 0]) for s in roll.steps]) / w.sum()
    t = dt * np.arange(1, len(x) + 1)
    late = t > start
    return x, 2 * float(np.polyfit(t[late], x[late], 2)[0]), roll.converged


def slope_rows():
    """The cube on the plane obstacle at mu 0.5, 0.49, 0.3, and on the slab at 0.3."""
    rows, dt = [], 0.01
    cube = af.box_beam(size=(0.02, 0.02, 0.02), cells=(2, 2, 2))
    C = cube.vertices - cube.vertices.min(axis=0)
    material = af.Material(1e7, 0.4, 1000.0, model="neohookean")
    mesh = af.TetMesh(C + [0, 0, 3e-5], cube.tets)
    every = np.arange(mesh.n_vertices)
    for mu in (0.5, 0.49, 0.3):
        def scene_of(force):
            return af.Scene(mesh, material, gravity=(0, 0, -G * np.cos(THETA)),
                            nodal_force=force, contact=af.Contact([af.Plane()], friction=mu))
        settled = af.simulate(scene_of(None), 30, dt=dt, warn=False).steps[-1]
        push = np.zeros((mesh.n_vertices, 3))
        push[:, 0] = scene_of(None).masses * G * np.sin(THETA)
        tilted = scene_of(push).following([Timed(af.LoadCurve([0, 0.3, 10], [0, 1, 1]),
                                                 force=push)])
        x, a, ok = slide(tilted, settled.x, settled.v, 100, dt, every, 0.4)
        rows.append({"contact": "plane obstacle", "mu": mu, "slide_mm": 1e3 * float(x[-1]),
                     "smoothing_mm": 1e3 * 1e-3 * body_size(mesh) * 1.0, "a": a,
                     "a_coulomb": G * (np.sin(THETA) - mu * np.cos(THETA)), "converged": ok})
    slab = af.box_beam(size=(0.3, 0.04, 0.01), cells=(15, 2, 1))
    S = slab.vertices - slab.vertices.min(axis=0)
    mesh = af.TetMesh(np.vstack([S, C + [0.013, 0.011, 0.01 + 5e-5]]),
                      np.vstack([slab.tets, cube.tets + len(S)]))
    held = np.zeros((mesh.n_vertices, 3), bool)
    held[:len(S)] = True
    push = np.zeros((mesh.n_vertices, 3))
    push[len(S):, 0] = af.Scene(mesh, material, fixed=held).masses[len(S):] * G * np.sin(THETA)
    scene = af.Scene(mesh, material, gravity=(0, 0, -G * np.cos(THETA)), fixed=held,
                     nodal_force=push, contact=af.Contact(self_contact=True, friction=0.3))
    tilted = scene.following([Timed(af.LoadCurve([0, 0.1, 10], [0, 1, 1]), force=push)])
    x, a, ok = slide(tilted, scene.initial_positions(), np.zeros((mesh.n_vertices, 3)), 40, dt,
                     np.arange(len(S), mesh.n_vertices), 0.15)
    rows.append({"contact": "self-contact (ipctk)", "mu": 0.3, "slide_mm": 1e3 * float(x[-1]),
                 "smoothing_mm": None, "a": a,
                 "a_coulomb": G * (np.sin(THETA) - 0.3 * np.cos(THETA)), "converged": ok})
    return rows


def drop_rows():
    """The beam dropped on the ground and a block at each gravity and time step."""
    beam = af.box_beam(size=(0.2, 0.02, 0.02), cells=(20, 2, 2))
    mesh = af.TetMesh(beam.vertices - [0, 0, beam.vertices[:, 2].min() - 0.02], beam.tets)
    material = af.Material(1e5, 0.45, 1000.0, np.array([1.0, 0, 0]), 1e5, model="neohookean")
    block = af.Box((0.1, 0.0, 0.005), (0.02, 0.05, 0.005), name="block")
    rows = []
    for g, dt in itertools.product((1, 10, 100), (0.005, 0.02, 0.05)):
        scene = af.Scene(mesh, material, gravity=(0, 0, -G * g),
                         contact=af.Contact([af.Plane(name="ground"), block]))
        term = ContactTerm(scene)
        steps = int(round(np.sqrt(2 * 0.03 / (G * g)) * 3 / dt)) + 5
        roll = af.simulate(scene, steps, dt=dt, warn=False)
        rows.append({"g": g, "dt": dt, "steps": len(roll.steps),
                     "nearest_um": 1e6 * min(float(term.distances(s.x).min())
                                             for s in roll.steps),
                     "dhat_um": 1e6 * term.dhat,
                     "iterations": max(s.newton.iterations for s in roll.steps),
                     "inverted": max(s.newton.inversion.inverted for s in roll.steps),
                     "converged": roll.converged})
    return rows


def cost_rows():
    """ms per step and per iteration of the clamped beam sagging onto the ground, and free."""
    beam = af.box_beam(size=(0.2, 0.02, 0.02), cells=(40, 4, 4))
    mesh = af.TetMesh(beam.vertices - [0, 0, beam.vertices[:, 2].min() - 0.01], beam.tets)
    material = af.Material(1e5, 0.45, 1000.0, np.array([1.0, 0, 0]), 1e5, model="neohookean")
    clamp = beam.vertices[:, 0] <= 1e-9
    rows = []
    for contact in (None, af.Contact([af.Plane(name="ground")], friction=0.3)):
        scene = af.Scene(mesh, material, gravity=(0, 0, -G), fixed=clamp, contact=contact)
        af.simulate(scene, 2, dt=0.01, warn=False)          # compiled and warm
        t0 = time.perf_counter()
        roll = af.simulate(scene, 40, dt=0.01, warn=False)
        seconds = time.perf_counter() - t0
        iterations = sum(s.newton.iterations for s in roll.steps)
        rows.append({"scene": "with the ground" if contact else "without", "tets": mesh.n_tets,
                     "ms_per_step": 1e3 * seconds / 40,
                     "ms_per_iteration": 1e3 * seconds / max(iterations, 1),
                     "iterations_per_step": iterations / 40, "converged": roll.converged,
                     "lowest_mm": 1e3 * min(float(s.x[:, 2].min()) for s in roll.steps)})
    return rows


def reduced_rows():
    """The tentacle on the ground: reduced model against the FEM, and the steps' cost."""
    from anisofem.io.scenefile import SceneFile
    from anisofem.reduced import Loads, ReducedModel
    here = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "examples", "scenes")
    written = SceneFile(os.path.join(here, "tentacle.toml"))
    base, ranges = written.scene, written.control_ranges
    scene = af.Scene(base.mesh, base.material, fixed=base.fixed_mask, gravity=(0, 0, -G),
                     activation=base.activations,
                     contact=af.Contact([af.Plane((0, 0, -0.022), name="ground")],
                                        friction=0.5))
    model = ReducedModel(scene, modes=4, snapshots=14, loads=Loads(controls=ranges))
    X = scene.mesh.vertices
    q, _ = model.solve()
    rest = af.solve(scene, warn=False).x
    static = (np.linalg.norm(model.positions(q) - rest, axis=1).max()
              / np.linalg.norm(rest - X, axis=1).max())
    dt, steps = 0.02, 50

    def up(t):
        return {"up": 0.05 * min(1.0, t / 0.5)}
    t0 = time.perf_counter()
    roll = af.simulate(scene, steps, dt=dt, warn=False, controls=up)
    fem_ms = 1e3 * (time.perf_counter() - t0) / steps
    q, w = np.zeros(model.r), np.zeros(model.r)
    t0 = time.perf_counter()
    for k in range(steps):
        q, w, _ = model.step(q, w, dt, controls=up((k + 1) * dt))
    library_ms = 1e3 * (time.perf_counter() - t0) / steps
    moved = max(np.linalg.norm(s.x - X, axis=1).max() for s in roll.steps)
    rollout = np.linalg.norm(model.positions(q) - roll.steps[-1].x, axis=1).max() / moved
    c_ms = c_rollout_ms(model, steps, dt, lambda c, k: c.set_controls(up((k + 1) * dt)))
    return {"tets": scene.mesh.n_tets, "r": model.r, "static_off": float(static),
            "rollout_off": float(rollout), "fem_ms": fem_ms, "library_ms": library_ms,
            "c_ms": c_ms}


def runtime_row():
    """The T with four obstacles in the C runtime: ms per step (None without a compiler)."""
    from anisofem.reduced import ReducedModel
    from export import native
    if native.compiler() is None:
        return None
    mesh = af.t_shape()
    X = mesh.vertices
    top = X[:, 2].max()
    arms = top - 0.02                   # the arms' underside
    obstacles = [af.Plane((0.052, 0, 0), (-1, 0, 0), name="wall"),
                 af.Sphere((-0.035, 0.0, top + 0.012), 0.01, name="ball"),
                 af.Box((0.035, 0.0, arms - 0.006), (0.004, 0.02, 0.004), name="box",
                        rotation=[[0.8, -0.6, 0.0], [0.6, 0.8, 0.0], [0.0, 0.0, 1.0]]),
                 af.Capsule((-0.045, -0.03, arms - 0.005), (-0.045, 0.03, arms - 0.005),
                            0.003, name="rod")]
    scene = af.Scene(mesh, af.Material(1e5, 0.48, 1000.0, np.array([1.0, 0, 0]), 1e5),
                     fixed=X[:, 2] <= 1e-9, gravity=(0, 0, -G),
                     contact=af.Contact(obstacles, friction=0.3))
    model = ReducedModel(scene, modes=6, snapshots=10, validate=False)

    def push(c, k):
        c.move_obstacle("ball", (-0.035, 0.0, top + 0.012 - 0.01 * np.sin(np.pi * k / 200)))
    return {"tets": mesh.n_tets, "r": model.r, "surface_nodes": len(model.contact.x0),
            "c_ms": c_rollout_ms(model, 200, 0.01, push)}


def c_rollout_ms(model, steps, dt, each):
    """ms per step of the C runtime stepping the ReducedModel `model` (written to a temporary
    file) `steps` times under its scene's constant force, each(c, k) called before step k;
    None without a C compiler."""
    from export import native
    from export.writers.reduced import write
    if native.compiler() is None:
        return None
    with tempfile.TemporaryDirectory() as folder:
        path = os.path.join(folder, "model")
        write(model, path)
        c = native.CReducedSimulator(path)
        c.set_constant_force(model.scene.external_force)
        q, w = c.rest_state()
        t0 = time.perf_counter()
        for k in range(steps):
            each(c, k)
            c.step(q, w, None, dt)
        return 1e3 * (time.perf_counter() - t0) / steps


def hertz_rows():
    """The ball pressed onto the plane at each contact distance: force, Hertz's, their ratio."""
    from anisofem.studies.hertz import pressed
    here = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tests", "data")
    mesh = af.read_mesh(os.path.join(here, "hemisphere_quarter_2.msh"))
    rows = []
    for distance in (1e-5, 3e-6, 1e-6, 3e-7):
        force, hertz, result = pressed(mesh, 0.01, 1e-4, distance)
        rows.append({"distance_m": distance, "force_N": force, "hertz_N": hertz,
                     "ratio": force / hertz, "newton": result.iterations,
                     "converged": result.converged, "tets": mesh.n_tets})
    return rows


def _print(report):
    print("slope tilted by atan(0.5):")
    print(f"{'contact':<22} {'mu':>5} {'slide mm':>9} {'a m/s^2':>9} {'Coulomb':>8} {'off':>7}")
    for r in report["slope"]:
        off = (f"{100 * (r['a'] / r['a_coulomb'] - 1):6.2f}%" if r["a_coulomb"] > 1e-9
               else f"(eps_v t {r['smoothing_mm']:.3f} mm)")
        print(f"{r['contact']:<22} {r['mu']:5.2f} {r['slide_mm']:9.4f} {r['a']:9.5f} "
              f"{r['a_coulomb']:8.5f} {off}")
    print("\ndrops of the 0.2 m beam onto the ground and a block:")
    print(f"{'g':>4} {'dt s':>6} {'steps':>5} {'nearest um':>10} {'dhat um':>8} {'Newton':>6} "
          f"{'inverted':>8} converged")
    for r in report["drops"]:
        print(f"{r['g']:4d} {r['dt']:6.3f} {r['steps']:5d} {r['nearest_um']:10.2f} "
              f"{r['dhat_um']:8.1f} {r['iterations']:6d} {r['inverted']:8d} {r['converged']}")
    print("\ncost: the clamped 0.2 m beam sagging onto the ground:")
    for r in report["cost"]:
        print(f"{r['scene']:<16} {r['tets']:5d} tets  {r['ms_per_step']:7.1f} ms/step  "
              f"{r['iterations_per_step']:4.1f} Newton/step  {r['ms_per_iteration']:6.1f} "
              f"ms/iteration  lowest z {r['lowest_mm']:7.3f} mm  converged {r['converged']}")
    free, touching = report["cost"]
    print(f"contact / contact-free: {touching['ms_per_step'] / free['ms_per_step']:.2f}x per "
          f"step, {touching['ms_per_iteration'] / free['ms_per_iteration']:.2f}x per iteration")
    r = report["reduced"]
    c = "no C compiler" if r["c_ms"] is None else (f"C runtime {r['c_ms']:.3f} ms "
                                                   f"({r['fem_ms'] / r['c_ms']:.0f}x)")
    t = report["runtime"]
    if t is not None:
        print(f"\nthe T ({t['tets']} tets, r = {t['r']}, {t['surface_nodes']} surface nodes) with "
              f"four obstacles, its ball moved every step: C runtime {t['c_ms']:.3f} ms per step")
    h = report["hertz"]
    print(f"\nHertz: a 10 mm ball ({h[0]['tets']} curved quadratic tets in its quarter) pressed "
          f"0.1 mm onto a plane")
    print(f"{'distance (m)':>12} {'force (N)':>10} {'Hertz (N)':>10} {'ratio':>7} {'Newton':>6}")
    for row in h:
        print(f"{row['distance_m']:12.1e} {row['force_N']:10.4e} {row['hertz_N']:10.4e} "
              f"{row['ratio']:7.4f} {row['newton']:6d}")
    print(f"\nthe tentacle on the ground ({r['tets']} tets), reduced r = {r['r']} against the "
          f"FEM: rest shape {100 * r['static_off']:.2f}% off, rollout's end "
          f"{100 * r['rollout_off']:.2f}% off (of the largest displacement); per step: FEM "
          f"{r['fem_ms']:.2f} ms, library reduced {r['library_ms']:.2f} ms "
          f"({r['fem_ms'] / r['library_ms']:.0f}x), {c}")


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--json", default=result_path("contact_checks.json"))
    args = parser.parse_args()
    publish({"slope": slope_rows(), "drops": drop_rows(), "cost": cost_rows(),
             "reduced": reduced_rows(), "runtime": runtime_row(), "hertz": hertz_rows()},
            _print, args.json)


if __name__ == "__main__":
    main()
