"""What the MuJoCo plugin costs over the C runtime alone: a model file stepped by mj_step (the
plugin "anisofem.soft" on a body) and by the C runtime's af_step (through ctypes, as the
tests call it), the same steps, controls and gravity, each timed alone in turn.

    python scripts/mujoco_plugin_cost.py [--steps 2000] [--json results/mujoco_plugin_cost.json]

Cases: the pneumatic finger of tests/test_controls.py (reduced, r = 35, on a fixed body, its
three controls on curves through plugin actuators) and the 0.1 m beam's framed model on a
hinge spun at 2 rad/s (the body moves: the soft body pulls it). Prints microseconds per step
(medians of 5 runs) and the plugin's over the runtime's.
"""
import argparse
import os
import statistics
import sys
import tempfile
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, os.pardir, "tests"))

import anisofem as af  # noqa: E402
from anisofem.io.output import publish, result_path  # noqa: E402
from anisofem.reduced import FramedModel, ReducedModel  # noqa: E402
from export import mujoco as plugin, native  # noqa: E402
from export.writers import reduced as writer  # noqa: E402
from test_controls import controls_at, finger  # noqa: E402

RUNS = 5
DT = 0.01


def cases(folder):
    """{name: (file, MJCF, per-step controls or None, base (k -> (3, 4)) or None)}."""
    finger_file = os.path.join(folder, "finger")
    writer.write(ReducedModel(finger(), modes=4, validate=False), finger_file)
    actuators = "".join(f'<plugin name="{name}" instance="soft" site="here"/>'
                        for name in ("push", "curl", "squeeze"))
    finger_xml = plugin.mjcf(finger_file).replace(
        '<plugin instance="soft"/>', '<site name="here"/><plugin instance="soft"/>').replace(
        "</worldbody>", f"</worldbody><actuator>{actuators}</actuator>")
    mesh = af.box_beam(size=(0.1, 0.02, 0.02), cells=(8, 2, 2))
    scene = af.Scene(mesh, af.Material(1e5, 0.45, 1000.0),
                     fixed=af.metrics.end_vertices(mesh, 0, "min"), gravity=(0, 0, -9.81))
    beam_file = os.path.join(folder, "beam")
    writer.write_framed(FramedModel(scene, validate=False), beam_file)
    beam_xml = plugin.mjcf(beam_file).replace(
        '<plugin instance="soft"/>', '<joint name="spin" type="hinge" axis="0 0 1"/>'
        '<geom type="box" size="0.01 0.01 0.01" mass="0.5"/><plugin instance="soft"/>')
    return {"finger (reduced, fixed, 3 controls)": (finger_file, finger_xml, True),
            "beam (framed, on a spun hinge)": (beam_file, beam_xml, False)}


def time_mujoco(xml, controlled, steps):
    """Microseconds per mj_step, and the bases the body took (3, 4) per soft step."""
    import mujoco
    model = mujoco.MjModel.from_xml_string(xml)
    model.opt.timestep = DT
    data = mujoco.MjData(model)
    if not controlled:
        data.qvel[0] = 2.0
    body = model.body("soft").id
    schedule = [controls_at(k) for k in range(steps + 1)] if controlled else None
    bases = []
    t0 = time.perf_counter()
    for k in range(steps + 1):
        if controlled:
            data.ctrl[:] = schedule[k]
        mujoco.mj_step(model, data)
        bases.append(np.column_stack([data.xmat[body].reshape(3, 3), data.xpos[body]]))
    seconds = time.perf_counter() - t0
    return 1e6 * seconds / (steps + 1), bases


def time_runtime(path, controlled, bases, gravity, steps):
    """Microseconds per af_step of the same steps (the bases MuJoCo's body took)."""
    c = native.CModel(path)
    state = np.zeros(c.state_size)
    c._c.af_rest_state(c._handle, native._pointer(state))
    c.set_constant_force(c.masses[:, None] * gravity)
    schedule = [controls_at(k) for k in range(steps + 1)] if controlled else None
    moving = c.kind == native.FRAMED
    t0 = time.perf_counter()
    for k in range(1, steps + 1):
        if controlled:
            c.set_controls(schedule[k])
        c.advance(state, None, DT, bases[k - 1] if moving else None)
    return 1e6 * (time.perf_counter() - t0) / steps


def measure(steps):
    import mujoco
    plugin.load_plugin()
    rows = {}
    with tempfile.TemporaryDirectory() as folder:
        for name, (path, xml, controlled) in cases(folder).items():
            gravity = mujoco.MjModel.from_xml_string(xml).opt.gravity.copy()
            inside, alone = [], []
            for _ in range(RUNS):
                micro, bases = time_mujoco(xml, controlled, steps)
                inside.append(micro)
                alone.append(time_runtime(path, controlled, bases, gravity, steps))
            rows[name] = {"plugin_us": statistics.median(inside),
                          "runtime_us": statistics.median(alone),
                          "runs": list(zip(inside, alone))}
            rows[name]["ratio"] = rows[name]["plugin_us"] / rows[name]["runtime_us"]
    return {"steps": steps, "dt": DT, "cases": rows}


def _print(report):
    print(f"{'case':<36} | {'mj_step (us)':>12} | {'af_step (us)':>12} | plugin / runtime")
    for name, row in report["cases"].items():
        print(f"{name:<36} | {row['plugin_us']:12.1f} | {row['runtime_us']:12.1f} | "
              f"{row['ratio']:.3f}")


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--steps", type=int, default=2000)
    parser.add_argument("--json", default=result_path("mujoco_plugin_cost.json"))
    args = parser.parse_args()
    publish(measure(args.steps), _print, args.json)


if __name__ == "__main__":
    main()
