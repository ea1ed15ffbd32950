"""A tentacle dropped onto the ground: contact with friction (Incremental
Potential Contact), no node ever passing an obstacle, no element inverted (Neo-Hookean).

The scene is examples/scenes/tentacle_drop.toml: the 0.2 m tentacle of tentacle.toml, free,
3 cm above the ground, friction 0.5. Its section is a polygon: it lands on an edge and, a
moment later, rolls onto a face (its kinetic energy rises to about 1e-4 J and dies away).

    python examples/tentacle_drop.py

Prints, every 0.2 s of the 2 s rollout (dt = 0.01 s): the lowest point, the smallest gap
between the surface and an obstacle, the kinetic energy and the Newton iterations of the step;
then the smallest gap over every step and whether the tentacle came to rest. Draws its side
view at 0, 0.05, 0.08, 0.12 and 2 s in out/tentacle_drop.png.
"""
import os
import time

import matplotlib
import numpy as np

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

import anisofem as af  # noqa: E402
from anisofem.io.output import scratch_path  # noqa: E402
from anisofem.physics.contact import ContactTerm  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
DT, STEPS = 0.01, 200
DRAWN = (0, 5, 8, 12, 200)


def main():
    scene = af.load_scene(os.path.join(HERE, "scenes", "tentacle_drop.toml"))
    term = ContactTerm(scene)
    t0 = time.perf_counter()
    roll = af.simulate(scene, STEPS, dt=DT, warn=False)
    seconds = time.perf_counter() - t0
    print(f"tentacle: {scene.mesh.n_tets} tets, {STEPS} steps of {DT} s in {seconds:.1f} s; "
          f"contact distance {1e6 * term.dhat:.0f} um")
    print(f"{'t (s)':>6} | {'lowest z (mm)':>13} | {'gap (um)':>9} | {'kinetic (J)':>11} | "
          f"Newton")
    gaps = []
    for k, s in enumerate(roll.steps, 1):
        gaps.append(float(term.distances(s.x).min()))
        if k % 20 == 0:
            kinetic = 0.5 * float(scene.masses @ (s.v ** 2).sum(axis=1))
            print(f"{k * DT:6.2f} | {1e3 * s.x[:, 2].min():13.3f} | {1e6 * gaps[-1]:9.1f} | "
                  f"{kinetic:11.3g} | {s.newton.iterations:6d}")
    inverted = max(s.newton.inversion.inverted for s in roll.steps)
    last = roll.steps[-1]
    print(f"smallest gap over every step: {1e6 * min(gaps):.1f} um; inverted elements: "
          f"{inverted}; every step converged: {roll.converged}; at rest: "
          f"{float(np.abs(last.v).max()):.2g} m/s largest speed")
    draw(scene, [scene.initial_positions()] + [s.x for s in roll.steps],
         scratch_path("tentacle_drop.png"))


def draw(scene, states, path):
    """The side view (x-z) of the states at DRAWN steps, with the ground."""
    fig, ax = plt.subplots(figsize=(8, 3.2))
    colors = plt.cm.viridis(np.linspace(0.0, 0.9, len(DRAWN)))
    for k, color in zip(DRAWN, colors):
        x = states[k]
        ax.plot(x[:, 0], x[:, 2], ".", ms=3, color=color, label=f"{k * DT:.2f} s")
    ax.axhline(-0.045, color="k", lw=1)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("z (m)")
    ax.legend(loc="upper right", fontsize=7, ncol=5)
    os.makedirs(os.path.dirname(path), exist_ok=True)
    fig.savefig(path, dpi=200, bbox_inches="tight")
    print(f"drew {path}")


if __name__ == "__main__":
    main()
