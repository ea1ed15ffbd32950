"""Under mpirun: the static solve and STEPS backward-Euler steps of a case of cases.py over the
ranks; rank 0 saves them.

    mpirun -n 2 python run_case.py NAME METHOD STEPS OUT.npz RTOL FOLDER
"""
import sys

import numpy as np

from anisofem import distributed
from cases import scene

name, method, steps, out = sys.argv[1], sys.argv[2], int(sys.argv[3]), sys.argv[4]
rtol, folder = float(sys.argv[5]), sys.argv[6]
s = scene(name, folder)
static = distributed.solve(s, method=method, rtol=rtol)
xs, _, last = distributed.simulate(s, steps, 0.02, method=method, rtol=rtol)
from petsc4py import PETSc  # noqa: E402 (initialized by anisofem.distributed)
if PETSc.COMM_WORLD.getRank() == 0:
    np.savez(out, static=static.x, rollout=xs, converged=static.converged and last.converged,
             ranks=static.ranks)
