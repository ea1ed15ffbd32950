"""What conjugate-gradient iterations after the step buy, with the network and without it, on
the evaluation cantilevers (anisognn.evaluate's Table 1 scenes, 200 steps of 0.02 s from rest).

    python scripts/cg_iterations.py [--iterations 0 10 20 40] [--json cg_iterations.json]

For each shipped model and each count k (ModelConfig.cg_iterations), prints and writes:
- tip error against anisofem's rollout at steps 10, 25, 100 and 200, over the static tip
  deflection (the tip: vertices whose static displacement is within 1% of the largest, as in
  `python -m anisofem trade`), of the float32 model;
- the largest vertex distance between its float32 and float64 rollouts over the 200 steps,
  over the largest static displacement;
and the same tip errors for the step without a network (anisognn.rungs.
previous_acceleration_rung: the model's Galerkin passes with the previous step's acceleration
in the network's place, then the same k iterations); then a summary table of the ranges over
scenes and models. Run alone, with OMP_NUM_THREADS=1 (about 8 minutes).
"""
import argparse

import numpy as np

import anisofem
from anisofem.io.output import result_path, write_json
from anisognn import evaluate, shipped
from anisognn.model import with_galerkin
from anisognn.rollout import rollout
from anisognn.rungs import previous_acceleration_rung

STEPS = 200
CHECKED = (10, 25, 100, 200)


def fem_reference(scene):
    """(anisofem's rollout (STEPS + 1, n, 3), tip vertices (n,) bool, static tip deflection m):
    the tip is the vertices whose static displacement is within 1% of the largest."""
    static = np.linalg.norm(anisofem.solve(scene).x - scene.mesh.vertices, axis=1)
    return evaluate.fem_rollout(scene, STEPS), static >= 0.99 * static.max(), static.max()


def tip_errors(positions, reference, tip, deflection):
    """Tip errors at CHECKED steps: |mean tip displacement difference| / deflection."""
    return [float(np.linalg.norm((positions[s] - reference[s])[tip].mean(axis=0)) / deflection)
            for s in CHECKED]


def roll_rung(rung, scene, dt):
    advance = rung.make(scene, dt)
    x, v = scene.initial_positions(), np.zeros((scene.mesh.n_vertices, 3))
    out = [x]
    for _ in range(STEPS):
        x, v, _ = advance(x, v)
        out.append(x)
    return np.array(out)


def measure(iterations):
    rows = []
    for case in evaluate.cases()[:4]:
        scene = case.scene
        reference, tip, deflection = fem_reference(scene)
        for name in shipped.NAMES:
            model = shipped.pretrained(name)
            for k in iterations:
                net = with_galerkin(model, True, None, k)
                single = rollout(net, scene, STEPS)
                double = rollout(net.double(), scene, STEPS)
                alone = roll_rung(previous_acceleration_rung("", net.config.galerkin_passes, k),
                                  scene, net.config.dt)
                rows.append({"case": case.label, "model": name, "cg_iterations": k,
                             "tip_errors": tip_errors(single, reference, tip, deflection),
                             "float32_vs_float64": float(np.abs(single - double).max()
                                                         / deflection),
                             "no_network_tip_errors": tip_errors(alone, reference, tip,
                                                                 deflection)})
                print(_line(rows[-1]), flush=True)
    return rows


def _line(row):
    def errors(values):
        return " / ".join(f"{e:.3f}" for e in values)
    return (f"{row['case'][:34]:34} {row['model']:13} {row['cg_iterations']:3d}  "
            f"{errors(row['tip_errors'])}  {row['float32_vs_float64']:.1e}  "
            f"{errors(row['no_network_tip_errors'])}")


def summary(rows):
    """Markdown table: per count k, the range over scenes and models of each tip error, of the
    same without the network, and of float32 against float64 (the README's table)."""
    lines = ["| CG iterations | tip error at steps " + " / ".join(map(str, CHECKED))
             + " (both networks) | the same without the network | float32 against float64 |",
             "|---|---|---|---|"]
    for k in sorted({r["cg_iterations"] for r in rows}):
        group = [r for r in rows if r["cg_iterations"] == k]

        def spans(key):
            return " / ".join(f"{min(r[key][i] for r in group):.3f}-"
                              f"{max(r[key][i] for r in group):.3f}"
                              for i in range(len(CHECKED)))
        drift = [r["float32_vs_float64"] for r in group]
        lines.append(f"| {k} | {spans('tip_errors')} | {spans('no_network_tip_errors')} | "
                     f"{min(drift):.1e}-{max(drift):.1e} |")
    return "\n".join(lines)


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--iterations", type=int, nargs="+", default=[0, 10, 20, 40])
    p.add_argument("--json", default=result_path("cg_iterations.json"))
    args = p.parse_args()
    print(f"{'case':34} {'model':13} {'k':>3}  tip error at steps {'/'.join(map(str, CHECKED))}"
          f"  f32 vs f64  without the network")
    rows = measure(args.iterations)
    write_json(args.json, {"steps": STEPS, "checked_steps": list(CHECKED), "rows": rows})
    print(summary(rows))
    print(f"-> {args.json}")


if __name__ == "__main__":
    main()
