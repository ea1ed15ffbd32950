"""`python -m anisofem bench --large [--huge]`: static solves of the box cantilever at 10^4 and
10^5 tets (10^6 with --huge) by each large-mesh path, each in a fresh process so that its peak
memory is its own: the time to build the scene (mesh, per-element data, sparsity pattern),
the static solve, Newton and CG iterations, peak memory, the linear solver, how far the
answer is from exact Newton's (at the sizes where exact Newton runs), and the time of the
first of STEPS backward-Euler steps of the cantilever falling from rest and the mean of the
others (one method for the rollout, so the first step builds what the later ones keep:
hierarchies, factors). Prints a table, writes JSON (atomically).

`python -m anisofem bench --crossover`: the same two paths around the size where method="auto"
switches from one to the other (anisofem.solvers.methods.AUTO_MULTIGRID_MIN), at the paper's nu =
0.48 and at a nearly incompressible nu = 0.499, where multigrid needs the most CG iterations."""
import json
import os
import resource
import subprocess
import sys
import tempfile
import time

import numpy as np

from ..io.output import publish, result_path

#: cells (nx, ny, nz) of the 0.1 x 0.02 x 0.02 m box cantilever (5 tets per cell)
SIZES = {"1e4": (25, 8, 10), "1e5": (50, 20, 20), "1e6": (100, 40, 50)}
#: the paths: label -> solve options; exact Newton runs up to EXACT_MAX tets
PATHS = {"newton": {"method": "newton"}, "cg amg": {"method": "cg", "preconditioner": "amg"}}
EXACT_MAX = 100_000
#: backward-Euler steps timed per row, and their dt (s)
STEPS, STEP_DT = 5, 0.02
#: the crossover's cantilevers (cells) and Poisson ratios
CROSSOVER_SIZES = {"4,800": (20, 6, 8), "1e4": SIZES["1e4"], "19,200": (32, 10, 12)}
CROSSOVER_POISSON = (0.48, 0.499)


def measure(cells, path, poisson=0.48):
    """One static solve of the box cantilever of cells (nx, ny, nz) (the paper's material with
    Poisson's ratio poisson) by path (a key of PATHS) in this process: a dict of the
    quantities in the module docstring, and the solution (n, 3)."""
    from ..solvers import linsolve
    from ..physics.material import Material
    from ..physics.meshgen import box_beam
    from ..physics.scene import default_scene
    from ..solvers.solve import simulate, solve

    t0 = time.perf_counter()
    mesh = box_beam(cells=cells)
    scene = default_scene(mesh, Material(poisson=poisson))
    scene.layout("csr")
    build_s = time.perf_counter() - t0
    options = PATHS[path]
    t0 = time.perf_counter()
    result = solve(scene, warn=False, **options)
    solve_s = time.perf_counter() - t0
    stamps = [time.perf_counter()]
    rollout = simulate(scene, STEPS, STEP_DT, warn=False,
                       callback=lambda k, r: stamps.append(time.perf_counter()), **options)
    seconds = np.diff(stamps)
    solver = ("none (multigrid-preconditioned CG)" if options.get("preconditioner") == "amg"
              else type(linsolve.make("auto", scene.n_free)).__name__)
    row = {"path": path, "tets": mesh.n_tets, "unknowns": scene.n_free, "poisson": poisson,
           "build_s": build_s, "solve_s": solve_s, "newton_iterations": result.iterations,
           "cg_iterations": result.linear_iterations,
           "factorizations": result.factorizations, "converged": result.converged,
           "first_step_s": float(seconds[0]), "step_s": float(seconds[1:].mean()),
           "step_newton_iterations": float(np.mean(
               [r.newton.iterations for r in rollout.steps])),
           "steps_converged": rollout.converged,
           "linear_solver": solver,
           "peak_memory_gb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2 ** 20,
           "tip_sag_m": float(-(result.x - mesh.vertices)[:, 2].min())}
    return row, result.x


def run(huge=False, out=result_path("bench_large.json"), sizes=None):
    """Measure every (size, path) in its own process, compare each answer with exact
    Newton's where that ran (max vertex difference over the largest displacement), print the
    table and write JSON. sizes: {label: cells} (default SIZES, 1e6 only if huge)."""
    if sizes is None:
        sizes = {k: v for k, v in SIZES.items() if huge or k != "1e6"}
    rows = []
    for size, cells in sizes.items():
        rows += _compared(size, cells, 0.48)
    return publish({"rows": rows}, print_report, out)


def crossover(out=result_path("bench_crossover.json"), sizes=None, poissons=CROSSOVER_POISSON):
    """Both paths on each cantilever of sizes ({label: cells}, default CROSSOVER_SIZES) at
    each Poisson ratio of poissons, each in its own process; print the table (the times,
    which path "auto" takes) and write JSON."""
    rows = []
    for size, cells in (CROSSOVER_SIZES if sizes is None else sizes).items():
        for poisson in poissons:
            rows += _compared(size, cells, poisson)
    return publish({"rows": rows}, print_crossover, out)


def _compared(size, cells, poisson):
    """The rows of every path for one cantilever, each with its answer's distance to exact
    Newton's where that ran."""
    answers, rows = {}, []
    for path in PATHS:
        if path == "newton" and 5 * int(np.prod(cells)) > EXACT_MAX:
            continue
        print(f"  {size} tets, nu {poisson}, {path} ...", file=sys.stderr, flush=True)
        row, answers[path] = _in_fresh_process(cells, path, poisson)
        row["size"] = size
        rows.append(row)
    if "newton" in answers:
        ref = answers["newton"]
        scale = float(np.abs(ref - _rest(cells)).max())
        for row in rows:
            row["difference_to_newton"] = float(np.abs(answers[row["path"]] - ref).max()) / scale
    return rows


def _rest(cells):
    from ..physics.meshgen import box_beam
    return box_beam(cells=cells).vertices


def _in_fresh_process(cells, path, poisson):
    """measure(cells, path, poisson) in a new Python process: (row, solution)."""
    with tempfile.TemporaryDirectory() as folder:
        target = os.path.join(folder, "x.npy")
        done = subprocess.run([sys.executable, "-m", "anisofem.studies.bench_large",
                               "x".join(map(str, cells)), path, str(poisson), target],
                              check=True, capture_output=True, text=True)
        return json.loads(done.stdout.strip().splitlines()[-1]), np.load(target)


def print_report(report):
    print("Static solve of the box cantilever under gravity, and its first backward-Euler steps "
          f"falling from rest (dt {STEP_DT} s): the first, and the mean of the next {STEPS - 1} "
          "(with their mean Newton iterations); one process per row (2 threads)")
    print(f"{'tets':>9} {'unknowns':>9} {'path':<8} | {'build s':>7} {'solve s':>8} "
          f"{'Newton':>6} {'CG its':>6} {'peak GB':>7} | {'vs newton':>9} | {'1st step':>8} "
          f"{'step s':>6} {'Newton':>6} | linear solver")
    for r in report["rows"]:
        diff = r.get("difference_to_newton")
        print(f"{r['tets']:9,d} {r['unknowns']:9,d} {r['path']:<8} | {r['build_s']:7.1f} "
              f"{r['solve_s']:8.1f} {r['newton_iterations']:6d} {r['cg_iterations']:6d} "
              f"{r['peak_memory_gb']:7.2f} | {'-' if diff is None else f'{diff:.1e}':>9} | "
              f"{r['first_step_s']:8.1f} {r['step_s']:6.2f} {r['step_newton_iterations']:6.1f} | "
              f"{r['linear_solver']}"
              + _unconverged(r))


def print_crossover(report):
    from ..solvers.methods import choose
    print("Exact Newton against multigrid-preconditioned inexact Newton (cg amg) on the box "
          f"cantilever: static solve and backward-Euler step (mean of steps 2 to {STEPS} from "
          f"rest, dt {STEP_DT} s), s; one process per run")
    print(f"{'tets':>7} {'unknowns':>8} {'nu':>5} | {'newton static':>13} {'step':>6} | "
          f"{'cg amg static':>13} {'step':>6} | {'vs newton':>9} | auto takes")
    pairs = {}
    for r in report["rows"]:
        pairs.setdefault((r["tets"], r["poisson"]), {})[r["path"]] = r
    for (tets, poisson), pair in pairs.items():
        exact, multigrid = pair["newton"], pair["cg amg"]
        print(f"{tets:7,d} {exact['unknowns']:8,d} {poisson:5} | {exact['solve_s']:13.2f} "
              f"{exact['step_s']:6.2f} | {multigrid['solve_s']:13.2f} {multigrid['step_s']:6.2f}"
              f" | {multigrid['difference_to_newton']:9.1e} | {choose(exact['unknowns'])[0]}"
              + _unconverged(exact) + _unconverged(multigrid))


def _unconverged(row):
    return "" if row["converged"] and row["steps_converged"] else f"  {row['path']} NOT CONVERGED"


if __name__ == "__main__":
    cells, path, poisson, target = sys.argv[1:5]
    row, x = measure(tuple(int(c) for c in cells.split("x")), path, float(poisson))
    np.save(target, x)
    print(json.dumps(row))
