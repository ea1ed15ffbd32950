"""`python -m anisofem solve ... --engine petsc` under mpirun: the scene solved over the ranks
and its result written, by every rank into an XDMF file over HDF5 where the output is .xdmf
(anisofem.distributed.output), else gathered and written by rank 0. A rank that fails prints its error and stops every
rank (MPI_Abort), so that no rank is left waiting in a collective call."""
import sys

from ..solvers import methods
from ..physics.inversion import inversion
from ..io.meshes import write_mesh
from ..physics.metrics import tip_displacement
from .output import write_xdmf


def method_of(name, n_free):
    """The distributed method for the CLI's --method name ("auto": exact Newton up to
    anisofem.solvers.methods.AUTO_MULTIGRID_MIN unknowns, CG + multigrid above, as the serial
    default)."""
    if name == "auto":
        return "newton" if n_free < methods.AUTO_MULTIGRID_MIN else "cg"
    if name not in ("newton", "cg"):
        raise ValueError(f"--method {name}: the petsc engine runs newton and cg (and auto)")
    return name


def check(args, scene):
    """The distributed method the options ask for scene; ValueError for the serial engine's
    options that the petsc engine does not take."""
    if args.iterations is not None:
        raise ValueError("--iterations: the petsc engine solves to a tolerance (--rtol)")
    if args.continuation != "auto":
        raise ValueError("--continuation: the petsc engine does not ramp the load")
    return method_of(args.method, scene.n_free)


def run(args, scene, method):
    """Solve or roll out scene by method as args say; returns the exit status (0:
    converged)."""
    from . import _petsc, simulate, solve
    PETSc = _petsc()
    comm = PETSc.COMM_WORLD
    try:
        if args.steps:
            xs, _, result = simulate(scene, args.steps, args.dt, method=method, rtol=args.rtol)
            x, said = xs[-1], f"{len(xs) - 1} steps, converged: {result.converged}"
        else:
            result = solve(scene, method=method, rtol=args.rtol)
            x, n = result.x, result.newton
            said = (f"{n.iterations} Newton iterations, {n.linear_iterations} Krylov "
                    f"iterations, converged: {n.converged}, gradient {n.gradient_norm:.3g} N "
                    f"(tolerance {n.tolerance:.3g} N)")
        if args.output.endswith(".xdmf"):
            write_xdmf(args.output, scene, result.partition, comm, x)
        if comm.getRank() == 0:
            mesh = scene.mesh
            print(f"{said} on {comm.getSize()} ranks ({method})")
            print("tip displacement (m):", tip_displacement(mesh, x).round(6))
            inv = inversion(mesh, x)
            if not inv.physical:
                print(f"not physical: {inv.inverted} of {mesh.n_tets} elements turned inside "
                      f"out (smallest det F {inv.min_volume_ratio:.3g})")
            if args.output.endswith(".xdmf"):
                print(f"-> {args.output} (written by the {comm.getSize()} ranks)")
            else:
                write_mesh(args.output, mesh, x, scene)
                print(f"-> {args.output} (gathered on rank 0)")
        return 0 if result.converged else 1
    except Exception as err:  # one rank's failure must not leave the others waiting
        if comm.getSize() == 1:
            raise
        print(f"python -m anisofem solve: error on rank {comm.getRank()}: {err}",
              file=sys.stderr, flush=True)
        comm.tompi4py().Abort(2)
