"""anisofem's solves on PETSc across MPI ranks (`mpirun -n 4 python -m anisofem solve part.msh
--engine petsc`, or these functions under mpirun).

PETSc does what a distributed solver needs beyond the element kernels: PT-Scotch splits the
mesh, the matrix is PETSc's parallel AIJ (block size 3 where whole nodes are held), and its
KSP solves the Newton systems, MUMPS for exact Newton and CG with smoothed-aggregation
multigrid (Trilinos' ML through PETSc, else PETSc's GAMG; rigid-body modes as near-null
space) for the inexact one. anisofem contributes the element loop, the Newton
iteration's test and line search (anisofem.distributed.newton) and the split of the work
(anisofem.distributed.partition). Every rank holds the whole scene; each evaluates the elements
touching its nodes and owns their rows. Every material and element order runs.

    import anisofem as af
    from anisofem import distributed
    result = distributed.solve(scene)            # under mpirun: the same answer on every rank

Needs petsc4py and mpi4py (`make install-mpi`); without them, any call raises ImportError
saying what to install.
"""
import resource
import sys
import time
from dataclasses import dataclass, field

import numpy as np

from ..physics.potential import check_positions
from ..physics.scene import check_scene
from .newton import METHODS, RankResult, Solver, minimize
from .partition import partition
from .system import RankSystem

MISSING = ("the petsc engine needs petsc4py and mpi4py: run `make install-mpi` (Debian's PETSc "
           "3.18 and Open MPI, petsc4py built against them, mpi4py)")

__all__ = ["solve", "simulate", "available", "DistributedResult", "RankResult", "METHODS"]


def available():
    """Whether petsc4py and mpi4py are installed (found, not imported: importing them starts
    MPI in this process, after which it cannot launch mpirun)."""
    from importlib.util import find_spec
    return find_spec("petsc4py") is not None and find_spec("mpi4py") is not None


def _petsc():
    try:
        import petsc4py
        import mpi4py  # noqa: F401
    except ImportError as err:
        raise ImportError(f"{MISSING} ({err})") from None
    petsc4py.init(sys.argv[:1])
    from petsc4py import PETSc
    return PETSc


@dataclass
class DistributedResult:
    """x: (n, 3) positions in m, the same on every rank. newton: how the solve ended (or the
    last step's, for a rollout). ranks: how many took part. seconds: wall time of the split
    ("partition"), this solve's assembly and KSP ("assembly", "linear"), each the slowest
    rank's. peak_memory_gb: each rank's peak resident memory so far."""
    x: np.ndarray
    newton: RankResult
    ranks: int
    seconds: dict = field(default_factory=dict)
    peak_memory_gb: list = field(default_factory=list)
    partition: object = None  # this rank's anisofem.distributed.partition.Partition

    @property
    def converged(self):
        return self.newton.converged


def _context(scene, comm, *options):
    """(comm, this rank's Partition, seconds the split took) once every rank has checked that
    all ranks hold the same scene size and options."""
    PETSc = _petsc()
    check_scene(scene)
    if scene.pressures or scene.cables:
        raise ValueError(f"scene: the petsc engine takes nodal forces, gravity and tractions; "
                         f"this scene has {'pressure loads' if scene.pressures else 'cables'} "
                         f"(solve it with anisofem.solve)")
    if scene.contact is not None:
        raise ValueError("scene: the petsc engine does not take contact (solve it with "
                         "anisofem.solve)")
    comm = PETSc.COMM_WORLD if comm is None else comm
    _share_cores(comm)
    _agree(comm, scene, *options)
    start = time.perf_counter()
    part = partition(scene, comm)
    return comm, part, time.perf_counter() - start


def _result(system, x, info, comm, partition_seconds):
    """The DistributedResult of a minimization on every rank."""
    mpi = comm.tompi4py()
    from mpi4py import MPI
    seconds = {"partition": partition_seconds, "assembly": system.assembly_seconds,
               "linear": info.linear_seconds}
    seconds = {k: mpi.allreduce(v, op=MPI.MAX) for k, v in seconds.items()}
    memory = mpi.allgather(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2 ** 20)
    return DistributedResult(system.gather(x), info, comm.getSize(), seconds, memory,
                             system.part)


def _share_cores(comm):
    """Give each rank its share of the machine's cores for numba's threads (the ranks on one
    machine otherwise run cores x ranks threads, and a rank waiting in a collective call
    spins against the others' threads: a 2-rank solve ran 90x slower). The count is fixed
    (anisofem.threads.set_threads): the other ranks' threads are no load to step aside from."""
    import numba
    from mpi4py import MPI

    from .. import threads
    local = comm.tompi4py().Split_type(MPI.COMM_TYPE_SHARED)
    threads.set_threads(max(1, numba.config.NUMBA_NUM_THREADS // local.Get_size()))
    local.Free()


def _agree(comm, scene, *options):
    """ValueError on every rank unless every rank has the same scene size and options (a
    mismatch would otherwise hang in a collective call)."""
    mine = (scene.mesh.n_vertices, scene.mesh.n_tets, scene.n_free) + tuple(map(repr, options))
    every = comm.tompi4py().allgather(mine)
    if any(theirs != mine for theirs in every):
        raise ValueError(f"ranks disagree on the scene or options: {every}")


def solve(scene, method="newton", rtol=1e-8, atol=None, max_iter=100, comm=None):
    """Static equilibrium of scene over the ranks of comm (default PETSc.COMM_WORLD), from its
    initial positions. method: "newton" (exact, MUMPS) or "cg" (inexact, CG + multigrid); rtol,
    atol, max_iter: Newton's test as in anisofem.solve. Returns a DistributedResult."""
    comm, part, split = _context(scene, comm, method, rtol, atol, max_iter)
    system = RankSystem(scene, part, comm)
    x, info = minimize(system, scene.initial_positions(), method, rtol, atol, max_iter)
    return _result(system, x, info, comm, split)


def simulate(scene, steps, dt=0.02, x0=None, v0=None, method="newton", rtol=1e-8, atol=None,
             max_iter=100, comm=None):
    """steps backward-Euler steps of dt (s) from x0, v0 (n, 3; default rest), each solved over
    the ranks as solve does, started from the inertial predictor x + dt v. Returns
    (positions (steps + 1, n, 3), velocities (steps + 1, n, 3), the last step's
    DistributedResult), the same on every rank; stops at a step that does not converge."""
    if not dt > 0:
        raise ValueError(f"dt: the time step must be > 0 s, got {dt}")
    x = scene.initial_positions() if x0 is None else scene.with_fixed(
        check_positions(scene, x0, "x0"))
    v = np.zeros_like(x) if v0 is None else check_positions(scene, v0, "v0")
    comm, part, split = _context(scene, comm, steps, dt, method, rtol, atol, max_iter)
    xs, vs = [x], [v]
    result = None
    system = RankSystem(scene, part, comm)
    solver = Solver(system, method)  # kept from step to step, and its hierarchy with it
    try:
        for _ in range(int(steps)):
            x_hat = x + dt * v
            system.at_step(x_hat, dt)
            y, info = minimize(system, scene.with_fixed(x_hat), method, rtol, atol, max_iter,
                               x_start=x, solver=solver)
            result = _result(system, y, info, comm, split)
            if not info.converged:
                break
            v = (result.x - x) / dt
            x = result.x
            xs.append(x)
            vs.append(v)
    finally:
        solver.destroy()
    return np.stack(xs), np.stack(vs), result
