"""A fiber-reinforced cantilever stepped by the exported network with only the runtime.

Everything here is what a deployment has: export/runtime.py (numpy + onnxruntime), a .onnx
model, and a mesh (built below with numpy). No torch, numba, scipy or anisofem is imported.
The 0.1 x 0.02 x 0.02 m beam is clamped at x = 0, has fibers at 45 degrees in the x-z plane
(kappa = 100 kPa), falls under gravity for 200 steps of 20 ms, and out/onnx_cantilever.png
shows its rest and final states from the side.

    python examples/onnx_cantilever.py [MODEL.onnx]   (default export/models/directional.onnx)
"""
import os
import sys

import matplotlib
import numpy as np

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "export"))  # as if runtime.py were copied here
from runtime import OnnxSimulator  # noqa: E402

#: the model the examples step unless given another
DEFAULT_MODEL = os.path.join(HERE, "..", "export", "models", "directional.onnx")

#: the six tets of a unit cube sharing its diagonal 0-7 (corners numbered x + 2 y + 4 z)
KUHN = np.array([[0, 1, 3, 7], [0, 1, 5, 7], [0, 2, 3, 7], [0, 2, 6, 7], [0, 4, 5, 7],
                 [0, 4, 6, 7]])


def box_tets(size, cells):
    """(vertices (n, 3) m, tets (m, 4)) of a box [0, size] split into cells hexes, 6 tets each
    (the same split in every hex, so faces match)."""
    axes = [np.linspace(0.0, s, c + 1) for s, c in zip(size, cells)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)
    index = np.arange(grid[..., 0].size).reshape(grid.shape[:3])
    corners = np.stack([index[dx:dx + cells[0], dy:dy + cells[1], dz:dz + cells[2]].ravel()
                        for dz in (0, 1) for dy in (0, 1) for dx in (0, 1)], axis=1)
    return grid.reshape(-1, 3), corners[:, KUHN].reshape(-1, 4)


def main(model):
    vertices, tets = box_tets((0.1, 0.02, 0.02), (10, 2, 2))
    sim = OnnxSimulator(model, vertices, tets, fixed=vertices[:, 0] < 1e-9, density=1000.0,
                        fiber_direction=(1.0, 0.0, 1.0), fiber_stiffness=1e5)
    gravity = sim.masses[:, None] * np.array([0.0, 0.0, -9.81])  # N per vertex
    positions = sim.rollout(200, gravity)
    tip = vertices[:, 0] > 0.1 - 1e-9
    uz = positions[:, tip, 2].mean(axis=1) - vertices[tip, 2].mean()
    print(f"{len(tets)} tets, dt = {sim.dt} s: mean tip z displacement after 1 s "
          f"{1e3 * uz[50]:+.2f} mm, after 4 s {1e3 * uz[-1]:+.2f} mm, lateral tip drift "
          f"{1e3 * np.abs(positions[-1, tip, 1] - vertices[tip, 1]).max():.3f} mm")

    # the front face (y = 0) at rest in gray and after 4 s colored by displacement; the tip
    front = tets[(vertices[tets, 1] < 1e-9).sum(axis=1) == 3]
    tri = np.array([[v for v in t if vertices[v, 1] < 1e-9] for t in front])
    u = 1e3 * np.linalg.norm(positions[-1] - vertices, axis=1)
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(11, 3), width_ratios=(1.6, 1))
    ax.triplot(1e3 * vertices[:, 0], 1e3 * vertices[:, 2], tri, color="0.75", lw=0.6)
    shade = ax.tripcolor(1e3 * positions[-1, :, 0], 1e3 * positions[-1, :, 2], tri, u,
                         shading="gouraud", cmap="viridis")
    fig.colorbar(shade, ax=ax, label="displacement after 4 s (mm)")
    ax.set(xlabel="x (mm)", ylabel="z (mm)", aspect="equal",
           title="front face: rest (gray) and after 4 s")
    bx.plot(sim.dt * np.arange(len(uz)), 1e3 * uz, color="tab:blue")
    bx.set(xlabel="t (s)", ylabel="tip z displacement (mm)", title="tip under gravity")
    fig.suptitle("Cantilever, fibers at 45 deg in x-z, stepped by the exported network "
                 "(onnxruntime only)", fontsize=10, y=1.04)
    save(fig, "onnx_cantilever.png")


def save(fig, name):
    """Write the matplotlib figure to out/name and say so."""
    os.makedirs("out", exist_ok=True)
    fig.savefig(os.path.join("out", name), dpi=150, bbox_inches="tight")
    print(f"wrote out/{name}")


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else DEFAULT_MODEL)
