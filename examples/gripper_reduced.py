"""The soft gripper of gripper.py stepped by its reduced model beside the FEM: the fingers in
a basis of their vibration modes, their grip's static response and the principal directions of
the FEM's grip equilibria (snapshots), the box in its six rigid motions and three lowest modes,
the held bases' lift carried as a translation of the fingers, and the fingers' contact with
the box subspace self-contact (ipctk's pairs at x0 + U q, the collision test along the reduced
step).

    python examples/gripper_reduced.py [--seconds T]

Prints the box's height every 0.1 s in both, its height while held (from 1.0 s) and the
difference, the slip, the wall time per step of each and their ratio (each run timed alone,
one after the other), whether any reduced step intersected (ipctk's own test) or failed.
"""
import argparse
import time

import numpy as np

from gripper import DT, LIFTED, SCENE, grasp

from anisofem.io.scenefile import SceneFile
from anisofem.reduced import Loads, ReducedModel

#: The fingers' vibration modes and the principal directions of their grip's equilibria.
MODES, SNAPSHOTS = 4, 6


def reduced_grasp(seconds=2.0):
    """The gripper's reduced model (built from the scene at rest, its grip declared over the
    curve's range) stepped for `seconds` s like gripper.grasp, its controls and lift read from
    the scene's curves before the steps (a controller's inputs). Returns (the model, positions
    (k, n, 3) m after each step, every step's NewtonReport, build seconds, stepping
    seconds)."""
    read = SceneFile(SCENE)
    scene = read.scene
    rest = scene.at(0.0)
    top = max(scene.at(t).control_values[0] for t in np.arange(0.0, seconds + DT, DT))
    t0 = time.perf_counter()
    model = ReducedModel(rest, modes=MODES, snapshots=SNAPSHOTS, validate=False,
                         loads=Loads(controls={"grip": (0.0, top)}))
    built = time.perf_counter() - t0
    held = scene.fixed_mask.all(axis=1)
    steps = int(round(seconds / DT))
    controls, shifts = [], [np.zeros(3), np.zeros(3)]   # the scene's curves, step by step
    for k in range(1, steps + 1):
        now = scene.at(k * DT)
        controls.append(now.control_values)
        shifts.append((now.fixed_positions[held] - rest.fixed_positions[held]).mean(axis=0))
    q, v = np.zeros(model.r), np.zeros(model.r)
    xs, reports = [], []
    t0 = time.perf_counter()
    for k in range(steps):
        q, v, report = model.step(q, v, DT, controls=controls[k], carried=shifts[k:k + 3])
        reports.append(report)
        xs.append(model.positions(q, shifts[k + 2]))
        if not report.converged:
            break
    return model, np.array(xs), reports, built, time.perf_counter() - t0


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seconds", type=float, default=2.0)
    args = parser.parse_args()
    model, reduced, reports, built, reduced_seconds = reduced_grasp(args.seconds)
    scene, box, held, roll, fem_seconds = grasp(seconds=args.seconds)
    X = scene.mesh.vertices
    fem = np.array([s.x for s in roll.steps])
    steps = min(len(fem), len(reduced))
    up = {name: 1e3 * (x[:steps, box, 2] - X[box, 2]).mean(axis=1)
          for name, x in (("fem", fem), ("reduced", reduced))}
    print(f"reduced model: r = {model.r} ({model.fitted} fitted), built in {built:.2f} s")
    print(f"{'t (s)':>5} | {'FEM box up (mm)':>15} | {'reduced (mm)':>12} | Newton (reduced)")
    for k in range(9, steps, 10):
        print(f"{(k + 1) * DT:5.2f} | {up['fem'][k]:15.3f} | {up['reduced'][k]:12.3f} | "
              f"{reports[k].iterations:6d}")
    hold = slice(int(round(LIFTED / DT)), steps)
    heights = {name: float(h[hold].mean()) if h[hold].size else float("nan")
               for name, h in up.items()}
    difference = abs(heights["reduced"] - heights["fem"]) / heights["fem"]
    itself = model.contact.term.itself
    intersected = sum(bool(itself.ipctk.has_intersections(itself.mesh, itself.vertices(x)))
                      for x in reduced)
    fem_ms, reduced_ms = 1e3 * fem_seconds / len(fem), 1e3 * reduced_seconds / len(reduced)
    print(f"held from {LIFTED} s: the box {heights['fem']:.3f} mm up (FEM), "
          f"{heights['reduced']:.3f} mm (reduced): {100 * difference:.2f}% apart; reduced slip "
          f"{up['reduced'][hold][0] - up['reduced'][hold][-1]:.3f} mm" if hold.stop > hold.start
          else "not lifted yet")
    print(f"per step: FEM {fem_ms:.1f} ms, reduced {reduced_ms:.2f} ms "
          f"({fem_ms / reduced_ms:.1f}x); reduced steps that intersected: {intersected}, failed: "
          f"{sum(not r.converged for r in reports)}")


if __name__ == "__main__":
    main()
