"""`python -m anisofem bench`: assembly and solve speed of the numba kernels against the plain
numpy implementation (anisofem.physics.reference_numpy), measured in the same run, and the linear
solvers at the largest size. Prints tables and writes JSON (atomically)."""
import functools
import subprocess
import sys
import time

import numba
import numpy as np

from ..solvers import linsolve
from ..physics import reference_numpy
from ..io.output import publish, result_path
from ..physics.material import MODELS, Material
from ..physics.meshgen import box_beam
from ..solvers.newton import minimize
from ..physics.potential import Potential
from ..physics.scene import Scene, default_scene
from ..solvers.solve import simulate, solve, step
from .timing import best_time

#: cells (nx, ny, nz) of box beams of about 10^2, 10^3, 10^4 and 10^5 tets (5 per cell)
SIZES = {"1e2": (5, 2, 2), "1e3": (10, 4, 5), "1e4": (25, 8, 10), "1e5": (50, 20, 20)}


def bench_assembly(scene, x):
    """Gradient + projected Hessian (free DOFs, CSR): numba vs numpy, seconds."""
    pot = Potential(scene)
    layout = scene.layout("csr")
    numba_s = best_time(lambda: pot.hessian_data(x, layout, project=True), 20)

    def numpy_version():
        reference_numpy.elastic_energy_gradient(scene, x)
        reference_numpy.elastic_hessian(scene, x, project=True)
    numpy_s = best_time(numpy_version, 5, budget=20.0)
    return numba_s, numpy_s


def bench_size(label, cells, with_numpy_solve):
    mesh = box_beam(cells=cells)
    scene = default_scene(mesh)
    solve(scene, method="newton", max_iter=1, warn=False)  # compile and build the patterns
    x = scene.initial_positions() + 1e-4 * np.sin(mesh.vertices * 200)
    numba_s, numpy_s = bench_assembly(scene, x)
    results = []
    solve_s = best_time(lambda: results.append(solve(scene, method="newton")), 20, budget=10.0)
    res = results[-1]
    row = {"size": label, "tets": mesh.n_tets, "unknowns": scene.n_free,
           "assembly_numba_s": numba_s, "assembly_numpy_s": numpy_s,
           "assembly_speedup": numpy_s / numba_s, "elements_per_s": mesh.n_tets / numba_s,
           "solve_s": solve_s, "newton_iterations": res.iterations,
           "converged": res.converged, "linear_solver": type(linsolve.make(
               "auto", scene.n_free)).__name__}
    if with_numpy_solve:
        x0 = scene.initial_positions()
        refs = []
        numpy_solve_s = best_time(
            lambda: refs.append(minimize(reference_numpy.NumpyPotential(scene), x0)), 5,
            budget=10.0)
        row.update(solve_numpy_s=numpy_solve_s, newton_iterations_numpy=refs[-1].iterations)
    return row


def bench_materials(cells=SIZES["1e4"], rounds=10):
    """Each base model (anisofem.physics.material.MODELS) on the box cantilever with fibers along it
    (kappa = E) under gravity: gradient, true Hessian and projected Hessian assembly (free
    DOFs, CSR) at a rippled rest state (strains ~2%) and at the bent static equilibrium, and
    the static solve; least seconds over `rounds` rounds in which the models take turns, so
    both see the same machine load."""
    mesh = box_beam(cells=cells)
    fixed = np.flatnonzero(mesh.vertices[:, 0] <= 1e-9)
    scenes = {name: Scene(mesh, Material(fiber_stiffness=1e5, model=name), fixed=fixed,
                          gravity=(0.0, 0.0, -9.81)) for name in MODELS}
    rows, work = {}, {}
    for name, scene in scenes.items():
        solve(scene, method="newton", max_iter=1, warn=False)  # compile and build the patterns
        bent = solve(scene, method="newton")
        rows[name] = {"tets": mesh.n_tets, "solve_iterations": bent.iterations,
                      "converged": bent.converged}
        pot, layout = Potential(scene), scene.layout("csr")
        states = {"rippled": scene.initial_positions() + 1e-4 * np.sin(mesh.vertices * 200),
                  "bent": bent.x}
        for state, x in states.items():
            work[name, f"gradient_{state}_s"] = functools.partial(pot.energy_gradient, x)
            work[name, f"hessian_{state}_s"] = functools.partial(pot.hessian_data, x, layout)
            work[name, f"projected_{state}_s"] = functools.partial(pot.hessian_data, x, layout,
                                                                   project=True)
        work[name, "solve_s"] = functools.partial(solve, scene, method="newton")
    for _ in range(rounds):
        for (name, key), fn in work.items():
            once = best_time(fn, 1 if key == "solve_s" else 5)
            rows[name][key] = min(rows[name].get(key, np.inf), once)
    return rows


def bench_small_dynamics(cells=(5, 2, 2), steps=100, dt=0.02, repeats=5,
                         solvers=("banded", "dense")):
    """Backward Euler on the 100-tet cantilever, steps of dt s: the states of a rollout from rest
    are recorded, then each step is timed `repeats` times per linear solver (interleaved, so
    both see the same machine load) and its least time kept. Seconds: the median and least
    over steps per solver, and the first step from rest (least, default solver)."""
    scene = default_scene(box_beam(cells=cells))
    roll = simulate(scene, steps, dt, method="newton")
    xs, vs = roll.positions, roll.velocities
    guesses = [None] + [(vs[k] - vs[k - 1]) / dt for k in range(1, steps)]  # as simulate
    best = {name: np.full(steps, np.inf) for name in solvers}
    for _ in range(repeats):
        for name, times in best.items():
            for k in range(steps):
                t0 = time.perf_counter()
                step(scene, xs[k], vs[k], dt, guesses[k], method="newton", linear_solver=name)
                times[k] = min(times[k], time.perf_counter() - t0)
    x = scene.initial_positions()
    first_s = best_time(lambda: step(scene, x, np.zeros_like(x), dt, method="newton"), 20)
    iters = np.mean([s.newton.iterations for s in roll.steps])
    return {"steps": steps, "dt": dt, "newton_per_step": iters, "step_from_rest_s": first_s,
            "step_median_s": {k: float(np.median(t)) for k, t in best.items()},
            "step_min_s": {k: float(np.min(t)) for k, t in best.items()}}


def bench_linear_solvers(cells, colamd=True):
    """One factorization of the projected cantilever Hessian per sparse solver, seconds.
    colamd=False leaves out scipy's default ordering (minutes at 10^5 tets)."""
    scene = default_scene(box_beam(cells=cells))
    layout = scene.layout("csr")
    _, _, data = Potential(scene).hessian_data(scene.initial_positions(), layout, True)
    out = {}
    names = (["superlu"] + (["superlu-colamd"] if colamd else [])
             + (["cholmod"] if linsolve.cholmod_available() else []))
    for name in names:
        solver = linsolve.make(name, scene.n_free)
        out[name] = best_time(lambda: solver.factor(layout, data.copy()), 2, budget=60.0)
    return out


def bench_small_factorizations(cells=(5, 2, 2)):
    """One Cholesky factorization of the 100-tet cantilever's Hessian, seconds: dense with the
    default number of BLAS threads, dense with one thread (what dense Newton solves use), and
    banded (reverse Cuthill-McKee order)."""
    scene = default_scene(box_beam(cells=cells))
    pot, x = Potential(scene), scene.initial_positions()
    dense, banded = linsolve.DenseCholesky(), linsolve.BandedCholesky()

    def factor_time(solver):
        layout = scene.layout(solver.layout)
        _, _, data = pot.hessian_data(x, layout, want_grad=False)
        return best_time(lambda: solver.factor(layout, data.copy()), 200)
    default_s = factor_time(dense)
    with dense.threads():
        one_s = factor_time(dense)
    return {"unknowns": scene.n_free, "subdiagonals": scene.layout("banded").kd,
            "dense_default_threads_s": default_s, "dense_one_thread_s": one_s,
            "banded_s": factor_time(banded)}


def first_solve_in_new_process():
    """Wall time of a new Python process that imports anisofem and solves the 100-tet
    cantilever (numba cache warm after this run), seconds."""
    code = ("import anisofem as af; "
            "r = af.solve(af.default_scene(af.box_beam(cells=(5, 2, 2)))); assert r.converged")
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-c", code], check=True)
    return time.perf_counter() - t0


def run(sizes=tuple(SIZES), out=result_path("bench_anisofem.json")):
    # the base materials first: after the 10^5-tet runs the same 10^4-tet kernels measured
    # up to 1.5x slower and their ratio less steady
    materials = bench_materials()
    rows = []
    for label in sizes:
        rows.append(bench_size(label, SIZES[label], with_numpy_solve=label != "1e5"))
        print(f"  measured {label} ...", file=sys.stderr, flush=True)
    factorization = {label: bench_linear_solvers(SIZES[label], colamd=label != "1e5")
                     for label in sizes if label in ("1e4", "1e5")}
    report = {"assembly_and_static_solve": rows, "dynamics_100_tets": bench_small_dynamics(),
              "first_solve_new_process_s": first_solve_in_new_process(),
              "small_factorization": bench_small_factorizations(),
              "factorization_s": factorization, "materials_1e4": materials,
              "threads": numba.get_num_threads()}
    return publish(report, print_report, out)


def print_report(r):
    print(f"Gradient + projected Hessian assembly and static cantilever solve "
          f"({r['threads']} threads)")
    print(f"{'tets':>7} {'unknowns':>8} | {'numba ms':>9} {'numpy ms':>9} {'speedup':>7} "
          f"{'Melem/s':>7} | {'solve ms':>9} {'its':>3} {'numpy solve ms':>14} {'its':>3}")
    for row in r["assembly_and_static_solve"]:
        npy = (f"{1e3 * row['solve_numpy_s']:14.1f} {row['newton_iterations_numpy']:3d}"
               if "solve_numpy_s" in row else f"{'-':>14} {'-':>3}")
        print(f"{row['tets']:7d} {row['unknowns']:8d} | {1e3 * row['assembly_numba_s']:9.2f} "
              f"{1e3 * row['assembly_numpy_s']:9.2f} {row['assembly_speedup']:7.1f} "
              f"{row['elements_per_s'] / 1e6:7.2f} | {1e3 * row['solve_s']:9.1f} "
              f"{row['newton_iterations']:3d} {npy}")
    d = r["dynamics_100_tets"]
    print(f"\nBackward Euler, 100-tet cantilever, dt = {d['dt']:g} s, {d['steps']} steps from rest "
          f"({d['newton_per_step']:.1f} Newton iterations per step), each step's least time:")
    for name, median in d["step_median_s"].items():
        print(f"  {name:7} linear solver: {1e3 * median:.2f} ms per step (median; least "
              f"{1e3 * d['step_min_s'][name]:.2f} ms)")
    print(f"  first step from rest: {1e3 * d['step_from_rest_s']:.2f} ms")
    print(f"New process to first solve (numba cache warm): "
          f"{r['first_solve_new_process_s']:.2f} s")
    b = r["small_factorization"]
    print(f"Cholesky, {b['unknowns']} unknowns: dense {1e6 * b['dense_default_threads_s']:.0f} us "
          f"with the default BLAS threads, {1e6 * b['dense_one_thread_s']:.0f} us with one; "
          f"banded ({b['subdiagonals']} subdiagonals) {1e6 * b['banded_s']:.0f} us")
    for label, times in r["factorization_s"].items():
        print(f"One factorization at {label} tets: " + ", ".join(
            f"{k} {v:.2f} s" for k, v in times.items()))
    print_materials(r["materials_1e4"])


def print_materials(rows):
    """The table of bench_materials: ms, and in brackets the ratio to the first model."""
    first = next(iter(rows.values()))
    print(f"\nBase materials, {first['tets']} tets, fibers along the cantilever (kappa = E), "
          f"ms (x the first row):")
    keys = [f"{q}_{state}_s" for state in ("rippled", "bent")
            for q in ("gradient", "hessian", "projected")]
    heads = [f"{q} {state}" for state in ("rippled", "bent")
             for q in ("gradient", "true H", "proj. H")]
    print(f"{'model':<11}" + "".join(f"{h:>17}" for h in heads) + f"{'static solve':>19}")
    for name, row in rows.items():
        cells = [f"{1e3 * row[k]:8.2f} ({row[k] / first[k]:4.2f}x)" for k in keys + ["solve_s"]]
        print(f"{name:<11}" + "".join(f"{c:>17}" for c in cells[:-1])
              + f"{cells[-1]:>14} {row['solve_iterations']:2d} its")
