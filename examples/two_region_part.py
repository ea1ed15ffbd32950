"""A part of two regions from a mesh file with named groups: fibers at +45 degrees in one half
and -45 in the other, held on the face named "base", pulled on the face named "end" by a
traction that follows a load curve (ramped over 0.4 s, then held).

    python examples/two_region_part.py

Reads examples/scenes/part.toml and part.msh, rolls the scene out in backward Euler through
its load curve, prints the end's motion, draws three moments (out/two_region_part.png) and
writes the rollout as a ParaView collection (out/two_region_part.pvd).
"""
import os

import matplotlib
import numpy as np

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

import anisofem as af  # noqa: E402
import anisofem.io.draw  # noqa: E402,F401

SCENE = os.path.join(os.path.dirname(os.path.abspath(__file__)), "scenes", "part.toml")
STEPS, DT = 40, 0.02


def main():
    scene = af.load_scene(SCENE)
    rollout = af.simulate(scene, STEPS, DT)
    X = scene.mesh.vertices
    end = np.flatnonzero(X[:, 0] > X[:, 0].max() - 1e-9)
    for k in range(0, STEPS + 1, 10):
        u = 1e3 * (rollout.positions[k][end] - X[end]).mean(axis=0)
        print(f"t = {k * DT:4.2f} s: the end moved {u[0]:6.2f} mm along x, {u[2]:6.2f} mm along "
              f"z")
    print(f"converged: {rollout.converged}")
    os.makedirs("out", exist_ok=True)
    times = DT * np.arange(len(rollout.positions))
    af.io.write_series("out/two_region_part.pvd", scene.mesh, rollout.positions, times, scene)
    picks = [10, 20, STEPS]
    u_max = max(np.linalg.norm(rollout.positions[k] - X, axis=1).max() for k in picks)
    norm = matplotlib.colors.Normalize(0, 1e3 * u_max)
    fig = plt.figure(figsize=(12, 3.6))
    for i, k in enumerate(picks):
        ax = fig.add_subplot(1, len(picks), i + 1, projection="3d")
        af.io.draw.deformed_surface(ax, scene.mesh, rollout.positions[k], norm)
        ax.set(xlim=(0, 0.095), ylim=(-0.02, 0.02), zlim=(-0.02, 0.02), box_aspect=(9.5, 4, 4))
        ax.view_init(elev=18, azim=-70)
        ax.set_axis_off()
        ax.set_title(f"t = {k * DT:.1f} s (traction {min(k * DT / 0.4, 1):.0%})", fontsize=10)
    fig.subplots_adjust(left=0, right=0.9, bottom=0, top=0.85, wspace=0)
    fig.colorbar(plt.cm.ScalarMappable(norm, "viridis"), cax=fig.add_axes((0.91, 0.15, 0.012, 0.6)),
                 label="displacement (mm)")
    fig.suptitle("Two regions, fibers at +45 and -45 degrees, pulled along x (rest ghosted)")
    fig.savefig("out/two_region_part.png", dpi=120)
    print("wrote out/two_region_part.png and out/two_region_part.pvd")


if __name__ == "__main__":
    main()
