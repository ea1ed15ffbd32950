"""Two soft fingers on a MuJoCo slide grasp a MuJoCo box, lift it and hold it: the fingers'
reduced model (examples/scenes/fingers.toml: gripper.toml's fiber-reinforced bending
actuators) is the MuJoCo plugin "anisofem.soft" on the slide's body, its control "grip" a
plugin actuator; the box is a free MuJoCo body whose geom is named as the file's obstacle
"box", so each soft step solves the box's translation with the fingers' and MuJoCo applies
their push and friction on it over the same step (export/mujoco.py).

The grip fills both cavities to 30 kPa over 0.4 s; the slide (a position servo) lifts the
fingers 3 cm from 0.5 to 1 s and holds; the box stands on MuJoCo's ground (friction 0.5) and
goes up by the fingers' friction alone (0.8). MuJoCo and the soft body step at 0.01 s
(implicitfast). Prints the box's and the hand's heights every 0.2 s, the box's slip against
the hand over the hold (from 1 s), the least gap between the fingers and the box, how far the
box turned, and the real-time factor; draws the heights in out/mujoco_gripper.png.

    python examples/mujoco_gripper.py [--seconds T]
"""
import argparse
import os
import time

import matplotlib
import numpy as np

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from anisofem.io.output import scratch_path  # noqa: E402
from anisofem.io.scenefile import SceneFile  # noqa: E402
from anisofem.reduced import Loads, ReducedModel  # noqa: E402
from export import mujoco as plugin, native  # noqa: E402
from export.writers.reduced import write  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
SCENE = os.path.join(HERE, "scenes", "fingers.toml")
DT = 0.01
#: The grip's pressure, Pa, reached over SQUEEZE s; the lift, m, from LIFT[0] to LIFT[1] s.
GRIP, SQUEEZE = 3.0e4, 0.4
RISE, LIFT = 0.03, (0.5, 1.0)
#: The fingers' vibration modes and the principal directions of their grip's equilibria.
MODES, SNAPSHOTS = 4, 6
HAND = """<joint name="lift" type="slide" axis="0 0 1"/>
      <geom type="box" size="0.012 0.04 0.004" pos="0 0 0.096" mass="0.2" contype="0"
            conaffinity="0"/>
      <site name="palm" pos="0 0 0.092"/>
      <plugin instance="fingers"/>"""
WORLD = """
    <light pos="0 -0.3 0.6" dir="0 0.5 -1"/>
    <geom name="ground" type="plane" size="0.2 0.2 0.01" friction="0.5"/>
    <body name="carton" pos="0 0 0.02005">
      <freejoint/>
      <geom name="box" type="box" size="0.015 0.015 0.02" density="300" friction="0.5"
            rgba="0.8 0.6 0.3 1"/>
    </body>"""


def fingers(path):
    """The fingers' reduced model (its grip declared over 0 .. GRIP), written to path."""
    scene = SceneFile(SCENE).scene
    model = ReducedModel(scene, modes=MODES, snapshots=SNAPSHOTS, validate=False,
                         loads=Loads(controls={"grip": (0.0, GRIP)}))
    write(model, path)
    return model


def gripper_mjcf(path):
    """The MJCF: the fingers' file on the body "hand" on a vertical slide (a position servo
    "lift"), the box on the ground, the plugin actuator "grip"."""
    text = plugin.mjcf(path, body="hand", name="fingers", world=WORLD)
    text = text.replace('<plugin instance="fingers"/>', HAND)
    text = text.replace("<worldbody>", '<option timestep="0.01" integrator="implicitfast"/>'
                        "\n  <worldbody>", 1)
    return text.replace("</worldbody>", """</worldbody>
  <actuator>
    <position name="lift" joint="lift" kp="2000" kv="100"/>
    <plugin name="grip" instance="fingers" site="palm"/>
  </actuator>""")


def controls(t):
    """(grip, Pa; the slide's target, m) at time t, s."""
    s = min(max((t - LIFT[0]) / (LIFT[1] - LIFT[0]), 0.0), 1.0)
    return GRIP * min(t / SQUEEZE, 1.0), RISE * (0.5 - 0.5 * np.cos(np.pi * s))


def lift(seconds=3.0, folder=None):
    """Run the grasp for `seconds` s. Returns a dict of arrays over the steps: t (s), box and
    hand heights (m), gap (the least distance of a finger surface node from the box, m), turn
    (the box's turn from upright, rad); the wall time, s; r; and "views": (t, the fingers'
    surface nodes (k, 3) m, the box's center (3,) m) at rest, at the end of the squeeze and at
    the end."""
    mujoco = plugin.mujoco_module()
    plugin.load_plugin()
    folder = folder or scratch_path("mujoco_gripper")
    os.makedirs(folder, exist_ok=True)
    path = os.path.join(folder, "fingers")
    model_r = fingers(path)
    model = mujoco.MjModel.from_xml_string(gripper_mjcf(path))
    data = mujoco.MjData(model)
    runtime = native.CModel(path)
    box, hand = model.body("carton").id, model.body("hand").id
    grip, servo = model.actuator("grip").id, model.actuator("lift").id
    surface = np.unique(runtime.surface)
    half = np.array([0.015, 0.015, 0.02])
    rows = {k: [] for k in ("t", "box", "hand", "gap", "turn")}
    wall, views, steps = 0.0, [], int(round(seconds / DT))
    for step in range(steps):
        data.ctrl[grip], data.ctrl[servo] = controls(data.time)
        t0 = time.perf_counter()
        mujoco.mj_step(model, data)
        wall += time.perf_counter() - t0
        x = runtime._positions(data.plugin_state[plugin.HEADER:]) + data.xpos[hand]
        R = data.xmat[box].reshape(3, 3)
        local = np.abs((x[surface] - data.xpos[box]) @ R) - half
        gap = np.linalg.norm(np.maximum(local, 0.0), axis=1) + np.minimum(local.max(axis=1), 0)
        rows["t"].append(data.time)
        rows["box"].append(data.xpos[box, 2])
        rows["hand"].append(data.xpos[hand, 2])
        rows["gap"].append(gap.min())
        rows["turn"].append(np.arccos(np.clip(R[2, 2], -1.0, 1.0)))
        if step in (0, int(round(LIFT[0] / DT)) - 1, steps - 1):
            views.append((data.time, x[surface], data.xpos[box].copy()))
    out = {k: np.array(v) for k, v in rows.items()}
    out["wall"], out["r"], out["views"] = wall, model_r.r, views
    return out


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seconds", type=float, default=3.0)
    args = parser.parse_args()
    run = lift(args.seconds)
    t, box, hand = (run["t"], 1e3 * (run["box"] - run["box"][0]),
                    1e3 * (run["hand"] - run["hand"][0]))
    print(f"fingers: reduced model, r = {run['r']}; MuJoCo and soft step {DT} s")
    print(f"{'t (s)':>5} | {'grip (kPa)':>10} | {'hand up (mm)':>12} | {'box up (mm)':>11} | "
          f"{'gap (um)':>8}")
    for k in range(19, len(t), 20):
        print(f"{t[k]:5.2f} | {controls(t[k] - DT)[0] / 1e3:10.1f} | {hand[k]:12.3f} | "
              f"{box[k]:11.3f} | {1e6 * run['gap'][k]:8.1f}")
    hold = t >= LIFT[1]
    if hold.any():
        relative = box[hold] - hand[hold]
        print(f"held from {LIFT[1]} s to {t[-1]:.2f} s: the box {box[hold].mean():.3f} mm up, "
              f"slip against the hand {abs(relative[-1] - relative[0]):.3f} mm (most "
              f"{np.ptp(relative):.3f})")
    print(f"least gap fingers-box {1e6 * run['gap'].min():.1f} um; box turned at most "
          f"{np.degrees(run['turn'].max()):.3f} deg; {len(t)} steps in {run['wall']:.2f} s: "
          f"{t[-1] / run['wall']:.0f}x real time")
    figure, (axes, side) = plt.subplots(1, 2, figsize=(10, 4))
    axes.plot(t, hand, label="hand")
    axes.plot(t, box, label="box")
    axes.set(xlabel="t (s)", ylabel="up (mm)", title="a MuJoCo box lifted by soft fingers")
    axes.legend()
    for (when, nodes, center), color in zip(run["views"], ("0.7", "tab:blue", "tab:red")):
        side.scatter(1e3 * nodes[:, 1], 1e3 * nodes[:, 2], s=1, color=color,
                     label=f"t = {when:.2f} s")
        side.add_patch(plt.Rectangle((1e3 * (center[1] - 0.015), 1e3 * (center[2] - 0.02)),
                                     30.0, 40.0, fill=False, color=color))
    side.set(xlabel="y (mm)", ylabel="z (mm)", title="seen from the side", aspect="equal")
    side.legend(markerscale=8)
    figure.tight_layout()
    path = scratch_path("mujoco_gripper.png")
    figure.savefig(path, dpi=120)
    print(f"drew {path}")


if __name__ == "__main__":
    main()
