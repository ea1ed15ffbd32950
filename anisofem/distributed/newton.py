"""Newton's method over MPI ranks: the serial loop's test and line search (anisofem.solvers.newton),
with energies and norms summed over ranks and the linear systems solved by PETSc's KSP.

method "newton": exact Newton. The true Hessian is factored by MUMPS (Cholesky, LDL^T); it is
used when its inertia shows it positive definite and its step makes progress, else the
PSD-projected Hessian is (the serial "adaptive" choice). method "cg": inexact Newton, conjugate
gradients preconditioned by smoothed-aggregation multigrid (multigrid_type: Trilinos' ML
through PETSc where PETSc has it, else PETSc's GAMG) with the rigid-body modes as near-null
space, stopped at the serial method's forcing tolerance; the hierarchy of an earlier Hessian is
kept while CG converges with it in at most RENEW_AFTER iterations (a set-up, its Galerkin
products above all, costs several CG solves) and applied in each vertex's frame turned since
it was built, as the serial "amg" method does (anisofem.solvers.frames); a direction of negative
curvature of the true Hessian sends the iteration to the projected one.
"""
import math
import time
from dataclasses import dataclass

from ..solvers.frames import VertexFrames
from ..solvers.methods import forcing_tolerance
from ..solvers.newton import ARMIJO, ENERGY_NOISE, MIN_STEP, NOISE_PROGRESS

METHODS = ("newton", "cg")
#: "cg" keeps the multigrid hierarchy of an earlier Hessian (as the serial "amg" method does)
#: and renews it after a solve that needed more CG iterations than this with it
RENEW_AFTER = 60
#: MUMPS's controls for the inertia of its LDL^T factor (MatGetInertia): null pivots detected
#: (ICNTL 24), and the root front factored on one rank rather than by ScaLAPACK (ICNTL 13),
#: whose pivots MUMPS cannot count
MUMPS_OPTIONS = {"mat_mumps_icntl_24": 1, "mat_mumps_icntl_13": 1}


def multigrid_type(PETSc):
    """The "cg" method's preconditioner: "ml" (Trilinos' smoothed aggregation) where PETSc was
    built with ML, else "gamg" (PETSc's own). ML aggregates as anisofem's serial multigrid does;
    GAMG's MIS aggregation makes aggregates of about 4 nodes on the 5-tet split of a box and
    coarse operators with 8.5 times the fine matrix's nonzeros (docs/experiments.md). Another
    preconditioner: the PETSc option -anisofem_pc_type."""
    return "ml" if PETSc.Sys.hasExternalPackage("ml") else "gamg"


@dataclass
class RankResult:
    """How a distributed minimization ended (the same on every rank)."""
    converged: bool
    iterations: int
    linear_iterations: int
    gradient_norm: float    # N, over the free DOFs
    tolerance: float        # N
    message: str
    linear_seconds: float   # this rank's wall time in PETSc's KSP (set-up and solves), s


def minimize(system, x0, method="newton", rtol=1e-8, atol=None, max_iter=100, x_start=None,
             solver=None):
    """Minimize system's G from positions x0 (n, 3); returns (x, RankResult) with x up to date
    at the nodes this rank reads (RankSystem.gather for all of them). Converged: the gradient
    norm over free DOFs at most max(rtol * force scale, atol), the force scale taken at
    x_start (default x0), atol default Scene.gradient_roundoff. solver: a Solver(system,
    method) kept from an earlier minimization of the same system (a rollout's steps keep its
    multigrid hierarchy), which the caller then destroys; default a new one, destroyed here."""
    if method not in METHODS:
        raise ValueError(f"method: expected one of {METHODS}, got {method!r}")
    atol = system.scene.gradient_roundoff if atol is None else float(atol)
    tolerance = float(max(rtol * system.force_scale(x0 if x_start is None else x_start), atol))
    own = solver is None
    solver = Solver(system, method) if own else solver
    solver.restart()
    seconds = solver.seconds
    x = x0
    energy, g = system.energy_gradient(x)
    gnorm = g.norm()
    iterations = linear = 0
    message = "converged"
    try:
        while gnorm > tolerance:
            if iterations == max_iter:
                message = f"no convergence in {max_iter} iterations"
                break
            iterations += 1
            step = None
            for project in (False, True):
                p, its = solver.direction(x, g, gnorm, tolerance, project)
                linear += its
                if p is None:
                    continue
                step = _line_search(system, x, energy, g, gnorm, p)
                if step is not None:
                    break
            if step is None:
                message = (f"no step made progress along either Hessian's direction (PETSc's "
                           f"last KSP reason: {solver.reason})")
                break
            x, energy, g_new, gnorm_new, t = step
            solver.accepted(g, g_new, gnorm, t)
            g, gnorm = g_new, gnorm_new
    finally:
        if own:
            solver.destroy()
    converged = bool(gnorm <= tolerance)
    return x, RankResult(converged, iterations, linear, gnorm, tolerance,
                         "converged" if converged else message, solver.seconds - seconds)


class Solver:
    """PETSc's KSP for one method on one RankSystem, the "cg" method's kept multigrid
    hierarchy and its forcing tolerance."""

    def __init__(self, system, method):
        from petsc4py import PETSc
        self.PETSc, self.system, self.method = PETSc, system, method
        self.ksp = PETSc.KSP().create(comm=system.comm)
        self.ksp.setOptionsPrefix("anisofem_")
        if method == "newton":
            options = PETSc.Options()
            for name, value in MUMPS_OPTIONS.items():
                if not options.hasName("anisofem_" + name):
                    options["anisofem_" + name] = value
            self.ksp.setType("preonly")
            pc = self.ksp.getPC()
            pc.setType("cholesky")
            pc.setFactorSolverType("mumps")
        else:
            self.ksp.setType("cg")
            self.ksp.setNormType(PETSc.KSP.NormType.UNPRECONDITIONED)
            # the multigrid takes the options -anisofem_pc_*; the KSP's own PC turns it
            self.multigrid = PETSc.PC().create(comm=system.comm)
            self.multigrid.setOptionsPrefix("anisofem_")
            self.multigrid.setType(multigrid_type(PETSc))
            self.multigrid.setFromOptions()  # ML takes its defaults here: needed
            pc = self.ksp.getPC()
            pc.setOptionsPrefix("anisofem_turned_")
            pc.setType("python")
            self._turned = _Turned()
            pc.setPythonContext(self._turned)
            self._frames = VertexFrames(system.scene.mesh, system.owned_flat)
            self._built = self._kept = None
            #: the V-cycle's input and output (this rank's free DOFs)
            self._vectors = (system.vector.duplicate(), system.vector.duplicate())
        self.ksp.setFromOptions()
        self._eta = self._miss = None
        self._H = self._p = None
        self._renew = False
        self.seconds = 0.0
        self.reason = None

    def restart(self):
        """Start a new minimization: its first forcing tolerance is the largest again."""
        self._eta = self._miss = None

    def direction(self, x, g, gnorm, tolerance, project):
        """(Newton direction as a parallel vector, or None where this Hessian gives none;
        Krylov iterations)."""
        PETSc = self.PETSc
        H = self.system.hessian(x, project)
        reuse = self.method == "cg" and self._kept is not None and not self._renew
        if self.method == "cg":
            if not reuse:
                self._build(x, H)
            self._turned.apply_array = self._frames.carry(self._multigrid, self._built, x)
        self.ksp.setOperators(H)
        if self.method == "cg":
            if not project:  # one forcing tolerance per Newton iteration, set at its first try
                self._eta = forcing_tolerance(0.1, self._eta, self._miss, gnorm, tolerance)
            self.ksp.setTolerances(rtol=self._eta, atol=0.0, max_it=1000)
        rhs = g.copy()
        rhs.scale(-1.0)
        p = g.duplicate()
        start = time.perf_counter()
        try:
            self.ksp.solve(rhs, p)
        except PETSc.Error as err:  # a factorization that breaks down: no direction here
            self.reason = f"error {err.ierr}"
            return None, 0
        finally:
            self.seconds += time.perf_counter() - start
        its = self.ksp.getIterationNumber()
        self.reason = self.ksp.getConvergedReason()
        self._H, self._p = H, p
        if self.method == "cg":
            # a kept hierarchy is renewed after a solve that needed too many iterations with it
            self._renew = reuse and its > RENEW_AFTER
        if self.reason < 0 or not p.dot(g) < 0:
            return None, its
        if self.method == "newton" and not project:
            negative, zero, _ = self.ksp.getPC().getFactorMatrix().getInertia()
            if negative or zero:
                return None, its
        self.system.spread(p)
        return p, its

    def _build(self, x, H):
        """Build the multigrid hierarchy on a fresh copy of H (N/m, at positions x), with the
        rigid-body modes at x, and note the vertex frames at x. (ML set up again on the same
        matrix after MatCopy stalled CG: 1,000 iterations without converging on the 10^6-tet
        static solve, against 14 with a fresh copy.)"""
        start = time.perf_counter()
        if self._kept is not None:
            self._kept.destroy()
        self._kept = H.copy()
        modes = self.system.rigid_body_modes(x)
        if modes is not None:
            self._kept.setNearNullSpace(modes)
        self.multigrid.setOperators(self._kept)
        self.multigrid.setUp()
        self._built = self._frames.rotations(x)
        self.seconds += time.perf_counter() - start

    def _multigrid(self, r):
        """The kept multigrid's V-cycle on r (this rank's free DOFs, numpy) as numpy."""
        rhs, out = self._vectors
        rhs.setArray(r)
        self.multigrid.apply(rhs, out)
        return out.getArray(readonly=True)

    def accepted(self, g, g_new, gnorm, t):
        """After the step s = t p: how far the quadratic model missed the new gradient,
        |g_new - g - H s| / |g| (the next forcing tolerance's measure)."""
        if self.method != "cg":
            return
        Hs = self._p.duplicate()
        self._H.mult(self._p, Hs)
        Hs.scale(t)
        Hs.axpy(1.0, g)
        Hs.aypx(-1.0, g_new)
        self._miss = Hs.norm() / gnorm

    def destroy(self):
        self.ksp.destroy()
        if self.method == "cg":
            for obj in (self.multigrid, *self._vectors):
                obj.destroy()
            if self._kept is not None:
                self._kept.destroy()


class _Turned:
    """The "cg" method's preconditioner as a PETSc python PC: apply_array, a numpy function
    of this rank's free DOFs (the kept multigrid turned by VertexFrames.carry)."""
    apply_array = None

    def apply(self, pc, r, z):
        z.setArray(self.apply_array(r.getArray(readonly=True)))


def _line_search(system, x, energy, g, gnorm, p):
    """Backtracking to the Armijo condition on G from x along p (spread already), the serial
    loop's rules (anisofem.solvers.newton): a trial with G = +inf or NaN is rejected, and a trial
    whose energy change is round-off is taken where the gradient norm falls to NOISE_PROGRESS of its
    value. Returns (x_new, G, gradient, its norm, step length t), or None below MIN_STEP."""
    slope = p.dot(g)
    t = 1.0
    while t >= MIN_STEP:
        y = system.moved(x, p, t)
        trial, g_trial = system.energy_gradient(y)
        if math.isfinite(trial):
            gnorm_trial = g_trial.norm()
            if trial <= energy + ARMIJO * t * slope or (
                    abs(trial - energy) <= ENERGY_NOISE * abs(energy)
                    and gnorm_trial <= NOISE_PROGRESS * gnorm):
                return y, trial, g_trial, gnorm_trial, t
            g_trial.destroy()
        t *= 0.5
    return None
