"""A soft finger driven to a target by a controller, stepped by the exported network or by the
finger's reduced model with only the runtime: the control loop a robot would run.

The finger is the 0.1 x 0.02 x 0.02 m fiber-reinforced beam of onnx_cantilever.py (fibers at
45 degrees in the x-z plane, kappa = 100 kPa), held at x = 0 and hanging under gravity. A
tendon-like force on its tip face (the external force input, along z) is set every step by a
PID controller on the mean tip height; the target steps up 3 mm above the rest height at t = 0
and down 3 mm below it at t = 2 s, and the tip must stay within 0.3 mm of it from 1 s after
each step on. Only export/runtime.py (numpy + onnxruntime) steps the
model. Prints the tip error when each target is settled and the real-time factor (simulated
over wall time), and draws the tip against the target in out/finger_control_VARIANT.png
(VARIANT: the .onnx file's name, reduced or framed).

    python examples/finger_control.py [MODEL.onnx]   (default export/models/directional.onnx)
    python examples/finger_control.py reduced        (the finger's reduced model)
    python examples/finger_control.py framed         (its framed model, export/framed_runtime.py)

The reduced model is built once with anisofem into out/finger_reduced.json and .bin, for the
load the finger declares: its actuator, a force on the tip face along +z or -z up to twice the
finger's weight (4 modes and 8 directions fitted to the full FEM's equilibria under it, r =
12); the loop steps it with numpy alone. The framed model (domains in their own rotating
frames, for fingers that bend far) is built the same way into out/finger_framed.
"""
import os
import sys
import time

import matplotlib
import numpy as np

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "export"))  # as if runtime.py were copied here
from framed_runtime import FramedSimulator  # noqa: E402
from runtime import OnnxSimulator, ReducedSimulator  # noqa: E402
from onnx_cantilever import DEFAULT_MODEL, box_tets, save  # noqa: E402

#: PID gains on the tip height error: N/m, N/(m s), N s/m
GAINS = (30.0, 300.0, 0.2)
#: target tip height above rest (m) from each switch time (s), and the run's length (s)
TARGETS = ((0.0, 0.003), (2.0, -0.003))
DURATION = 4.0
#: the tip must be within TOLERANCE (m) of the target from SETTLE (s) after each switch on
TOLERANCE, SETTLE = 3e-4, 1.0


def target_at(t):
    """The target tip height above rest (m) at time t (s)."""
    return [z for start, z in TARGETS if t >= start - 1e-12][-1]


class PID:
    """Force (N) from the tip height error, its integral and the tip velocity (derivative on
    the measurement, so a target step gives no derivative kick)."""

    def __init__(self, gains, dt):
        self.kp, self.ki, self.kd = gains
        self.dt, self.integral = dt, 0.0

    def __call__(self, error, velocity):
        self.integral += error * self.dt
        return self.kp * error + self.ki * self.integral - self.kd * velocity


#: the finger's material: density kg/m^3, fiber direction (normalized by the runtime), Pa
DENSITY, FIBER, KAPPA = 1000.0, (1.0, 0.0, 1.0), 1e5
DT = 0.02


class Network:
    """The finger stepped by an exported network: step(external (n, 3) N) -> (x, v)."""

    def __init__(self, model, vertices, tets):
        self.sim = OnnxSimulator(model, vertices, tets, fixed=vertices[:, 0] < 1e-9,
                                 density=DENSITY, fiber_direction=FIBER, fiber_stiffness=KAPPA)
        self.masses, self.dt, self.label = self.sim.masses, self.sim.dt, "network"
        self.x, self.v = self.sim.rest_positions, np.zeros_like(self.sim.rest_positions)

    def step(self, external):
        self.x, self.v = self.sim.step(self.x, self.v, external)
        return self.x, self.v


class Reduced:
    """The finger stepped by its reduced model (built on first use): the same interface."""

    def __init__(self, vertices, tets):
        path = os.path.join("out", "finger_reduced")
        if not os.path.exists(path + ".json"):
            build_reduced(path, vertices, tets)
        self.sim = ReducedSimulator(path, vertices, tets)
        self.masses, self.dt, self.label = self.sim.masses, DT, "reduced model"
        self.q, self.w = self.sim.rest_state()
        self.x = self.sim.positions(self.q)

    def step(self, external):
        self.q, self.w = self.sim.step(self.q, self.w, external, self.dt)
        x = self.sim.positions(self.q)
        v, self.x = (x - self.x) / self.dt, x
        return x, v


class Framed:
    """The finger stepped by its framed model (built on first use): the same interface."""

    def __init__(self, vertices, tets):
        path = os.path.join("out", "finger_framed")
        if not os.path.exists(path + ".json"):
            build_reduced(path, vertices, tets, framed=True)
        self.sim = FramedSimulator(path, vertices, tets)
        self.masses, self.dt, self.label = self.sim.masses, DT, "framed model"
        self.now = self.before = self.sim.rest_state()
        self.x = self.sim.positions(self.now)

    def step(self, external):
        self.now, self.before = self.sim.step(self.now, self.before, external, self.dt), self.now
        x = self.sim.positions(self.now)
        v, self.x = (x - self.x) / self.dt, x
        return x, v


def build_reduced(path, vertices, tets, framed=False):
    """The finger's reduced model (framed: its FramedModel) written to path (.json, .bin): the
    one step that needs the library (anisofem) rather than the runtime."""
    import anisofem as af
    from anisofem.reduced import Drag, FramedModel, Loads, ReducedModel
    from export.writers.reduced import write, write_framed
    material = af.Material(1e5, 0.48, DENSITY, np.array(FIBER) / np.linalg.norm(FIBER), KAPPA)
    scene = af.Scene(af.TetMesh(vertices, tets), material,
                     fixed=np.flatnonzero(vertices[:, 0] < 1e-9), gravity=(0.0, 0.0, -9.81))
    tip = np.flatnonzero(vertices[:, 0] > 0.1 - 1e-9)
    actuator = Drag(tip, 2 * scene.masses.sum() * 9.81, directions=[(0, 0, 1), (0, 0, -1)])
    os.makedirs(os.path.dirname(path), exist_ok=True)
    if framed:
        write_framed(FramedModel(scene, loads=Loads((actuator,))), path)
    else:
        write(ReducedModel(scene, modes=4, snapshots=8, loads=Loads((actuator,))), path)


def main(which):
    vertices, tets = box_tets((0.1, 0.02, 0.02), (10, 2, 2))
    stepper = {"reduced": Reduced, "framed": Framed}.get(which)
    sim = stepper(vertices, tets) if stepper else Network(which, vertices, tets)
    gravity = sim.masses[:, None] * np.array([0.0, 0.0, -9.81])  # N per vertex
    tip = vertices[:, 0] > 0.1 - 1e-9
    share = np.where(tip, sim.masses, 0.0) / sim.masses[tip].sum()  # the tip force's split
    rest_height = vertices[tip, 2].mean()
    controller = PID(GAINS, sim.dt)
    steps = int(round(DURATION / sim.dt))
    x, v = sim.x, np.zeros_like(sim.x)
    times, heights, targets, forces = [], [], [], []
    wall = 0.0
    for k in range(steps):
        t = k * sim.dt
        height = x[tip, 2].mean() - rest_height
        force = controller(target_at(t) - height, v[tip, 2].mean())
        external = gravity.copy()
        external[:, 2] += force * share
        start = time.perf_counter()
        x, v = sim.step(external)
        wall += time.perf_counter() - start
        times.append(t + sim.dt)
        heights.append(x[tip, 2].mean() - rest_height)
        targets.append(target_at(t))
        forces.append(force)
    times, heights, targets = np.array(times), np.array(heights), np.array(targets)
    for start, z in TARGETS:
        settled = (times >= start + SETTLE) & (targets == z)
        error = np.abs(heights[settled] - z).max()
        print(f"target {1e3 * z:+.1f} mm from t = {start:g} s: largest tip error from "
              f"{start + SETTLE:g} s on {1e3 * error:.3f} mm (tolerance "
              f"{1e3 * TOLERANCE:.2f} mm): {'reached' if error <= TOLERANCE else 'missed'}")
    print(f"{steps} steps of {sim.dt} s in {wall:.2f} s of stepping: real-time factor "
          f"{steps * sim.dt / wall:.1f}")

    fig, (ax, bx) = plt.subplots(2, 1, figsize=(7, 5), sharex=True)
    ax.step(times, 1e3 * targets, where="post", color="0.5", label="target")
    ax.plot(times, 1e3 * heights, color="tab:blue", label=f"tip ({sim.label})")
    ax.set(ylabel="tip height above rest (mm)", title=f"Soft finger under PID control, stepped "
           f"by the {sim.label} (runtime only)")
    ax.legend(loc="lower left")
    bx.plot(times, 1e3 * np.array(forces), color="tab:red")
    bx.set(xlabel="t (s)", ylabel="tip force (mN)")
    variant = which if stepper else os.path.splitext(os.path.basename(which))[0]
    save(fig, f"finger_control_{variant}.png")


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else DEFAULT_MODEL)
