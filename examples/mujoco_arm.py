"""A three-link MuJoCo arm carries a soft finger through a motion: the finger's framed model
(anisofem.reduced.FramedModel, fibers along it) is the MuJoCo plugin "anisofem.soft" on
the arm's hand (export/mujoco.py), stepped by the C runtime as MuJoCo steps, pulling the hand
back as it swings.

The arm: a base turning about z, a shoulder and an elbow about their y axes (0.25 m links)
and a wrist, position servos following sines for 5 s (MuJoCo's implicitfast integrator, dt =
0.01 s). The finger (12 cm, 240 tets, E = 50 kPa, fibers along it at 200 kPa; 2 bands of 6
coordinates) sticks out of the hand, held at one end. Prints the real-time factor (simulated
seconds per wall second, the finger included), how far the finger's tip is from where the hand
would carry it rigidly (its sag and swing), and the servos' tracking error; draws the hand's
path and the finger tip's seen from above in out/mujoco_arm.png.

    python examples/mujoco_arm.py [--seconds T]
"""
import argparse
import os
import time

import matplotlib
import numpy as np

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

import anisofem as af  # noqa: E402
from anisofem.io.output import scratch_path  # noqa: E402
from anisofem.reduced import FramedModel  # noqa: E402
from export import mujoco as plugin, native  # noqa: E402
from export.writers.reduced import write_framed  # noqa: E402

DT = 0.01
LENGTH = 0.12
ARM = """
  <option integrator="implicitfast"/>
  <default>
    <joint damping="0.5" armature="0.01"/>
    <position kp="40" kv="2"/>
    <geom type="capsule" size="0.02" rgba="0.7 0.7 0.7 1"/>
  </default>"""


def finger(path):
    """The finger's scene, and its framed model written to path (.json, .bin)."""
    mesh = af.box_beam((LENGTH, 0.016, 0.016), (12, 2, 2))
    scene = af.Scene(mesh, af.Material(5e4, 0.45, 1100.0, (1.0, 0.0, 0.0), 2e5),
                     fixed=af.metrics.end_vertices(mesh, 0, "min"), gravity=(0, 0, -9.81))
    write_framed(FramedModel(scene, bands=2, coordinates=6, validate=False), path)
    return scene


def arm_mjcf(path):
    """The arm's MJCF with the finger on its hand (pointing along the last link)."""
    links = """
      <body name="upper" pos="0 0 0.1">
        <joint name="base" type="hinge" axis="0 0 1"/>
        <joint name="shoulder" type="hinge" axis="0 1 0"/>
        <geom fromto="0 0 0 0.25 0 0" mass="1"/>
        <body name="lower" pos="0.25 0 0">
          <joint name="elbow" type="hinge" axis="0 1 0"/>
          <geom fromto="0 0 0 0.25 0 0" mass="0.6"/>
          <body name="hand" pos="0.27 0 0">
            <joint name="wrist" type="hinge" axis="0 1 0"/>
            <geom type="sphere" size="0.015" mass="0.05"/>
            <plugin instance="finger"/>
          </body>
        </body>
      </body>"""
    text = plugin.mjcf(path, body="stand", name="finger")
    text = text.replace('<plugin instance="finger"/>', links)
    text = text.replace("<worldbody>", ARM + "\n  <worldbody>", 1)
    actuators = "".join(f'<position name="{j}" joint="{j}"/>'
                        for j in ("base", "shoulder", "elbow", "wrist"))
    return text.replace("</worldbody>", f"</worldbody>\n  <actuator>{actuators}</actuator>")


def targets(t):
    """The servos' targets (4,), rad, at time t, s."""
    return np.array([0.8 * np.sin(1.5 * t), 0.3 - 0.3 * np.cos(2.0 * t),
                     0.5 * np.sin(2.5 * t), -0.3 * np.sin(3.0 * t)])


def run(seconds):
    """The arm's rollout: (model, hand positions, finger tips, rigidly carried tips (k, 3),
    tracking errors (k,), wall seconds)."""
    import mujoco
    plugin.load_plugin()
    os.makedirs(scratch_path("mujoco_arm"), exist_ok=True)
    path = os.path.join(scratch_path("mujoco_arm"), "finger")
    scene = finger(path)
    model = mujoco.MjModel.from_xml_string(arm_mjcf(path))
    model.opt.timestep = DT
    data = mujoco.MjData(model)
    runtime = native.CModel(path)
    tip = af.metrics.end_vertices(scene.mesh, 0, "max")
    hand = model.body("hand").id
    header = plugin.HEADER + model.plugin_stateadr[0]
    hands, tips, rigid, errors = [], [], [], []
    t0 = time.perf_counter()
    for k in range(int(round(seconds / DT))):
        data.ctrl[:] = targets(data.time)
        mujoco.mj_step(model, data)
        R, p = data.xmat[hand].reshape(3, 3), data.xpos[hand]     # the soft state's time
        x = runtime._positions(data.plugin_state[header:header + runtime.state_size])
        hands.append(p.copy())
        tips.append(x[tip].mean(axis=0))
        rigid.append(scene.mesh.vertices[tip].mean(axis=0) @ R.T + p)
        errors.append(float(np.abs(data.qpos[:4] - targets(data.time)).max()))
    return model, np.array(hands), np.array(tips), np.array(rigid), np.array(errors), \
        time.perf_counter() - t0


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seconds", type=float, default=5.0)
    args = parser.parse_args()
    model, hands, tips, rigid, errors, wall = run(args.seconds)
    trail = np.linalg.norm(tips - rigid, axis=1)
    print(f"arm of {model.nbody - 1} bodies, {model.nu} servos, dt = {DT} s; the finger: "
          f"{LENGTH * 100:.0f} cm, framed model on the hand")
    print(f"{len(hands)} steps ({args.seconds:g} s) in {wall:.2f} s: "
          f"{args.seconds / wall:.0f}x real time, the finger included")
    print(f"the finger's tip is up to {1e3 * trail.max():.1f} mm from where the hand would carry "
          f"it rigidly (mean {1e3 * trail.mean():.1f} mm); the servos within "
          f"{np.degrees(errors[len(errors) // 5:].max()):.1f} degrees after the first second")
    fig, ax = plt.subplots(figsize=(5, 4.5))
    ax.plot(hands[:, 0], hands[:, 1], color="0.5", label="hand")
    ax.plot(rigid[:, 0], rigid[:, 1], "--", color="tab:blue", label="tip, carried rigidly")
    ax.plot(tips[:, 0], tips[:, 1], color="tab:orange", label="tip, soft")
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.legend(fontsize=8)
    out = scratch_path("mujoco_arm.png")
    fig.savefig(out, dpi=150, bbox_inches="tight")
    print(f"drew {os.path.relpath(out)}")


if __name__ == "__main__":
    main()
