"""The T pushed against a wall: a moving obstacle pushes a free body along the ground into a
fixed one (Incremental Potential Contact, friction, Neo-Hookean).

The scene is examples/scenes/tee_wall.toml: the T stands free on the ground between two
walls; the left one (the pusher) moves 35 mm to the right over 1.5 s, meets the T's flange,
slides the T along the ground to the right wall and squeezes its flange against it.

    python examples/tee_wall.py

Prints, every 0.2 s of the 2 s rollout (dt = 0.02 s): where the pusher is, the T's width
(its flange, 100 mm at rest), the nearest the T's surface comes to the ground, the wall and
the pusher, and the Newton iterations of the step; then the smallest of those gaps over every
step. Draws the side view at 0, 0.4, 0.8, 1.2, 1.5 and 2.0 s in out/tee_wall.png.
"""
import os
import time

import matplotlib
import numpy as np

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

import anisofem as af  # noqa: E402
from anisofem.io.output import scratch_path  # noqa: E402
from anisofem.physics.contact import surface_nodes  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
DT, STEPS = 0.02, 100
DRAWN = (1, 20, 40, 60, 75, 100)


def gaps(scene, x, placed):
    """(k,) the nearest the surface at x (n, 3) comes to each obstacle where `placed`
    (k, 3) has it, m."""
    nodes, _ = surface_nodes(scene.mesh)
    return np.array([o.moved(p - o.position).distance(x[nodes])[0].min()
                     for o, p in zip(scene.contact.obstacles, placed)])


def main():
    scene = af.load_scene(os.path.join(HERE, "scenes", "tee_wall.toml"))
    names = [o.name for o in scene.contact.obstacles]
    t0 = time.perf_counter()
    roll = af.simulate(scene, STEPS, dt=DT, warn=False)
    seconds = time.perf_counter() - t0
    print(f"the T: {scene.mesh.n_tets} tets, {len(roll.steps)} steps of {DT} s in "
          f"{seconds:.1f} s; contact distance {1e6 * scene.contact.distance:.0f} um")
    print(f"{'t (s)':>5} | {'pusher x (mm)':>13} | {'width (mm)':>10} | "
          + " | ".join(f"{n + ' (um)':>12}" for n in names) + " | Newton")
    nearest = np.full(len(names), np.inf)
    for k, s in enumerate(roll.steps, 1):
        placed = roll.obstacles[k]
        g = gaps(scene, s.x, placed)
        nearest = np.minimum(nearest, g)
        if k % 10 == 0:
            width = float(np.ptp(s.x[:, 0]))
            print(f"{k * DT:5.2f} | {1e3 * placed[names.index('pusher')][0]:13.2f} | "
                  f"{1e3 * width:10.3f} | " + " | ".join(f"{1e6 * v:12.1f}" for v in g)
                  + f" | {s.newton.iterations:6d}")
    inverted = max(s.newton.inversion.inverted for s in roll.steps)
    print("smallest gaps over every step: " + ", ".join(
        f"{n} {1e6 * v:.1f} um" for n, v in zip(names, nearest))
        + f"; inverted elements: {inverted}; every step converged: {roll.converged}")
    draw(roll, names, scratch_path("tee_wall.png"))


def draw(roll, names, path):
    """The side view (x-z) of the T at the steps DRAWN, with the ground and the walls."""
    fig, axes = plt.subplots(1, len(DRAWN), figsize=(2.6 * len(DRAWN), 2.6), sharey=True)
    for ax, k in zip(axes, DRAWN):
        x = roll.steps[k - 1].x
        ax.plot(x[:, 0], x[:, 2], ".", ms=2, color="tab:blue")
        ax.axvline(roll.obstacles[k][names.index("pusher")][0], color="tab:orange", lw=1)
        ax.axvline(roll.obstacles[k][names.index("wall")][0], color="k", lw=1)
        ax.axhline(0.0, color="k", lw=1)
        ax.set_xlim(-0.07, 0.08)
        ax.set_aspect("equal")
        ax.set_title(f"{k * DT:.1f} s", fontsize=9)
        ax.set_xlabel("x (m)")
    axes[0].set_ylabel("z (m)")
    os.makedirs(os.path.dirname(path), exist_ok=True)
    fig.savefig(path, dpi=200, bbox_inches="tight")
    print(f"drew {path}")


if __name__ == "__main__":
    main()
