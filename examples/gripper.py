"""A soft gripper grasps, lifts and holds a box by friction: two pressure-driven fingers and a
foam box in one mesh, their contact with each other by Incremental Potential Contact
(self-contact, ipctk), the box on the ground (an obstacle).

The scene is examples/scenes/gripper.toml: the control "grip" fills both fingers' cavities
over 0.4 s (30 kPa), their held bases lift 3 cm from 0.5 to 1.0 s and hold it there to 2 s.
The box rises only by the fingers' friction on its sides (0.8); with friction 0.1 it stays on
the ground (--friction 0.1).

    python examples/gripper.py [--friction MU] [--seconds T]

Prints, every 0.1 s (dt = 0.01 s): the grip pressure, how far the bases and the box have
risen, the box's slip (the bases' rise less the box's), the nearest the fingers and the box
come to each other and the Newton iterations of the step; then the box's height while held,
its slip over the hold, and whether any step intersected (ipctk's own test), inverted an
element or failed to converge. Draws the front view (y-z) at 0, 0.4, 1.0 s and the end in
out/gripper.png.
"""
import argparse
import os
import time
from dataclasses import replace

import matplotlib
import numpy as np

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

import anisofem as af  # noqa: E402
from anisofem.io.output import scratch_path  # noqa: E402
from anisofem.io.scenefile import SceneFile  # noqa: E402
from anisofem.physics.contact import ContactTerm  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
SCENE = os.path.join(HERE, "scenes", "gripper.toml")
DT = 0.01
#: The lift ends here, s: the hold is what follows.
LIFTED = 1.0


def grasp(friction=None, seconds=2.0):
    """Roll the gripper out for `seconds` s (friction: the fingers' on the box, default the
    scene file's). Returns (scene, the box's vertices (n,) bool, the held vertices (n,) bool,
    the Rollout, wall seconds)."""
    read = SceneFile(SCENE)
    scene = read.scene
    if friction is not None:
        scene = scene.with_contact(replace(scene.contact, friction=friction))
    box = np.zeros(scene.mesh.n_vertices, bool)
    box[np.unique(scene.mesh.tets[read.region("box")])] = True
    held = scene.fixed_mask.all(axis=1)
    t0 = time.perf_counter()
    roll = af.simulate(scene, int(round(seconds / DT)), dt=DT, warn=False)
    return scene, box, held, roll, time.perf_counter() - t0


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--friction", type=float, default=None,
                        help="the fingers' friction on the box (default: the scene's, 0.8)")
    parser.add_argument("--seconds", type=float, default=2.0)
    args = parser.parse_args()
    scene, box, held, roll, seconds = grasp(args.friction, args.seconds)
    itself = ContactTerm(scene).itself
    X = scene.mesh.vertices
    print(f"gripper: {scene.mesh.n_tets} tets, {len(roll.steps)} steps of {DT} s in "
          f"{seconds:.1f} s; contact distance {1e6 * itself.dhat:.0f} um")
    print(f"{'t (s)':>5} | {'grip (kPa)':>10} | {'bases up (mm)':>13} | {'box up (mm)':>11} | "
          f"{'slip (mm)':>9} | {'nearest (um)':>12} | Newton")
    intersected, heights = 0, []
    for k, s in enumerate(roll.steps, 1):
        t = k * DT
        intersected += bool(itself.ipctk.has_intersections(itself.mesh, itself.vertices(s.x)))
        bases = float((s.x[held, 2] - X[held, 2]).mean())
        lift = float((s.x[box, 2] - X[box, 2]).mean())
        if t > LIFTED:
            heights.append(lift)
        if k % 10 == 0:
            grip = scene.at(t).control_values[0]
            print(f"{t:5.2f} | {grip / 1e3:10.1f} | {1e3 * bases:13.3f} | {1e3 * lift:11.3f} | "
                  f"{1e3 * (bases - lift):9.3f} | {1e6 * itself.nearest(s.x):12.1f} | "
                  f"{s.newton.iterations:6d}")
    inverted = max(s.newton.inversion.inverted for s in roll.steps)
    if heights:
        print(f"held from {LIFTED} s: the box {1e3 * heights[0]:.3f} mm up, slipped "
              f"{1e3 * (heights[0] - heights[-1]):.3f} mm by {len(roll.steps) * DT:.1f} s")
    print(f"steps that intersected: {intersected}; inverted elements: {inverted}; every step "
          f"converged: {roll.converged}")
    states = [X] + [s.x for s in roll.steps]
    drawn = sorted({0, 40, int(LIFTED / DT), len(roll.steps)} & set(range(len(states))))
    draw(states, drawn, box, scratch_path("gripper.png"))


def draw(states, drawn, box, path):
    """The front view (y-z) of the states at the steps `drawn`, fingers and box apart."""
    fig, axes = plt.subplots(1, len(drawn), figsize=(2.4 * len(drawn), 3.2), sharey=True)
    for ax, k in zip(np.atleast_1d(axes), drawn):
        x = states[k]
        ax.plot(x[~box, 1], x[~box, 2], ".", ms=2, color="tab:blue")
        ax.plot(x[box, 1], x[box, 2], ".", ms=2, color="tab:orange")
        ax.axhline(0.0, color="k", lw=1)
        ax.set_title(f"{k * DT:.2f} s", fontsize=9)
        ax.set_aspect("equal")
        ax.set_xticks([-0.03, 0.0, 0.03])
        ax.set_xlabel("y (m)")
    np.atleast_1d(axes)[0].set_ylabel("z (m)")
    os.makedirs(os.path.dirname(path), exist_ok=True)
    fig.savefig(path, dpi=200, bbox_inches="tight")
    print(f"drew {path}")


if __name__ == "__main__":
    main()
