"""A tentacle that reaches for targets: four bands of contractile fibers around its axis, each
band's activation a control, and the controls that bring its tip to a target found at static
equilibrium in its reduced model (inverse statics, ReducedModel.reach), checked against the
full FEM and, where a C compiler is found, solved again by the C runtime (af_reach).

The tentacle is examples/scenes/tentacle.toml: a 0.2 m cylinder of radius 15 mm along x (StVK,
E = 100 kPa, nu = 0.45, fibers along it with kappa = 500 kPa), held at its base under gravity
along -z; the fibers of each quarter of its section (up +z, down -z, left +y, right -y)
contract by an activation in [0, 0.1] (their rest stretch 1 - a). Its reduced model is fitted to those ranges (4 modes, the
static response to each band and 14 directions fitted to static equilibria under single,
paired and combined activations: r = 22).

    python examples/tentacle.py

Prints, per target: the controls found, the tip's distance to the target in the model, the
full FEM's tip at those controls (what the body does) and the time of each solve; a target
above the tentacle's reach says so and gives the nearest point found. Draws the tentacle at
each answer in out/tentacle.png.
"""
import os
import sys
import time

import matplotlib
import numpy as np

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

import anisofem as af  # noqa: E402
from anisofem.io.output import scratch_path  # noqa: E402
from anisofem.io.scenefile import SceneFile  # noqa: E402
from anisofem.reduced import Loads, ReducedModel  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
LENGTH = 0.2
#: Targets for the tip (m): four within reach (at rest it hangs to (0.1995, 0, -0.0142)),
#: then one above it.
TARGETS = ((0.185, 0.04, 0.0), (0.185, -0.035, 0.02), (0.19, 0.0, 0.03), (0.185, 0.02, -0.05),
           (0.12, 0.0, 0.12))


def tentacle():
    """(the tentacle's Scene, its bands' ranges {name: (low, high)}): the scene file's."""
    scene_file = SceneFile(os.path.join(HERE, "scenes", "tentacle.toml"))
    return scene_file.scene, scene_file.control_ranges


def c_runtime(model, folder):
    """The model written to folder/tentacle and loaded by the C runtime, or None without a C
    compiler."""
    sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))
    from export import native
    from export.writers.reduced import write
    if native.compiler() is None:
        return None
    path = os.path.join(folder, "tentacle")
    write(model, path, title="tentacle")
    c = native.CReducedSimulator(path)
    c.set_constant_force(model.scene.external_force)
    return c


def main():
    scene, ranges = tentacle()
    t0 = time.perf_counter()
    model = ReducedModel(scene, modes=4, snapshots=14, loads=Loads(controls=ranges))
    print(f"tentacle: {scene.mesh.n_tets} tets; reduced model r = {model.r}, built in "
          f"{time.perf_counter() - t0:.1f} s")
    tip = np.flatnonzero(scene.mesh.vertices[:, 0] > LENGTH - 1e-9)
    center = int(tip[np.argmin(np.linalg.norm(scene.mesh.vertices[tip, 1:], axis=1))])
    folder = os.path.dirname(scratch_path("tentacle.png"))
    os.makedirs(folder, exist_ok=True)
    c = c_runtime(model, folder)
    low, high = np.array([ranges[name] for name in model.controls]).T
    print(f"{'target (m)':>22} | {'controls: ' + ' '.join(model.controls):>28} | model "
          f"(mm) | FEM (mm) | reach (ms) | C (ms)")
    shapes = []
    for target in TARGETS:     # each from rest: the controls written in the scene, q = 0
        t1 = time.perf_counter()
        found = model.reach(center, target)
        seconds = time.perf_counter() - t1
        full = af.solve(scene.with_controls(found.controls), warn=False).x
        fem = np.linalg.norm(full[center] - target)
        c_ms = ""
        if c is not None:
            t1 = time.perf_counter()
            c.reach([center], [1.0], target, low, high)
            c_ms = f"{1e3 * (time.perf_counter() - t1):.2f}"
        print(f"{str(tuple(target)):>22} | {' '.join(f'{u:.3f}' for u in found.controls):>28} "
              f"| {1e3 * found.distance:10.3f} | {1e3 * fem:8.3f} | {1e3 * seconds:10.1f} | "
              f"{c_ms:>6}")
        if not found.reached:
            print(f"  {found.message}")
        shapes.append((target, full))
    draw(scene, shapes, scratch_path("tentacle.png"))


def draw(scene, shapes, path):
    """The tentacle's vertices seen from the side (x-z) and from the end (y-z) at each
    answer, with its target."""
    fig, axes = plt.subplots(1, 2, figsize=(10, 4.5))
    for k, (target, x) in enumerate(shapes):
        color = f"C{k}"
        for ax, (i, j) in zip(axes, ((0, 2), (1, 2))):
            ax.plot(x[:, i], x[:, j], ".", ms=2, color=color)
            ax.plot(target[i], target[j], "x", ms=10, mew=2, color=color)
    for ax, title in zip(axes, ("side (x-z)", "end (y-z)")):
        ax.set_title(title)
        ax.set_aspect("equal")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    print(f"drew {path}")


if __name__ == "__main__":
    main()
