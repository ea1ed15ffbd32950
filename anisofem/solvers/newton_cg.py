"""Inexact Newton, "cg" (NewtonCG): preconditioned conjugate gradients on the assembled
Hessian to a forcing tolerance, truncated at negative curvature; anisofem.solvers.methods says
what it is for."""
import math

import numpy as np

from . import linsolve, multigrid
from .frames import VertexFrames
from .kept_factor import KeptFactor


class NewtonCG(KeptFactor):
    """Inexact Newton by truncated, preconditioned conjugate gradients (see the module
    docstring). cg_iter: most CG iterations per Newton iteration. forcing: largest relative
    CG tolerance, the first iteration's (with a small budget of iterations, a small forcing
    such as 0.01 keeps each iteration close to a Newton step); see forcing_tolerance.
    preconditioner: "jacobi" (the Hessian's diagonal: no factorization at all), "factor" (a
    kept factorization of an earlier Hessian) or "amg" (a kept smoothed-aggregation
    multigrid hierarchy of an earlier Hessian, with the rigid-body modes at the current
    positions: no factorization, memory linear in the mesh, the rung for large meshes;
    anisofem.solvers.multigrid; applied in each vertex's frame rotated since it was
    built, anisofem.solvers.frames). A kept factor or hierarchy is renewed at the current state when
    a CG solve with it needs more than refactor_after iterations (default 10 with "factor", 60
    with "amg"), unless it was built for that solve. linear_solver: for "factor".
    """

    name = "cg"
    PRECONDITIONERS = ("jacobi", "factor", "amg")

    def __init__(self, cg_iter=1000, forcing=0.1, preconditioner="jacobi", refactor_after=None,
                 **newton):
        super().__init__(**newton)
        if int(cg_iter) < 1:
            raise ValueError(f"cg_iter: must be >= 1, got {cg_iter}")
        if not 0 < forcing < 1:
            raise ValueError(f"forcing: a fraction in (0, 1), got {forcing}")
        if preconditioner not in self.PRECONDITIONERS:
            raise ValueError(f"preconditioner: expected one of {self.PRECONDITIONERS}, got "
                             f"{preconditioner!r}")
        if refactor_after is None:
            refactor_after = 60 if preconditioner == "amg" else 10
        if int(refactor_after) < 1:
            raise ValueError(f"refactor_after: must be >= 1, got {refactor_after}")
        self.cg_iter, self.forcing = int(cg_iter), float(forcing)
        self.preconditioner, self.refactor_after = preconditioner, int(refactor_after)
        self._frames = self._built = self._nested = None

    def start(self, potential):
        super().start(potential)
        self.csr = potential.scene.layout("csr")
        self._eta = self._miss = self._model = None

    def first_factor(self, potential):
        """With "amg", the vertex frames the hierarchies of this scene are carried by."""
        if self.preconditioner == "amg":
            scene = potential.scene
            self._frames = VertexFrames(scene.mesh, scene.free_dofs)
            self._nested = (multigrid.corner_prolongation(scene.mesh, scene.free_dofs)
                            if scene.mesh.order == 2 else (None, scene.free_dofs))

    def threads(self):
        """One BLAS thread unless a factorization is kept
        (anisofem.solvers.linsolve.one_blas_thread): the iterations' vector products would
        otherwise slow the parallel assembly."""
        if self.preconditioner == "factor":
            return super().threads()
        return linsolve.one_blas_thread()

    def directions(self, x, g, residual):
        gnorm = math.sqrt(float(np.dot(g, g)))
        self._eta = eta = forcing_tolerance(self.forcing, self._eta, self._miss, gnorm,
                                            self.tolerance)
        for projected in self._CHOICES[self.projection]:
            data = self.potential.hessian_data(x, self.csr, project=projected,
                                               want_grad=False)[2]
            fresh = self._solve is None
            precondition = self._preconditioner(x, data, projected)
            if precondition is None:
                continue
            hessian = self.csr.operator(data)
            p, its = truncated_cg(hessian, g, precondition, eta, self.cg_iter)
            self.counts["linear_iterations"] += its
            # one built at this very iterate is as fresh as a renewal would be
            if self.preconditioner != "jacobi" and its > self.refactor_after and not fresh:
                self._solve = None
            if p is not None:
                self.counts["projected"] += projected
                self._model = hessian, gnorm
                yield p

    def accepted(self, s, y, progress):
        """Keep how far the quadratic model of the last iterate missed the new gradient,
        |y - H s| / |g|: the next forcing tolerance's measure."""
        hessian, gnorm = self._model
        miss = y - hessian @ s
        self._miss = math.sqrt(float(np.dot(miss, miss))) / gnorm

    def _preconditioner(self, x, data, projected):
        """r -> M^-1 r, or None when there is none for this Hessian."""
        if self.preconditioner == "jacobi":
            diagonal = data[self.csr.diag]
            return (lambda r: r / diagonal) if (diagonal > 0).all() else None
        if self.preconditioner == "amg":
            if self._solve is None:
                if not projected:  # multigrid wants a positive definite matrix: the projected
                    data = self.potential.hessian_data(x, self.csr, project=True,
                                                       want_grad=False)[2]
                self.counts["factorizations"] += 1  # hierarchies built
                nested, coarse_dofs = self._nested
                modes = multigrid.rigid_body_modes(x, coarse_dofs)
                self._solve = multigrid.preconditioner(self.csr.matrix(data), modes, nested)
                self._built = self._frames.rotations(x)
                return self._solve  # made here: nothing to carry
            return self._frames.carry(self._solve, self._built, x)
        if self._solve is None:
            # the factorization may overwrite its input
            same = self.layout is self.csr
            if not self.refresh(x, projected, data.copy() if same else None):
                return None
        return self._solve


#: Eisenstat and Walker's safeguard exponent: the golden ratio, the order of the forcing
#: choice's convergence.
_GOLDEN = (1.0 + math.sqrt(5.0)) / 2.0


def forcing_tolerance(forcing, previous, miss, gnorm, tolerance):
    """The relative CG tolerance of a Newton iteration (Eisenstat and Walker 1996, choice 1,
    with their safeguard, and Kelley's lower bound). forcing: the largest, a solve's first
    iteration's (previous None). previous: the last iteration's. miss: the relative error
    |g - g_prev - H_prev s| / |g_prev| of the last iteration's quadratic model, kept from
    falling faster than previous^1.618 while that is above 0.1. The result is no smaller than
    0.5 tolerance / gnorm: no CG digits past the Newton tolerance (N) at a gradient of norm
    gnorm (N)."""
    eta = forcing
    if previous is not None:
        eta = miss
        if previous ** _GOLDEN > 0.1:
            eta = max(eta, previous ** _GOLDEN)
    return min(forcing, max(eta, 0.5 * tolerance / gnorm))


def truncated_cg(A, g, precondition, eta, max_iter):
    """Approximate solution p of A p = -g by preconditioned CG (precondition: r -> M^-1 r for
    a positive definite M), stopped when |A p + g| <= eta |g|, after max_iter iterations, or
    at the first direction of non-positive curvature (Steihaug). Returns (p, or None if the
    first direction already has non-positive curvature; iterations)."""
    p = np.zeros_like(g)
    r = -g
    z = precondition(r)
    d = z.copy()
    rz = float(np.dot(r, z))
    stop = (eta * math.sqrt(float(np.dot(g, g)))) ** 2
    for it in range(max_iter):
        Ad = A @ d
        curvature = float(np.dot(d, Ad))
        if not curvature > 0:
            return (p if it else None), it
        alpha = rz / curvature
        p += alpha * d
        r -= alpha * Ad
        if float(np.dot(r, r)) <= stop:
            return p, it + 1
        z = precondition(r)
        rz, rz_old = float(np.dot(r, z)), rz
        d = z + (rz / rz_old) * d
    return p, max_iter
