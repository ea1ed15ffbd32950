"""`python -m anisofem bench --distributed [--huge]`: the petsc engine's multigrid path (CG +
smoothed aggregation, anisofem.distributed.newton.multigrid_type) on 1 and 2 MPI ranks of this
machine against the single-process multigrid path (`cg` with `preconditioner="amg"`,
anisofem.studies.bench_large) on the box cantilever of 10^5 tets (and 10^6 with --huge), each run in
its own processes: the static solve's wall time split into the partition, the assembly and the
linear solves (the slowest rank's), Newton and Krylov iterations, the mean of 5 backward-Euler
steps (dt 0.02 s, from rest), each rank's peak memory, and the answer's distance to the
single-process one. Prints a table and writes JSON (atomically). Run alone."""
import json
import os
import subprocess
import sys
import tempfile
import time

import numpy as np

from . import bench_large
from ..io.output import publish, result_path

RANKS = (1, 2)
#: mpirun's flags here: as many ranks as asked whatever the cores, and as root where CI is root
MPIRUN = ["mpirun", "--oversubscribe"] + (["--allow-run-as-root"] if os.geteuid() == 0 else [])


def case(cells, target):
    """Under mpirun: measure the cantilever of cells on the ranks; rank 0 writes the row (JSON
    at target) and the static solution (target + ".npy")."""
    from ..distributed import simulate, solve
    from ..physics.material import Material
    from ..physics.meshgen import box_beam
    from ..physics.scene import default_scene
    scene = default_scene(box_beam(cells=cells), Material(poisson=0.48))
    start = time.perf_counter()
    result = solve(scene, method="cg")
    solve_s = time.perf_counter() - start
    start = time.perf_counter()
    _, _, last = simulate(scene, bench_large.STEPS, bench_large.STEP_DT, method="cg")
    step_s = (time.perf_counter() - start) / bench_large.STEPS
    from petsc4py import PETSc
    from ..distributed.newton import multigrid_type
    if PETSc.COMM_WORLD.getRank() == 0:
        n = result.newton
        row = {"engine": "petsc " + multigrid_type(PETSc), "ranks": result.ranks,
               "tets": scene.mesh.n_tets,
               "unknowns": scene.n_free, "solve_s": solve_s,
               **{f"{k}_s": v for k, v in result.seconds.items()},
               "newton_iterations": n.iterations, "krylov_iterations": n.linear_iterations,
               "converged": n.converged and last.converged, "step_s": step_s,
               "peak_memory_gb": result.peak_memory_gb}
        np.save(target + ".npy", result.x)
        with open(target, "w") as f:
            json.dump(row, f)


def run(huge=False, out=result_path("bench_distributed.json")):
    rows = []
    sizes = {k: v for k, v in bench_large.SIZES.items() if k == "1e5" or (huge and k == "1e6")}
    for size, cells in sizes.items():
        print(f"  {size} tets, one process ...", file=sys.stderr, flush=True)
        serial, reference = bench_large._in_fresh_process(cells, "cg amg", 0.48)
        rows.append({"engine": "serial amg", "ranks": 1, "tets": serial["tets"],
                     "unknowns": serial["unknowns"], "solve_s": serial["solve_s"],
                     "newton_iterations": serial["newton_iterations"],
                     "krylov_iterations": serial["cg_iterations"],
                     "converged": serial["converged"] and serial["steps_converged"],
                     "step_s": (serial["first_step_s"] + (bench_large.STEPS - 1)
                                * serial["step_s"]) / bench_large.STEPS,
                     "peak_memory_gb": [serial["peak_memory_gb"]], "difference": 0.0})
        scale = float(np.abs(reference - bench_large._rest(cells)).max())
        for ranks in RANKS:
            print(f"  {size} tets, petsc on {ranks} ranks ...", file=sys.stderr, flush=True)
            row, x = _on_ranks(cells, ranks)
            row["difference"] = float(np.abs(x - reference).max()) / scale
            rows.append(row)
    return publish({"rows": rows}, _print, out)


def _on_ranks(cells, ranks):
    """case(cells) under mpirun on ranks: (row, static solution)."""
    with tempfile.TemporaryDirectory() as folder:
        target = os.path.join(folder, "row.json")
        subprocess.run([*MPIRUN, "-n", str(ranks), sys.executable, "-m",
                        "anisofem.studies.bench_distributed", "x".join(map(str, cells)), target],
                       check=True, capture_output=True, text=True)
        with open(target) as f:
            return json.load(f), np.load(target + ".npy")


def _print(report):
    print("The box cantilever (nu = 0.48), static solve and backward-Euler steps by multigrid "
          "CG: one process against PETSc (CG + ML or GAMG) on MPI ranks; times in s, the slowest "
          "rank's")
    print(f"{'tets':>9} {'unknowns':>9} {'engine':>10} {'ranks':>5} | {'solve':>7} "
          f"{'split':>6} {'assemb':>6} {'linear':>7} | {'Newton':>6} {'Krylov':>6} | "
          f"{'step':>6} | {'GB per rank':>12} | {'vs one':>8}")
    for r in report["rows"]:
        split, assembly, linear = (f"{r[k]:.2f}" if k in r else "-"
                                   for k in ("partition_s", "assembly_s", "linear_s"))
        memory = " ".join(f"{m:.2f}" for m in r["peak_memory_gb"])
        print(f"{r['tets']:>9,} {r['unknowns']:>9,} {r['engine']:>10} {r['ranks']:>5} | "
              f"{r['solve_s']:>7.2f} {split:>6} {assembly:>6} {linear:>7} | "
              f"{r['newton_iterations']:>6} {r['krylov_iterations']:>6} | {r['step_s']:>6.2f} | "
              f"{memory:>12} | {r['difference']:>8.1e}" + ("" if r["converged"] else
                                                          "  (not converged)"))


if __name__ == "__main__":
    case(tuple(int(c) for c in sys.argv[1].split("x")), sys.argv[2])
