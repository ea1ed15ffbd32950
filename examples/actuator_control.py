"""A pneumatic actuator whose tip follows a path in closed loop, stepped by the C runtime: every
step the controller asks the runtime for the pressure that brings the tip to its target at
equilibrium (inverse statics, af_reach), corrects the target by the tracking error it has
integrated so far, and steps the body with that pressure (af_set_controls, af_step): the loop
a soft robot's controller would run.

The actuator is examples/scenes/actuator_control.toml: the fiber-reinforced bending actuator of
actuator.toml with the pressure in its cavity a control from 0 to 20 kPa. Its reduced model
(6 modes and the directions fitted to its pressure range) is built once into
out/actuator_control.json and .bin; without a C compiler the loop runs on the numpy runtime
and says so. The tip (the mean of its end face) is asked to bend 10 mm toward its layer and
back over 2 s. Prints the tip's tracking error, the time per step of the loop, and the full
FEM's tip under the same pressures (what the body does), and draws out/actuator_control.png.

    python examples/actuator_control.py
"""
import os
import sys
import time

import matplotlib
import numpy as np

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, ".."))
import anisofem as af  # noqa: E402
from anisofem.io.output import scratch_path  # noqa: E402
from anisofem.io.scenefile import SceneFile  # noqa: E402
from anisofem.reduced import Loads, ReducedModel  # noqa: E402
from export import native  # noqa: E402
from export.writers.reduced import write  # noqa: E402

DT, DURATION = 0.02, 2.0
#: The tip's bend toward the layer (-y), m, at time t, s: down 10 mm and back.
DEPTH = 0.010
#: The integral gain on the tip's error, per s: the target is moved by it times the error
#: integrated so far.
INTEGRAL = 4.0


def bend(t):
    return DEPTH * np.sin(np.pi * t / DURATION) ** 2


def main():
    scene_file = SceneFile(os.path.join(HERE, "scenes", "actuator_control.toml"))
    scene, tip = scene_file.scene, scene_file.vertices("tip")
    model = ReducedModel(scene, modes=6, snapshots=24,
                         loads=Loads(controls=scene_file.control_ranges))
    path = scratch_path("actuator_control")
    os.makedirs(os.path.dirname(path), exist_ok=True)
    write(model, path, title="actuator_control")
    low, high = np.array([scene_file.control_ranges[n] for n in model.controls]).T
    rest = scene.mesh.vertices[tip].mean(axis=0)
    steps = int(round(DURATION / DT))
    if native.compiler() is not None:
        runtime, how = native.CReducedSimulator(path), "the C runtime"
    else:
        runtime, how = None, "numpy (no C compiler found)"
    print(f"actuator: {scene.mesh.n_tets} tets, reduced model r = {model.r}, stepped by {how}; "
          f"its validation, pressures switched on at once and off again: "
          f"{100 * model.validation.tip_error:.2g}% off the FEM (the walls' fast vibration a "
          f"sudden step excites)")
    q, w = np.zeros(model.r), np.zeros(model.r)
    integral = np.zeros(3)
    tips, pressures, seconds = [rest], [], 0.0
    for k in range(1, steps + 1):
        target = rest + [0.0, -bend(k * DT), 0.0]
        t0 = time.perf_counter()
        aim = target + INTEGRAL * integral
        if runtime is not None:
            controls, _, _, _ = runtime.reach(tip, np.full(tip.size, 1.0 / tip.size), aim,
                                              low, high)
            runtime.step(q, w, None, DT, controls=controls)
            x = runtime.positions(q)
        else:
            found = model.reach(list(tip), aim, controls=pressures[-1] if pressures else None)
            controls = found.controls
            q, w, _ = model.step(q, w, DT, controls=controls)
            x = model.positions(q)
        seconds += time.perf_counter() - t0
        now = x[tip].mean(axis=0)
        integral += (target - now) * DT
        tips.append(now)
        pressures.append(controls)
    tips, pressures = np.array(tips), np.array(pressures)
    wanted = rest + np.outer([bend(k * DT) for k in range(steps + 1)], [0.0, -1.0, 0.0])
    error = np.linalg.norm(tips - wanted, axis=1)
    print(f"tip: largest error {1e3 * error.max():.3f} mm, after the first 0.2 s "
          f"{1e3 * error[10:].max():.3f} mm (of a {1e3 * DEPTH:.0f} mm bend); "
          f"{1e3 * seconds / steps:.2f} ms per step of the loop (reach and step), "
          f"{DURATION / seconds:.0f}x real time")
    full = af.simulate(scene, steps, DT,
                       controls=lambda t: {model.controls[0]: pressures[min(
                           int(round(t / DT)) - 1, steps - 1), 0]}, warn=False)
    fem = full.positions[:, tip].mean(axis=1)
    apart = np.linalg.norm(fem - tips, axis=1).max()
    off = np.linalg.norm(fem - wanted, axis=1).max()
    print(f"full FEM under the same pressures: tip within {1e3 * apart:.3f} mm of the "
          f"runtime's, {1e3 * off:.3f} mm of the path")
    draw(tips, wanted, fem, pressures[:, 0], scratch_path("actuator_control.png"))


def draw(tips, wanted, fem, pressure, path):
    """The tip's bend against the path, and the pressure, over time."""
    t = DT * np.arange(len(tips))
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(7, 6), sharex=True)
    top.plot(t, 1e3 * (wanted[0, 1] - wanted[:, 1]), "k--", label="path")
    top.plot(t, 1e3 * (tips[0, 1] - tips[:, 1]), label="runtime, closed loop")
    top.plot(t, 1e3 * (fem[0, 1] - fem[:, 1]), ":", label="full FEM, same pressures")
    top.set_ylabel("tip bend (mm)")
    top.legend()
    bottom.plot(t[1:], 1e-3 * pressure)
    bottom.set_ylabel("pressure (kPa)")
    bottom.set_xlabel("t (s)")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    print(f"drew {os.path.relpath(path)}")


if __name__ == "__main__":
    main()
