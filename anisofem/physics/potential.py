"""The (incremental) potential of a scene, its gradient and Hessian: the public functions that
are also the network's loss.

Statics:          G(x) = sum_e Psi_e(x) - f_ext . x
Backward Euler:   G(x) = 1/(2 dt^2) (x - x_hat)^T M (x - x_hat) + sum_e Psi_e(x) - f_ext . x,
                  with x_hat = x_n + dt v_n and the lumped mass matrix M.
Positions x are (n, 3) in m, energies in J, gradients in N, Hessians in N/m.
"""
import functools
import math

import numpy as np

from . import kernels
from .contact import ContactTerm
from .scene import ROUNDOFF_FACTOR, Scene
from .._validate import as_float_array, as_scalar

#: A Newton step that moves no node by more than this share of the contact distance has
#: resolved the contact (Potential.contact_resolved)
RESOLVED = 1e-3


_NO_MASS = np.empty(0)


class Potential:
    """G of a scene, statics (x_hat = dt = None) or one backward-Euler step.

    x_start (n, 3), m: the state the problem starts from, which sets its force scale
    (force_scale): a step's x_n (default x_hat), statics' the scene's initial positions.
    """

    def __init__(self, scene, x_hat=None, dt=None, x_start=None):
        if not isinstance(scene, Scene):
            raise TypeError(f"scene: expected an anisofem.Scene, got {type(scene).__name__}")
        if (x_hat is None) != (dt is None):
            raise ValueError("x_hat, dt: give both (backward Euler) or neither (statics)")
        self.scene = scene
        self.dynamic = dt is not None
        # statics: no inertia (empty arrays, which the load kernel reads as "no inertia")
        self.x_hat, self.mass_over_dt2 = kernels.EMPTY_GRAD, _NO_MASS
        if self.dynamic:
            self.dt = as_scalar(dt, "dt")
            if self.dt <= 0:
                raise ValueError(f"dt: the time step must be > 0 s, got {self.dt}")
            self.x_hat = check_positions(scene, x_hat, "x_hat")
            self.mass_over_dt2 = scene.masses / self.dt ** 2
            self.mass_per_dof = np.repeat(self.mass_over_dt2, 3)
        if x_start is None:
            x_start = self.x_hat if self.dynamic else scene.initial_positions()
        self.x_start = check_positions(scene, x_start, "x_start")
        self.contact = (ContactTerm(scene, self.x_start, dt if self.dynamic else None)
                        if scene.contact is not None else None)
        #: whether the Hessian couples nodes no element joins (self-contact, surfaces)
        self.coupled = scene.contact is not None and scene.contact.pairs

    def loaded(self, share):
        """The same problem under `share` (0 to 1) of its load (load continuation,
        anisofem.solvers.continuation): statics under Scene.loaded(share), external force and
        prescribed displacements scaled; a step with its external force scaled, from the same
        state with the same x_hat and dt (its prescribed positions are the step's own)."""
        if not self.dynamic:
            return Potential(self.scene.loaded(share))
        return Potential(self.scene.loaded(share, prescribed=False), self.x_hat, self.dt,
                         x_start=self.x_start)

    def force_scale(self):
        """The size of this problem's forces in N, whatever the start of a solve: the norms
        over the free components of the external force, the elastic force at x_start and, in
        a step, the inertial force M (x_start - x_hat) / dt^2 (= -M v_n / dt), summed. Newton's
        tolerance is relative to it."""
        free = self.scene.free_dofs
        parts = [self.scene.external_force, self._start[1]]
        if self.dynamic:
            parts.append(self.mass_over_dt2[:, None] * (self.x_start - self.x_hat))
        total = 0.0
        for part in parts:
            v = part.ravel()[free]
            total += math.sqrt(float(np.dot(v, v)))
        return total

    def start_energy(self):
        """G(x_start) in J; for a step, the mechanical energy it starts with:
        elastic - f_ext . x_n + 1/2 v_n^T M v_n."""
        return self._start[0]

    @functools.cached_property
    def _start(self):
        """(G, elastic force (n, 3)) at x_start, from one assembly."""
        e_iso, e_fib, elastic = kernels.assemble(self.x_start, self.scene.elements,
                                                 want_grad=True)
        external, kinetic = self._loads(self.x_start, kernels.EMPTY_GRAD)
        pressure = self._pressure(self.x_start, elastic)
        return (float(e_iso.sum()) + float(e_fib.sum()) + external + kinetic + pressure
                + self._contact(self.x_start), elastic)

    def _elastic(self, x, want_grad=False, layout=None, project=False):
        """Elastic part: (e_iso (m,), e_fib (m,), gradient (n, 3) or None, Hessian data or
        None); the Hessian is added into layout.zeros() when a layout is given."""
        if layout is None:
            return kernels.assemble(x, self.scene.elements, want_grad=want_grad) + (None,)
        data = layout.zeros()
        e_iso, e_fib, grad = kernels.assemble(
            x, self.scene.elements, want_grad=want_grad, want_hess=True, project=project,
            hess_map=layout.map, hess_data=data)
        return e_iso, e_fib, grad, data

    def terms(self, x):
        """Energy terms in J: isotropic, fiber, external, kinetic, pressure (-p times each
        cavity's volume change, and each cable's tension times its length, summed), contact
        (the barrier's and friction's, anisofem.physics.contact), total; and
        per-element elastic energies (m,) under "elements"."""
        e_iso, e_fib, _, _ = self._elastic(x)
        external, kinetic = self._loads(x, kernels.EMPTY_GRAD)
        out = {"isotropic": float(e_iso.sum()), "fiber": float(e_fib.sum()),
               "external": external, "kinetic": kinetic, "pressure": self._pressure(x),
               "contact": self._contact(x)}
        out["total"] = (out["isotropic"] + out["fiber"] + out["external"] + out["kinetic"]
                        + out["pressure"] + out["contact"])
        out["elements"] = e_iso + e_fib
        return out

    def energy(self, x):
        """G(x) in J."""
        return self.terms(x)["total"]

    def energy_gradient(self, x):
        """(G(x) in J, dG/dx (n, 3) in N)."""
        return self._evaluate(x, want_grad=True)[:2]

    def hessian_data(self, x, layout, project=False, want_grad=True):
        """Assemble d2G/dx2 into layout (a CsrLayout or DenseLayout over some DOFs).

        Returns (G, gradient (n, 3) or None, data) where layout.matrix(data) is the Hessian.
        project: use the PSD-projected element Hessians (see anisofem.physics.kernels).
        """
        return self._evaluate(x, want_grad, layout, project)

    def _evaluate(self, x, want_grad, layout=None, project=False):
        e_iso, e_fib, grad, data = self._elastic(x, want_grad, layout, project)
        external, kinetic = self._loads(x, grad if want_grad else kernels.EMPTY_GRAD)
        pressure = self._pressure(x, grad if want_grad else None)
        value = (float(e_iso.sum()) + float(e_fib.sum()) + external + kinetic + pressure
                 + self._contact(x, grad if want_grad else None))
        if layout is not None and self.contact is not None:
            self.contact.add_hessian(x, layout, data, project)
        if layout is not None and not project:
            for cavity in self.scene.pressures:
                cavity.add_hessian(x, layout, data)
        if layout is not None:   # a cable's Hessian is positive semi-definite
            for cable in self.scene.cables:
                cable.add_hessian(x, layout, data)
        if self.dynamic and layout is not None:
            data[layout.diag] += self.mass_per_dof[layout.dofs]
        return value, grad, data

    def _pressure(self, x, grad=None):
        """The pressures' and cables' energy, J (the actuators'); adds their gradient to grad
        (n, 3) when given. (The pressures' Hessian is left out of the PSD-projected one: the
        elastic part is PSD by itself.)"""
        total = 0.0
        for load in self.scene.pressures + self.scene.cables:
            total += load.energy(x, grad)
        return total

    def _contact(self, x, grad=None):
        """The contact's energy, J (inf where a node reached an obstacle); adds its gradient
        to grad (n, 3) when given."""
        return 0.0 if self.contact is None else self.contact.energy(x, grad)

    def coupled_hessian(self, x, layout, project=False):
        """The part of d2G/dx2 at x that couples nodes no element joins (self-contact's pairs),
        a scipy CSC matrix over layout's unknowns, or None where there is none."""
        if self.contact is None:
            return None
        return self.contact.coupled_hessian(x, layout.dofs, project)

    def contact_roundoff(self, x):
        """The free-gradient norm, N, below which float64 cannot resolve the contact's forces
        at x (n, 3): ROUNDOFF_FACTOR eps R |H_c|, R the largest coordinate and |H_c| the
        Frobenius norm of the contact's Hessian (a barrier's stiffness grows without bound as
        a gap closes, and its force's round-off with it); 0 without contact."""
        if self.contact is None:
            return 0.0
        blocks = self.contact.node_hessians(x)
        size = float(np.einsum("kij,kij->", blocks, blocks))
        coupled = self.contact.coupled_hessian(x, self.scene.free_dofs)
        if coupled is not None:
            size += float((coupled.multiply(coupled)).sum())
        return (ROUNDOFF_FACTOR * np.finfo(float).eps * float(np.abs(x).max())
                * math.sqrt(size))

    def contact_resolved(self, p):
        """Whether the move p (over the free unknowns, m) moves no node farther than RESOLVED
        of the contact distance dhat: below that, a stalled line search has nothing left to
        find (the pair distances are only once differentiable where their closest features
        change, and near there an Armijo search can stall with the residual above its
        tolerance; IPC stops on the Newton step's length for the same reason). False without
        contact."""
        if self.contact is None:
            return False
        return float(np.abs(p).max(initial=0.0)) <= RESOLVED * self.contact.dhat

    def step_limit(self, x, p):
        """The largest share in (0, 1] of the move p (over the free unknowns) from x (n, 3)
        that keeps every surface node clear of the obstacles (1 without contact)."""
        if self.contact is None:
            return 1.0
        dx = np.zeros_like(x)
        dx.ravel()[self.scene.free_dofs] = p
        return self.contact.max_step(x, dx)

    def feasible(self, x0):
        """A solve's start: x0 (n, 3), or with contact the point of the way from x_start to it
        where it would first come too close to an obstacle; where x_start is not clear of them
        (an obstacle moved into where the step began), x0 as it is, which must be."""
        if self.contact is None or not self.contact.clear(self.x_start):
            return x0
        share = self.contact.max_step(self.x_start, x0 - self.x_start)
        return x0 if share >= 1.0 else self.x_start + share * (x0 - self.x_start)

    def _loads(self, x, grad):
        """(external, kinetic) energies in J; adds their gradient to grad unless it is empty."""
        return kernels.loads_and_inertia(x, self.scene.external_force, self.mass_over_dt2,
                                         self.x_hat, grad)


def check_positions(scene, x, name="x"):
    """x as a finite (n, 3) float64 array."""
    return as_float_array(x, name, shape=(scene.mesh.n_vertices, 3))


def energy(scene, x, x_hat=None, dt=None):
    """Potential G(x) in J (statics, or backward Euler with x_hat and dt); its terms:
    anisofem.physics.metrics.energy_split."""
    return Potential(scene, x_hat, dt).energy(check_positions(scene, x))


def gradient(scene, x, x_hat=None, dt=None):
    """dG/dx, (n, 3) in N, for every vertex (fixed ones included)."""
    return Potential(scene, x_hat, dt).energy_gradient(check_positions(scene, x))[1]


def hessian(scene, x, x_hat=None, dt=None, project=False):
    """d2G/dx2 as a scipy.sparse CSR matrix (3n, 3n) in N/m, DOF 3 i + c for vertex i, axis c.

    project=True returns the PSD-projected Hessian Newton uses away from equilibrium.
    """
    layout = scene.full_layout
    potential, x = Potential(scene, x_hat, dt), check_positions(scene, x)
    _, _, data = potential.hessian_data(x, layout, project=project, want_grad=False)
    coupled = potential.coupled_hessian(x, layout, project)
    return layout.matrix(data) if coupled is None else (layout.matrix(data) + coupled).tocsr()


def element_energy(scene, x):
    """(m,) elastic energy of each tet in J (isotropic + fiber)."""
    return Potential(scene).terms(check_positions(scene, x))["elements"]
