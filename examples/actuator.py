"""A fiber-reinforced soft actuator inflated: a scene file with regions, a wound fiber field, a
held base and pressure in a cavity.

    python examples/actuator.py          # bends: fibers at +-88 degrees (crossed hoops)
    python examples/actuator.py twist    # bends and twists: one family, 88 -> 60 degrees

Reads examples/scenes/actuator.toml (or actuator_twist.toml) and its mesh (examples/scenes/
actuator.msh, made by anisofem.physics.meshgen.actuator: an elastomer body of half-circular section
around a cavity on a stiff strain-limiting layer). Ramps the cavity's pressure in static
solves, prints the tip's bending and twist at each pressure, draws the actuator at four of them
(out/actuator.png or out/actuator_twist.png) and writes the ramp as a ParaView collection
(out/actuator.pvd, one .vtu per pressure, with the fiber field as cell data).
"""
import os
import sys

import matplotlib
import numpy as np
from scipy.spatial.transform import Rotation

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

import anisofem as af  # noqa: E402
import anisofem.io.draw  # noqa: E402,F401

SCENES = os.path.join(os.path.dirname(os.path.abspath(__file__)), "scenes")
#: Shares of the scene file's pressure the ramp solves for, in order.
SHARES = np.linspace(0.1, 1.0, 10)


def tip_turn(scene, x):
    """(bending, twist) of the tip face in degrees: the best-fit rotation of its vertices from
    rest to x (Kabsch), split into a swing of the z axis and a twist about it."""
    X = scene.mesh.vertices
    tip = np.flatnonzero(np.abs(X[:, 2] - X[:, 2].max()) < 1e-9 * scene.mesh.size)
    rest, now = X[tip] - X[tip].mean(0), x[tip] - x[tip].mean(0)
    u, _, vt = np.linalg.svd(now.T @ rest)
    R = u @ np.diag([1.0, 1.0, np.linalg.det(u @ vt)]) @ vt
    bend = np.degrees(np.arccos(np.clip(R[2, 2], -1.0, 1.0)))
    qx, qy, qz, qw = Rotation.from_matrix(R).as_quat()
    return bend, np.degrees(2.0 * np.arctan2(qz, qw))


def main(kind):
    name = "actuator" if kind == "bend" else "actuator_twist"
    scene = af.load_scene(os.path.join(SCENES, f"{name}.toml"))
    pressure = scene.pressures[0].magnitude
    os.makedirs("out", exist_ok=True)
    states, bends, x = [scene.initial_positions()], [0.0], None
    for share in SHARES:
        result = af.solve(scene.loaded(share), x0=x)
        x = result.x
        bend, twist = tip_turn(scene, x)
        print(f"{share * pressure / 1e3:5.1f} kPa: {result.iterations:2d} Newton iterations, "
              f"converged {result.converged}, tip bent {bend:5.1f} deg, twisted {twist:5.1f} "
              f"deg")
        states.append(x)
        bends.append(bend)
    print(f"bending grows with pressure: {bool(np.all(np.diff(bends) > 0))}")
    af.io.write_series(f"out/{name}.pvd", scene.mesh, states,
                       np.concatenate([[0.0], SHARES * pressure]), scene)
    draw(scene, states, pressure, f"out/{name}.png", kind)
    print(f"wrote out/{name}.png and out/{name}.pvd")


def draw(scene, states, pressure, path, kind):
    """Four states of the ramp side by side, colored by displacement."""
    picks = [3, 6, 8, len(states) - 1]
    X = scene.mesh.vertices
    u_max = max(np.linalg.norm(states[k] - X, axis=1).max() for k in picks)
    norm = matplotlib.colors.Normalize(0, 1e3 * u_max)
    fig = plt.figure(figsize=(12, 5))
    lo = np.min([states[k].min(0) for k in picks], axis=0)
    hi = np.max([states[k].max(0) for k in picks], axis=0)
    for i, k in enumerate(picks):
        ax = fig.add_subplot(1, len(picks), i + 1, projection="3d")
        af.io.draw.deformed_surface(ax, scene.mesh, states[k], norm)
        ax.set(xlim=(lo[0], hi[0]), ylim=(lo[1], hi[1]), zlim=(lo[2], hi[2]),
               box_aspect=tuple(hi - lo))
        ax.view_init(elev=8, azim=-35)
        ax.set_axis_off()
        bend, twist = tip_turn(scene, states[k])
        # the caption under the body's foot, where the view leaves room (above it, the tip
        # bends into the caption)
        ax.text2D(0.5, 0.03, f"{SHARES[k - 1] * pressure / 1e3:.0f} kPa\nbent {bend:.0f} deg, "
                  f"twisted {twist:.0f} deg", transform=ax.transAxes, fontsize=9,
                  ha="center", va="top")
    fig.subplots_adjust(left=0, right=0.9, bottom=0, top=0.88, wspace=0)
    fig.colorbar(plt.cm.ScalarMappable(norm, "viridis"), cax=fig.add_axes((0.91, 0.15, 0.012, 0.6)),
                 label="displacement (mm)")
    what = ("fibers at +-88 degrees (crossed)" if kind == "bend" else
            "one fiber family, 88 degrees at the base to 60 at the tip")
    fig.suptitle(f"Soft actuator inflated: {what};\nstrain-limiting layer on the flat side "
                 f"(rest ghosted)", fontsize=11)
    fig.savefig(path, dpi=120)


if __name__ == "__main__":
    args = sys.argv[1:]
    if args not in ([], ["twist"]):
        sys.exit("usage: python examples/actuator.py [twist]")
    main("bend" if not args else "twist")
