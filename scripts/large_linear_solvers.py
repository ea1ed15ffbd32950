"""The sparse solvers a pip install can have, on anisofem's own Hessian (docs/fem.md, "Large
meshes"): one factorization or multigrid set-up (the second of two: the first loads libraries)
and one solve of the box cantilever's Hessian at rest, each candidate in a fresh process.

    python scripts/large_linear_solvers.py [--cells 50x20x20] [--candidates superlu amg-1e-3 ...]

Candidates: superlu (anisofem's), amg-TOL (pyamg smoothed aggregation with the rigid-body
modes as CG preconditioner, CG to TOL), cholespy and pardiso (pip install cholespy /
pypardiso first; skipped with a line when missing).
"""
import argparse
import json
import subprocess
import sys
import time

import numpy as np


def measure(cells, candidate):
    """{"candidate", "unknowns", "setup_s", "solve_s", "residual", ("cg_iterations")}."""
    import scipy.sparse as sp
    import scipy.sparse.linalg as spla

    import anisofem as af
    from anisofem.solvers import linsolve, multigrid
    from anisofem.physics.potential import Potential

    scene = af.default_scene(af.box_beam(cells=cells))
    layout = scene.layout("csr")
    x = scene.initial_positions()
    _, g, data = Potential(scene).hessian_data(x, layout, project=False)
    A = layout.matrix(data)
    b = -g.ravel()[scene.free_dofs]
    out = {"candidate": candidate, "unknowns": A.shape[0]}
    def setup():
        """The candidate's solve function (its factorization or hierarchy built)."""
        if candidate == "superlu":
            return linsolve.make("superlu", A.shape[0]).factor(layout, data.copy())
        if candidate == "cholespy":
            import cholespy
            factor = cholespy.CholeskySolverD(A.shape[0], A.indptr.astype(np.int32),
                                              A.indices.astype(np.int32), A.data.copy(),
                                              cholespy.MatrixType.CSR)

            def solve(r):
                y = np.zeros_like(r)
                factor.solve(r.copy(), y)
                return y
            return solve
        if candidate == "pardiso":
            import pypardiso
            upper = sp.triu(A, format="csr")  # mtype 2 (SPD) reads the upper triangle
            pardiso = pypardiso.PyPardisoSolver(mtype=2)
            pardiso.factorize(upper)
            return lambda r: pardiso.solve(upper, r)
        if candidate.startswith("amg-"):
            precondition = multigrid.preconditioner(
                A, multigrid.rigid_body_modes(x, scene.free_dofs))
            M = spla.LinearOperator(A.shape, matvec=precondition)

            def solve(r):
                count = [0]
                y, _ = spla.cg(A, r, rtol=float(candidate[4:]), M=M, maxiter=5000,
                               callback=lambda _: count.__setitem__(0, count[0] + 1))
                out["cg_iterations"] = count[0]
                return y
            return solve
        raise ValueError(f"candidate: unknown {candidate!r}")

    setup()  # first use loads libraries and starts threads: what a Newton solve pays once
    t0 = time.perf_counter()
    solve = setup()
    t1 = time.perf_counter()
    y = solve(b)
    out.update(setup_s=t1 - t0, solve_s=time.perf_counter() - t1,
               residual=float(np.linalg.norm(A @ y - b) / np.linalg.norm(b)))
    return out


def main():
    p = argparse.ArgumentParser(description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--cells", default="50x20x20", help="box cantilever cells (5 tets each)")
    p.add_argument("--candidates", nargs="+",
                   default=["superlu", "amg-1e-8", "amg-1e-3", "cholespy", "pardiso"])
    p.add_argument("--one", help=argparse.SUPPRESS)  # a single candidate, in this process
    args = p.parse_args()
    cells = tuple(int(c) for c in args.cells.split("x"))
    if args.one:
        print(json.dumps(measure(cells, args.one)))
        return
    print(f"{'candidate':<10} {'unknowns':>8} {'set-up s':>9} {'solve s':>8} {'CG its':>6} "
          f"{'residual':>9}")
    for candidate in args.candidates:
        done = subprocess.run([sys.executable, __file__, "--cells", args.cells, "--one",
                               candidate], capture_output=True, text=True)
        if done.returncode:
            print(f"{candidate:<10} skipped: {done.stderr.strip().splitlines()[-1]}")
            continue
        r = json.loads(done.stdout.strip().splitlines()[-1])
        print(f"{candidate:<10} {r['unknowns']:8d} {r['setup_s']:9.2f} {r['solve_s']:8.2f} "
              f"{r.get('cg_iterations', '-'):>6} {r['residual']:9.1e}")


if __name__ == "__main__":
    main()
