"""The soft gripper stepped by the FEM and by its reduced model, each timed alone and in turn
(examples/gripper.py's grasp, examples/gripper_reduced.py's reduced_grasp: 2 s at dt = 0.01 s).

    python scripts/reduced_gripper.py [--repeats 3] [--json results/reduced_gripper.json]

Prints each run's wall time per step, the medians and their ratio, the box's height while
held (from 1.0 s) in both, and the reduced model's most Newton iterations in a step and how
often its contact pairs were found. About a minute per repeat.
"""
import argparse
import os
import statistics
import sys

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), os.pardir,
                                "examples"))
from gripper import LIFTED, DT, grasp  # noqa: E402
from gripper_reduced import reduced_grasp  # noqa: E402

from anisofem.io.output import publish, result_path  # noqa: E402

SECONDS = 2.0


def measure(repeats):
    """{runs: [(FEM ms per step, reduced ms per step)], r, build_seconds, held heights}."""
    runs, heights = [], {}
    for _ in range(repeats):
        model, reduced, reports, built, reduced_seconds = reduced_grasp(SECONDS)
        scene, box, _, roll, fem_seconds = grasp(seconds=SECONDS)
        runs.append((1e3 * fem_seconds / len(roll.steps), 1e3 * reduced_seconds / len(reports)))
        X = scene.mesh.vertices
        hold = slice(int(round(LIFTED / DT)), None)
        for name, x in (("fem", np.array([s.x for s in roll.steps])), ("reduced", reduced)):
            heights[name] = float(1e3 * (x[hold][:, box, 2] - X[box, 2]).mean())
    fem, red = (statistics.median(r[k] for r in runs) for k in (0, 1))
    return {"runs": runs, "fem_ms": fem, "reduced_ms": red, "speedup": fem / red,
            "r": model.r, "build_seconds": built, "held_mm": heights,
            "difference": abs(heights["reduced"] - heights["fem"]) / heights["fem"],
            "failed": sum(not r.converged for r in reports),
            "most_newton": max(r.iterations for r in reports),
            "pair_searches": model.contact.near.builds}


def _print(report):
    print(f"{'run':>3} | {'FEM (ms/step)':>13} | {'reduced (ms/step)':>17} | ratio")
    for k, (fem, red) in enumerate(report["runs"], 1):
        print(f"{k:3d} | {fem:13.1f} | {red:17.2f} | {fem / red:5.1f}")
    print(f"median: FEM {report['fem_ms']:.1f} ms, reduced {report['reduced_ms']:.2f} ms a "
          f"step: {report['speedup']:.1f}x (reduced model r = {report['r']}, built in "
          f"{report['build_seconds']:.2f} s)")
    held = report["held_mm"]
    print(f"box held {held['fem']:.3f} mm up (FEM), {held['reduced']:.3f} mm (reduced): "
          f"{100 * report['difference']:.2f}% apart; reduced steps failed: {report['failed']}")
    print(f"reduced (last run): at most {report['most_newton']} Newton iterations in a step; "
          f"its contact pairs found {report['pair_searches']} times")


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--json", default=result_path("reduced_gripper.json"))
    args = parser.parse_args()
    publish(measure(args.repeats), _print, args.json)


if __name__ == "__main__":
    main()
