"""Idle ms per step of the trade's rungs with this checkout's anisofem against another commit's,
on the trade's 200- and 12,800-tet cantilevers: does a change make the idle machine slower?

    python scripts/idle_against.py ba6e593                  # both scenes, every rung
    python scripts/idle_against.py HEAD~1 --scenes 200 --rounds 5 --rungs exact "cg amg"

The other commit is checked out in a temporary git worktree. Each round times every rung in
one process per version, the versions alternating (this checkout first in odd rounds, the
other in even ones), so that a drift of the machine's speed reaches both alike; a rung's time
is the median over its steps (the first left out) and then over the rounds. Run it alone.
Writes results/idle_against.json.
"""
import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

import numpy as np

HERE = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
#: name -> (cells, steps per rollout)
SCENES = {"200": ((10, 2, 2), 20), "12800": ((40, 8, 8), 5)}


def worker(tree, scene_name, names):
    """Time the rungs of the anisofem in `tree` on one scene: {rung: ms per step}. It builds
    the trade cantilever itself (as anisofem.studies.bench_load does) from the API every version
    has: an older tree may have no bench_load to import."""
    sys.path.insert(0, tree)
    import anisofem as af
    from anisofem.studies import rungs as ladder_rungs
    cells, steps = SCENES[scene_name]
    mesh = af.box_beam((0.1, 0.02, 0.02), cells)
    fiber = (np.cos(np.radians(40)), 0.0, np.sin(np.radians(40)))
    scene = af.Scene(mesh, af.Material(1e5, 0.48, 1000.0, fiber, 1e5),
                     fixed=af.metrics.end_vertices(mesh, 0, "min"), gravity=(0, 0, -9.81))
    assert os.path.dirname(os.path.dirname(af.__file__)) == tree, af.__file__
    rungs = ladder_rungs.fem_rungs() + ladder_rungs.registered_rungs(scene, 0.02, [])
    if names:
        rungs = ladder_rungs.select_rungs(rungs, names)
    out = {}
    for rung in rungs:
        advance = rung.make(scene, 0.02 * rung.dt_factor)
        x = scene.initial_positions()
        v = np.zeros_like(x)
        seconds = []
        for _ in range(max(2, steps // rung.dt_factor)):
            t0 = time.perf_counter()
            x, v, _ = advance(x, v)
            seconds.append(time.perf_counter() - t0)
        out[rung.name] = 1e3 * float(np.median(seconds[1:])) / rung.dt_factor
    print(json.dumps(out))


def _run(tree, scene_name, names):
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    done = subprocess.run([sys.executable, __file__, "--worker", tree, scene_name, *names],
                          capture_output=True, text=True, env=env, cwd=tempfile.gettempdir())
    if done.returncode:
        sys.exit(f"worker in {tree} failed: {done.stderr[-2000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def main():
    if sys.argv[1:2] == ["--worker"]:
        return worker(sys.argv[2], sys.argv[3], sys.argv[4:])
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("rev", help="the commit to compare with")
    p.add_argument("--scenes", nargs="+", default=list(SCENES), choices=list(SCENES))
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--rungs", nargs="+", default=[], help="only these rungs (and exact)")
    p.add_argument("--json", default=os.path.join("results", "idle_against.json"))
    args = p.parse_args()
    rev = subprocess.run(["git", "rev-parse", "--short", args.rev], cwd=HERE, check=True,
                         capture_output=True, text=True).stdout.strip()
    with tempfile.TemporaryDirectory() as tmp:
        other = os.path.join(tmp, "tree")
        subprocess.run(["git", "worktree", "add", "--detach", other, rev], cwd=HERE, check=True,
                       capture_output=True)
        try:
            rows = []
            for name in args.scenes:
                times = {"this": [], rev: []}
                for k in range(args.rounds):
                    order = [("this", HERE), (rev, other)]
                    for label, tree in (order if k % 2 == 0 else order[::-1]):
                        print(f"{name} tets, round {k + 1}/{args.rounds}: {label}",
                              file=sys.stderr, flush=True)
                        times[label].append(_run(tree, name, args.rungs))
                for rung in times["this"][0]:
                    now = float(np.median([t[rung] for t in times["this"]]))
                    then = float(np.median([t[rung] for t in times[rev]]))
                    rows.append({"tets": name, "rung": rung, "this_ms": now, "other_ms": then,
                                 "ratio": now / then})
        finally:
            subprocess.run(["git", "worktree", "remove", "--force", other], cwd=HERE,
                           capture_output=True)
    print(f"idle ms per step, this checkout against {rev} (median of {args.rounds} rounds)")
    print(f"{'tets':>6} {'rung':<30} {'this':>9} {rev:>9} {'ratio':>7}")
    for r in rows:
        print(f"{r['tets']:>6} {r['rung']:<30} {r['this_ms']:9.3g} {r['other_ms']:9.3g} "
              f"{r['ratio']:7.2f}")
    from anisofem.io.output import write_json
    write_json(args.json, {"other": rev, "rounds": args.rounds, "rows": rows})
    print(f"-> {args.json}")


if __name__ == "__main__":
    main()
