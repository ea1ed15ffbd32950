"""A character's tail: a fiber-reinforced beam held at the hip of a body that runs and turns,
stepped by its framed model in the C runtime (export/c, through export.native: what an engine
links), against the full FEM with the same prescribed motion.

The tail is 0.2 x 0.02 x 0.02 m (320 tets, E = 100 kPa, nu = 0.48, fibers along it with
kappa = E), held at x = 0 and hanging under gravity. The hip moves 0.3 m along -x while it
turns 90 degrees about z in 0.4 s (a smooth start and stop), then stands still for 1.6 s: the
tail whips round and settles. The framed model is built with anisofem into out/tail.json and
.bin for the loads it must handle, declared: the hip's carry (a turn of up to 90 degrees and
a move of up to 0.3 m in 0.4 s, Carry) and a drag at the tip of up to twice the tail's
weight in any direction, what the turn's inertia pulls it with (with the default
declaration, a drag of half the weight, the whip is 12% off; the carry alone 11%; with the
drag 3.6%). Each step passes the hip's rigid motion as the base (the held vertices at
R_g x0 + c_g). Prints the tip's error against the
full FEM with the same prescribed motion over the tip's largest swing from where the hip
carries it, and ms per step of the runtime and of the full FEM, and draws both seen from
above in out/tail.png. Without a C compiler it steps the same file with the numpy runtime
(export/framed_runtime.py, the C runtime's reference, some ten times slower) and says so.

    python examples/tail.py
"""
import os
import time

import matplotlib
import numpy as np

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from export import native  # noqa: E402
from export.framed_runtime import FramedSimulator  # noqa: E402

DT, STEPS, TURN_STEPS = 0.02, 100, 20
LENGTH = 0.2
#: the loads the model declares besides the carry: a drag at the tip of up to WHIP times the
#: tail's weight, in any direction (what the turn's inertia pulls it with)
WHIP = 2.0


def hip(k):
    """The hip's rigid motion [R_g | c_g] (3, 4) at step k: 0.3 m along -x and a quarter turn
    about z over TURN_STEPS steps (smoothly started and stopped), then held."""
    s = 0.5 - 0.5 * np.cos(np.pi * min(k / TURN_STEPS, 1.0))
    a = 0.5 * np.pi * s
    R = np.array([[np.cos(a), -np.sin(a), 0.0], [np.sin(a), np.cos(a), 0.0], [0.0, 0.0, 1.0]])
    return np.hstack([R, [[-0.3 * s], [0.0], [0.0]]])


def build(path):
    """The tail's scene, and its framed model written to path (.json, .bin): the one step that
    needs the library (anisofem) rather than the runtime."""
    import anisofem as af
    from anisofem.reduced import Carry, Drag, FramedModel, Loads
    from export.writers.reduced import write_framed
    mesh = af.box_beam((LENGTH, 0.02, 0.02), (16, 2, 2))
    scene = af.Scene(mesh, af.Material(1e5, 0.48, 1000.0, (1.0, 0.0, 0.0), 1e5),
                     fixed=af.metrics.end_vertices(mesh, 0, "min"), gravity=(0, 0, -9.81))
    tip = tuple(int(i) for i in af.metrics.end_vertices(mesh, 0, "max"))
    loads = Loads((Drag(tip, WHIP * scene.masses.sum() * 9.81),),
                  carry=Carry(turn=90, move=0.3, seconds=TURN_STEPS * DT))
    os.makedirs(os.path.dirname(path), exist_ok=True)
    model = FramedModel(scene, loads=loads)
    v = model.validation
    print(f"framed model: {len(model.domains)} domains, r = {model.r}; on {v.cases} unseen "
          f"drags with carries, its tip within {100 * v.tip_error:.2g}% of the full FEM")
    write_framed(model, path, "tail", gravity=scene.gravity)
    return scene


def main():
    import anisofem as af
    path = os.path.join("out", "tail")
    scene = build(path)
    runtime = "C runtime" if native.compiler() else "numpy runtime: no C compiler here"
    sim = native.CFramedSimulator(path) if native.compiler() else FramedSimulator(path)
    x0 = sim.rest_positions
    tip = x0[:, 0] > LENGTH - 1e-9
    gravity = sim.masses[:, None] * np.array([0.0, 0.0, -9.81])
    now = before = sim.rest_state()
    x, v = x0.copy(), np.zeros_like(x0)
    framed, full, carried = [x0], [x0], [x0]
    wall = fem_wall = 0.0
    for k in range(1, STEPS + 1):
        base = hip(k)
        start = time.perf_counter()
        now, before = sim.step(now, before, gravity, DT, base=base), now
        wall += time.perf_counter() - start
        rigid = x0 @ base[:, :3].T + base[:, 3]
        start = time.perf_counter()
        result = af.step(scene.held_at(rigid), x, v, DT)
        fem_wall += time.perf_counter() - start
        x, v = result.x, result.v
        framed.append(sim.positions(now))
        full.append(x)
        carried.append(rigid)
    framed, full, carried = (np.array(a)[:, tip].mean(axis=1) for a in (framed, full, carried))
    swing = np.linalg.norm(full - carried, axis=1).max()
    error = np.linalg.norm(framed - full, axis=1).max() / swing
    print(f"tail tip: largest swing from where the hip carries it {1e3 * swing:.1f} mm; the "
          f"framed model within {100 * error:.2g}% of the full FEM")
    print(f"ms per step: framed model ({runtime}) {1e3 * wall / STEPS:.2f}, full FEM "
          f"{1e3 * fem_wall / STEPS:.2f}")

    fig, ax = plt.subplots(figsize=(6, 5))
    for name, tips, style in (("full FEM", full, "-"), ("framed runtime", framed, "--"),
                              ("carried rigidly", carried, ":")):
        ax.plot(1e3 * tips[:, 0], 1e3 * tips[:, 1], style, label=f"tip, {name}")
    hips = np.array([hip(k)[:2, 3] for k in range(STEPS + 1)])
    ax.plot(1e3 * hips[:, 0], 1e3 * hips[:, 1], color="0.6", lw=3, label="hip")
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")
    ax.set_aspect("equal")
    ax.legend(fontsize=8)
    ax.set_title("a tail on a body that runs and turns, from above")
    fig.tight_layout()
    fig.savefig(os.path.join("out", "tail.png"), dpi=120)
    print("wrote out/tail.png")


if __name__ == "__main__":
    main()
