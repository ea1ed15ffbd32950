"""Directional encodings against MeshGraphNets over seeds (docs/reproduction.md): the shipped
recipe trained again with other seeds, and every model measured on the transient and on meshes
and shapes neither architecture was trained on.

    python scripts/seeds.py train [--seeds 1 2 3 4] [--jobs 2]
    python scripts/seeds.py measure [--seeds 0 1 2 3 4] [--json seeds.json]
    python scripts/seeds.py summary [--json seeds.json]
    python scripts/seeds.py compare MODEL [MODEL ...]
    python scripts/seeds.py tables [--seeds 0 1 2 3 4] [--steps 1000] [--json seed_tables.json]

train: `python -m anisognn train --config configs/shipped-NAME.toml --seed N --out
experiments/seeds/seedN-NAME` for both architectures, JOBS runs at a time, each on one thread; a run
started again resumes from its checkpoint, a finished one is skipped. Seed 0 is the shipped
pair.

measure: for each model, the tip error against anisofem's rollout at steps 10, 25, 100 and 200
over the static tip deflection (as scripts/cg_iterations.py) on every scene of SCENES, with the
shipped stepping and with CG_ITERATIONS conjugate-gradient iterations after it; prints each
architecture's mean and range over the seeds per scene and step, and in how many seeds the
directional model is the closer one, then the same over the training-size scenes and over the
others; writes JSON. Run alone, with OMP_NUM_THREADS=1. summary prints that again from the JSON.

compare: the same tip errors, with the shipped stepping, for model files (a training run's
model.pt or checkpoint.pt), each file's mean over the training-size scenes and over the others;
prints them (no JSON).

tables: the paper's Table 1 (tip error at rest over the FEM deflection), Table 2 (mean
imbalanced force) and Fig. 6 (volume change off the FEM's) from `python -m anisognn evaluate`'s
suite after STEPS steps, each architecture's mean (min-max) over the seeds and the seeds in
which the directional model is the closer; writes JSON.
"""
import argparse
import json
import math
import os
import subprocess
import sys
import time

import numpy as np

import anisofem
from anisofem import Material, Scene
from anisofem.physics import metrics
from anisofem.io.output import result_path, write_json
from anisognn import evaluate, shipped
from anisognn.model import with_galerkin
from anisognn.rollout import rollout
from anisognn.sampler import DENSITY, POISSON, YOUNG
from cg_iterations import CHECKED, STEPS, fem_reference, tip_errors

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
FOLDER = os.path.join(ROOT, "experiments", "seeds")
#: the CG iterations after the step measured besides the shipped stepping (0)
CG_ITERATIONS = 20
FIBER_40 = (math.cos(math.radians(40)), 0.0, math.sin(math.radians(40)))
#: the first scenes of scenes() whose meshes are of the training family's size
TRAINING_SIZE = 5
#: the tip error (over the static deflection) counted as close to the FEM's rollout
CLOSE = 0.05


def _held(mesh, fiber, axis=0):
    """mesh held at its minimum along axis, fibers (3,) with kappa = E, under gravity."""
    material = Material(YOUNG, POISSON, DENSITY, np.asarray(fiber) / np.linalg.norm(fiber), YOUNG)
    return Scene(mesh, material, fixed=metrics.end_vertices(mesh, axis, "min"),
                 gravity=(0.0, 0.0, -evaluate.GRAVITY))


def scenes():
    """{label: Scene}: the four Table 1 cantilevers, the 40-degree cantilever, the evaluation box
    cantilever refined 2x and 4x per direction, a 0.2 m beam, and the T and Y standing on their
    stems."""
    out = {case.label: case.scene for case in evaluate.cases()[:4]}
    box = anisofem.box_beam
    out["box, fibers at 40 deg, 200 tets"] = _held(box((0.1, 0.02, 0.02), (10, 2, 2)), FIBER_40)
    for k in (2, 4):
        out[f"box, fibers parallel to gravity, refined {k}x"] = _held(
            box((0.1, 0.02, 0.02), (5 * k, 2 * k, 2 * k)), (0, 0, 1))
    out["0.2 m box, fibers at 40 deg, 1,600 tets"] = _held(box((0.2, 0.02, 0.02), (20, 4, 4)),
                                                           FIBER_40)
    out["T, fibers at 40 deg"] = _held(anisofem.t_shape(), FIBER_40, axis=2)
    out["Y, fibers at 40 deg"] = _held(anisofem.y_shape(), FIBER_40, axis=2)
    return out


def model_path(seed, name):
    """The model of architecture name trained with seed (0: the shipped one)."""
    if seed == 0:
        return shipped.path(name)
    return os.path.join(FOLDER, f"seed{seed}-{name}", "model.pt")


def _start(seed, name):
    """Start (or resume) the training of one model in a child process, logging to its .log:
    (process, log file, out folder)."""
    out = os.path.dirname(model_path(seed, name))
    os.makedirs(out, exist_ok=True)
    log = open(out + ".log", "a")
    print(f"training seed {seed} {name} -> {out}", flush=True)
    command = [sys.executable, "-m", "anisognn", "train", "--config",
               os.path.join(ROOT, "configs", f"shipped-{name}.toml"), "--seed", str(seed),
               "--out", out, "--no-progress"]
    process = subprocess.Popen(command, cwd=ROOT, env=dict(os.environ, OMP_NUM_THREADS="1"),
                               stdout=log, stderr=subprocess.STDOUT)
    return process, log, out


def train(seeds, jobs):
    """Train the missing models of seeds, jobs at a time."""
    queue = [(s, n) for s in seeds for n in shipped.NAMES if not os.path.exists(model_path(s, n))]
    running = []
    while queue or running:
        while queue and len(running) < jobs:
            running.append(_start(*queue.pop(0)))
        time.sleep(5)
        for process, log, out in [r for r in running if r[0].poll() is not None]:
            running.remove((process, log, out))
            log.close()
            print(f"{out}: exit {process.returncode}", flush=True)


def seed_models(seeds):
    """{(seed, architecture): GraphNet} of every model of seeds."""
    return {(seed, name): shipped.model(model_path(seed, name))
            for seed in seeds for name in shipped.NAMES}


def measure(models, cg_iterations=(0, CG_ITERATIONS)):
    """Rows {scene, tets, seed, model, cg_iterations, tip_errors} for models {(seed, name):
    GraphNet} on every scene, with each count of CG iterations after the step."""
    rows = []
    for label, scene in scenes().items():
        reference, tip, deflection = fem_reference(scene)
        for (seed, name), model in models.items():
            for k in cg_iterations:
                positions = rollout(with_galerkin(model, True, None, k), scene, STEPS)
                rows.append({"scene": label, "tets": scene.mesh.n_tets, "seed": seed,
                             "model": name, "cg_iterations": k,
                             "tip_errors": tip_errors(positions, reference, tip, deflection)})
                print(f"{label[:44]:44} {seed} {name[-13:]:13} {k:3d}  " + " / ".join(
                    f"{e:.3f}" for e in rows[-1]["tip_errors"]), flush=True)
    return rows


def compare(paths):
    """Lines: each model file's mean tip error (shipped stepping, every checked step) over the
    training-size scenes and over the others."""
    rows = measure({(None, path): shipped.model(path) for path in paths}, (0,))
    labels = list(dict.fromkeys(r["scene"] for r in rows))
    lines = [f"{'model':60} {'training-size scenes':>20} {'other scenes':>12}"]
    for path in paths:
        means = [np.mean([r["tip_errors"] for r in rows if r["model"] == path
                          and r["scene"] in chosen])
                 for chosen in (labels[:TRAINING_SIZE], labels[TRAINING_SIZE:])]
        lines.append(f"{path[-60:]:60} {means[0]:>20.3f} {means[1]:>12.3f}")
    return "\n".join(lines)


def _compare(by, seeds, fmt=".3g"):
    """by {architecture: {seed: value}}: each architecture's "mean (min-max)" over seeds (in
    format fmt) and "k of n", the seeds in which the directional value is the lower."""
    cells = []
    for name in shipped.NAMES:
        v = [by[name][s] for s in seeds]
        cells.append(f"{np.mean(v):{fmt}} ({min(v):{fmt}}-{max(v):{fmt}})")
    wins = sum(by["directional"][s] < by["meshgraphnets"][s] for s in seeds)
    return cells + [f"{wins} of {len(seeds)}"]


def summary(rows):
    """Per scene, CG count and checked step: each architecture's mean (min-max) tip error over
    the seeds, and the seeds in which the directional model's is the lower."""
    lines = [f"{'scene':44} {'k':>3} {'step':>4}  {'directional':>22}  {'meshgraphnets':>22}  "
             f"directional closer"]
    keys = dict.fromkeys((r["scene"], r["cg_iterations"]) for r in rows)
    for scene, k in keys:
        by = {n: {r["seed"]: r["tip_errors"] for r in rows
                  if (r["scene"], r["cg_iterations"], r["model"]) == (scene, k, n)}
              for n in shipped.NAMES}
        seeds = sorted(set(by["directional"]) & set(by["meshgraphnets"]))
        for i, step in enumerate(CHECKED):
            cells = _compare({n: {s: e[i] for s, e in by[n].items()} for n in by}, seeds, ".3f")
            lines.append(f"{scene[:44]:44} {k:3d} {step:4d}  {cells[0]:>22}  {cells[1]:>22}  "
                         f"{cells[2]}")
    labels = list(dict.fromkeys(r["scene"] for r in rows))
    for k in dict.fromkeys(r["cg_iterations"] for r in rows):
        for group, chosen in (("training-size scenes", labels[:TRAINING_SIZE]),
                              ("other scenes", labels[TRAINING_SIZE:])):
            lines.append(_totals([r for r in rows if r["scene"] in chosen
                                  and r["cg_iterations"] == k], f"k = {k}, {group}"))
    return "\n".join(lines)


def _totals(rows, title):
    """Lines over rows (one CG count, a group of scenes): the seed, scene and step
    comparisons the directional model wins; its mean tip error over the baseline's per scene
    and step (median, range); each seed's mean over the rows, and the seeds it wins; the
    model and scene pairs within CLOSE of the deflection at every checked step."""
    error = {(r["seed"], r["model"], r["scene"], i): e for r in rows
             for i, e in enumerate(r["tip_errors"])}
    seeds = sorted({r["seed"] for r in rows})
    cells = sorted({(scene, i) for _, _, scene, i in error})
    wins = sum(error[s, "directional", c, i] < error[s, "meshgraphnets", c, i]
               for s in seeds for c, i in cells)
    ratio = [np.mean([error[s, "directional", c, i] for s in seeds])
             / np.mean([error[s, "meshgraphnets", c, i] for s in seeds]) for c, i in cells]
    per_seed = {n: [np.mean([error[s, n, c, i] for c, i in cells]) for s in seeds]
                for n in shipped.NAMES}
    seed_wins = sum(d < m for d, m in zip(*per_seed.values()))
    spans = "  ".join(f"{n} {min(v):.2f}-{max(v):.2f}" for n, v in per_seed.items())
    close = sum(max(r["tip_errors"]) <= CLOSE for r in rows)
    return (f"{title}: directional closer in {wins} of {len(seeds) * len(cells)};\n"
            f"    its mean over the baseline's {np.median(ratio):.2f} ({min(ratio):.2f}-"
            f"{max(ratio):.2f});\n"
            f"    seed means {spans}, directional lower in {seed_wins} of {len(seeds)};\n"
            f"    within {CLOSE:.0%} at every checked step: {close} of {len(rows)} models on "
            f"scenes")


#: the paper's tables: evaluate's group -> (title, the metric compared)
TABLES = {"cantilever": ("Table 1: tip error at rest over the FEM deflection", "tip_ratio"),
          "imbalance": ("Table 2: mean imbalanced force at the final state, N", "force_mean"),
          "tension": ("Fig. 6: max volume change off the FEM's, relative",
                      "volume_change_error")}


def tables(seeds, steps):
    """evaluate's suite for every model of seeds: ({"seedN-NAME": [metrics per case]}, the
    scored cases)."""
    simulators = {f"seed{seed}-{name}": evaluate.model_rollout(
        shipped.model(model_path(seed, name))) for seed in seeds for name in shipped.NAMES}
    results, suite, _ = evaluate.evaluate(simulators, steps, progress=True)
    return results, suite


def format_tables(results, suite, seeds):
    """TABLES' rows: per case, each architecture's mean (min-max) over seeds and the seeds in
    which the directional model is the closer."""
    lines = []
    for group, (title, key) in TABLES.items():
        lines += ["", title, f"{'case':52}  {'directional':>28}  {'meshgraphnets':>28}  "
                             f"directional closer"]
        for i, case in enumerate(suite):
            if case.group == group:
                cells = _compare({n: {s: results[f"seed{s}-{n}"][i].get(key, math.inf)
                                      for s in seeds} for n in shipped.NAMES}, seeds)
                lines.append(f"{case.label[:52]:52}  {cells[0]:>28}  {cells[1]:>28}  "
                             f"{cells[2]}")
    return "\n".join(lines)


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    sub = p.add_subparsers(dest="command", required=True)
    t = sub.add_parser("train")
    t.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3, 4])
    t.add_argument("--jobs", type=int, default=2)
    m = sub.add_parser("measure")
    m.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3, 4])
    m.add_argument("--json", default=result_path("seeds.json"))
    r = sub.add_parser("summary")
    r.add_argument("--json", default=result_path("seeds.json"))
    c = sub.add_parser("compare")
    c.add_argument("models", nargs="+")
    b = sub.add_parser("tables")
    b.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3, 4])
    b.add_argument("--steps", type=int, default=evaluate.STEPS)
    b.add_argument("--json", default=result_path("seed_tables.json"))
    args = p.parse_args()
    if args.command == "train":
        train(args.seeds, args.jobs)
        return
    if args.command == "summary":
        with open(args.json) as fh:
            print(summary(json.load(fh)["rows"]))
        return
    if args.command == "compare":
        print(compare(args.models))
        return
    if args.command == "tables":
        results, suite = tables(args.seeds, args.steps)
        write_json(args.json, {"steps": args.steps, "seeds": args.seeds,
                                      "results": results})
        print(format_tables(results, suite, args.seeds))
        print(f"-> {args.json}")
        return
    rows = measure(seed_models(args.seeds))
    write_json(args.json, {"steps": STEPS, "checked_steps": list(CHECKED),
                                  "rows": rows})
    print(summary(rows))
    print(f"-> {args.json}")


if __name__ == "__main__":
    main()
