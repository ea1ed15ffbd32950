"""A finger driven by two tendons: cables routed through the body above and below its axis,
anchored at its tip, each pulled with a tension (a control). The tensions that bring its tip to
a target at equilibrium are found in its reduced model (ReducedModel.reach), checked against
the full FEM, and the finger then follows a path in closed loop through the C runtime (af_reach
with an integral correction and af_step every step, the cables' length evaluated on their
routing points).

The finger is a 0.1 x 0.02 x 0.02 m beam along x (StVK, E = 500 kPa, nu = 0.3, quadratic tets)
held at x = 0 under gravity along -z; the cables run straight at 6 mm above ("flex") and below
("extend") its axis through 9 points each, from the held end to the tip, with tensions from 0
to 2.5 N (where the FEM stays physical: no element turned inside out at the anchors).

    python examples/cable_finger.py

Prints, per target, the tensions found, the tip's distance to the target in the model and in
the full FEM under them; then the closed loop's tracking error and time per step; draws
out/cable_finger.png.
"""
import os
import sys
import time

import matplotlib
import numpy as np

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, ".."))
import anisofem as af  # noqa: E402
from anisofem.io.output import scratch_path  # noqa: E402
from anisofem.reduced import Loads, ReducedModel  # noqa: E402
from export import native  # noqa: E402
from export.writers.reduced import write  # noqa: E402

LENGTH, SIDE, OFFSET = 0.1, 0.02, 0.006
RANGE = (0.0, 2.5)
DT, DURATION = 0.02, 1.6
#: The path: where the tip rests under a flexing tension up to FLEX, N, and back over DURATION
#: (a path the finger can follow, and 7 mm long).
FLEX = 1.6
#: The integral gain on the tip's error, per s: each step's target is moved by it times the
#: error integrated so far (the loop's dynamics lag a static answer).
INTEGRAL = 10.0
#: Targets for the tip (m): at rest it sags to about (0.0997, 0, -0.0074) under its weight;
#: three within reach, then one the tendons cannot reach.
TARGETS = ((0.099, 0.0, -0.002), (0.0985, 0.0, -0.012), (0.0995, 0.0, -0.005),
           (0.05, 0.0, 0.05))


def finger():
    """The finger's Scene: its two cables are its controls."""
    mesh = af.box_beam(size=(LENGTH, SIDE, SIDE), cells=(10, 2, 2), order=2)
    along = np.linspace(0.0, LENGTH, 9)
    cables = [af.Cable([(x, 0.0, side * OFFSET) for x in along], 0.0, name)
              for name, side in (("flex", 1.0), ("extend", -1.0))]
    return af.Scene(mesh, af.Material(5e5, 0.3, 1000.0), gravity=(0.0, 0.0, -9.81),
                    fixed=af.metrics.end_vertices(mesh, 0, "min"), cable=cables)


def main():
    scene = finger()
    t0 = time.perf_counter()
    model = ReducedModel(scene, modes=6, snapshots=16,
                         loads=Loads(controls={"flex": RANGE, "extend": RANGE}))
    tip = np.flatnonzero(np.abs(scene.mesh.vertices[:, 0] - LENGTH) < 1e-12)
    print(f"finger: {scene.mesh.n_tets} quadratic tets, reduced model r = {model.r}, built in "
          f"{time.perf_counter() - t0:.1f} s (validation {100 * model.validation.tip_error:.2g}% "
          f"off the FEM)")
    print(f"{'target (m)':>22} | tensions flex, extend (N) | model (mm) | FEM (mm)")
    for target in TARGETS:
        found = model.reach(list(tip), target)
        full = af.solve(scene.with_controls(found.controls), warn=False).x[tip].mean(axis=0)
        print(f"{str(target):>22} | {found.controls[0]:12.4f} {found.controls[1]:12.4f} | "
              f"{1e3 * found.distance:10.3f} | {1e3 * np.linalg.norm(full - target):8.3f}")
        if not found.reached:
            print(f"  {found.message}")
    follow_path(model, tip)


def follow_path(model, tip):
    """The tip along the path of its rest under a flexing tension up to FLEX and back, in closed
    loop: the C runtime's af_reach gives the tensions for each step's target (where there is no
    C compiler, ReducedModel.reach)."""
    path = scratch_path("cable_finger")
    os.makedirs(os.path.dirname(path), exist_ok=True)
    rest = model.positions(model.solve()[0])[tip].mean(axis=0)
    steps = int(round(DURATION / DT))
    low, high = np.array([RANGE, RANGE]).T
    c = None
    if native.compiler() is not None:
        write(model, path, title="cable finger")
        c = native.CReducedSimulator(path)
        c.set_constant_force(model.scene.external_force)
    q, w = model.solve()[0], np.zeros(model.r)
    tips, wanted, tensions, seconds = [rest], [rest], [], 0.0
    integral, found = np.zeros(3), None
    for k in range(1, steps + 1):
        flex = FLEX * np.sin(np.pi * k * DT / DURATION) ** 2
        path_point = model.positions(model.solve(controls=[flex, 0.0])[0])[tip].mean(axis=0)
        target = path_point + INTEGRAL * integral
        t0 = time.perf_counter()
        if c is not None:
            controls = c.reach(tip, np.full(tip.size, 1.0 / tip.size), target, low, high)[0]
            c.step(q, w, None, DT, controls=controls)
            x = c.positions(q)
        else:
            found = model.reach(list(tip), target, controls=found.controls if found else None,
                                q0=found.q if found else None)
            controls = found.controls
            q, w, _ = model.step(q, w, DT, controls=controls)
            x = model.positions(q)
        seconds += time.perf_counter() - t0
        tips.append(x[tip].mean(axis=0))
        wanted.append(path_point)
        tensions.append(controls)
        integral += (path_point - tips[-1]) * DT
    tips, wanted = np.array(tips), np.array(wanted)
    error = np.linalg.norm(tips - wanted, axis=1)
    how = "the C runtime" if c is not None else "the reduced model (no C compiler found)"
    length = np.linalg.norm(np.diff(wanted, axis=0), axis=1).sum() / 2
    print(f"closed loop through {how}: tip within {1e3 * error.max():.2f} mm of a path "
          f"{1e3 * length:.1f} mm long, "
          f"{1e3 * seconds / steps:.2f} ms per step (reach and step)")
    fig, (ax, right) = plt.subplots(1, 2, figsize=(10, 4))
    ax.plot(1e3 * wanted[:, 0], 1e3 * wanted[:, 2], "k--", label="path")
    ax.plot(1e3 * tips[:, 0], 1e3 * tips[:, 2], label="tip, closed loop")
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("z (mm)")
    ax.legend()
    t = DT * np.arange(1, steps + 1)
    for k, name in enumerate(model.controls):
        right.plot(t, np.array(tensions)[:, k], label=name)
    right.set_xlabel("t (s)")
    right.set_ylabel("tension (N)")
    right.legend()
    fig.tight_layout()
    fig.savefig(scratch_path("cable_finger.png"), dpi=120)
    print(f"drew {os.path.relpath(scratch_path('cable_finger.png'))}")


if __name__ == "__main__":
    main()
