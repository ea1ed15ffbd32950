"""FramedModel: a reduced model for bodies that bend and swing far. The body is cut into
domains (anisofem.reduced.domains), and each domain moves in its own rotating frame:

    x_i = R_d (y_i + U_i q_d) + c_d      for each node i of domain d,

R_d a rotation, c_d its centre, y_i the node's rest position about the domain's centre of mass
and U_d (k, 3, r_d) the domain's local basis, mass-orthonormal and free of rigid motion. The
local bases are the principal directions of the full FEM's static equilibria under the declared
loads (anisofem.reduced.snapshots), each pulled back into the domain's best-fitting frame, and
of the rest vibration modes: what a linear basis must hold for every orientation, a frame holds
by turning (after Barbic and Zhao 2011; here the domains are joined through the elements they
share). The held nodes keep their place.

Backward Euler minimizes over the frames and coordinates

    1/(2 dt^2) |x - x_hat|_M^2 + sum_d V_d(q_d) + V_joints(x) - f . x,

exactly for these kinematics:
- V_d, the elastic energy of the elements inside domain d, does not change when the domain
  turns: it is the quartic polynomial of anisofem.reduced.polynomial in q_d.
- The inertia and the loads are quadratic in x, so their sums over a domain's nodes reduce to
  3 x 3 moments of its basis, precomputed (FramedModel._targets): no mesh data per step.
- The joints, the elements whose nodes lie in more than one domain (or on held nodes), are
  evaluated element by element: a layer one element thick at each cut. Where the cut's
  cross-section holds many elements, a cubature (anisofem.reduced.cubature) of a few of them,
  weighted, fitted to the model's own rollouts under the declared loads, stands in for the
  layer, so that the step's cost stops growing with the mesh.
The domains form a kinematic tree from the held nodes (anisofem.reduced.domains.tree): a
domain's centre is carried by its parent's turn and its own about a pivot on their interface,
c_e = c_p + R_p a_e + R_e b_e + t_e, so that a turn swings the domains beyond it on their arcs
(FramedModel._plant). Each Newton step moves t_e, turns R_e by exp([theta_e]) and q_e, and
takes the exact gradient and Hessian in (t_e, theta_e, q_e) at theta = 0: the step is Newton's
on the model's own energy, started from the extrapolated state.
"""
import math
import time
from dataclasses import dataclass, field, replace

import numpy as np
import scipy.linalg as sla

from ..physics import kernels
from .._validate import as_float_array
from . import cubature as _cubature
from . import framed_kernels as fk
from .domains import split, tree
from .framed_build import block_map, build_domain, rest_modes
from .loads import Loads, default_loads, unseen_cases
from .model import (HOLD_STEPS, REDRAWS, VALIDATION_CASES, VALIDATION_DT, NewtonReport, _count,
                    check_polynomial_scene, validate_rollouts)
from .snapshots import static_states

#: Default number of bands the body is cut into from its held nodes (each band's connected
#: pieces are domains: a T cut in 4 bands has a domain per arm). With COORDINATES, the best
#: of the sizes measured on the T, the Y and the 0.2 m beam (docs/experiments.md).
BANDS = 4
#: Default local coordinates per domain.
COORDINATES = 12
#: Rest vibration modes whose restrictions join each domain's snapshots.
MODES = 6

#: The joints' cubature: a weighted few of the joint elements whose generalized forces match
#: the whole layer's within this share on the model's own rollouts, kept where it takes at
#: most CUBATURE_SHARE of the joint elements (else the layer is evaluated whole). Fitted on
#: CUBATURE_CASES rollouts under load cases drawn from the declaration with CUBATURE_SEED (the
#: validation draws with seed 0), each held HOLD_STEPS steps of VALIDATION_DT and released
#: as many, every CUBATURE_EVERY-th state a pose (docs/experiments.md).
CUBATURE_RESIDUAL = 0.01
CUBATURE_SHARE = 0.5
CUBATURE_CASES = 6
CUBATURE_SEED = 1
CUBATURE_EVERY = 2

#: A Newton iteration is the last when no node moves more than this share of the body's size.
STEP_TOLERANCE = 1e-8

@dataclass
class FramedState:
    """A framed model's state: c (D, 3) the domains' centres, m; R (D, 3, 3) their rotations;
    q (Q,) every domain's local coordinates, one after another (FramedModel.domains[d].q);
    base (3, 4) [R_g | c_g], where the held nodes are: x = R_g x0 + c_g (a rigid motion; the
    identity by default)."""
    c: np.ndarray
    R: np.ndarray
    q: np.ndarray
    base: np.ndarray = field(default_factory=lambda: np.eye(3, 4))

    def copy(self):
        return FramedState(self.c.copy(), self.R.copy(), self.q.copy(), self.base.copy())


class FramedModel:
    """The framed reduced model of a scene with the StVK base, with or without fibers.

    Parameters
    ----------
    scene : the Scene. Whole nodes must be held (no rollers); pressures are refused.
    bands : cut the body into this many bands of distance from the held nodes
        (anisofem.reduced.domains.split; each band's pieces are domains).
    coordinates : local coordinates per domain (fewer where a domain's snapshots span fewer).
    modes : rest vibration modes added to every domain's snapshots.
    loads : a Loads, what the model must handle beyond the scene's own loads (default:
        default_loads, a drag of up to half the body's weight at each free end). Its static
        equilibria shape the local bases, and unseen cases drawn from it validate the model.
    cubature : the share of the joints' generalized forces a cubature of the joint elements
        may miss on the model's rollouts (default CUBATURE_RESIDUAL); 0 evaluates every joint
        element. Kept only where it takes at most CUBATURE_SHARE of them.
    validate : run the validation (VALIDATION_CASES rollouts against the full FEM), of the
        model with its cubature.
    progress : a callable(str) told each stage of the build as it starts, once the arguments
        are checked (None: silent).

    Attributes: domains (list of Domain); labels (n,) each node's domain, -1 held; parent
    (D,) each domain's parent in the kinematic tree (-1: the held nodes); joint_nodes, the
    nodes of the joint elements evaluated; cubature (an anisofem.reduced.cubature.Cubature
    over the joint layer's elements, or None where every one is evaluated); r, the
    Newton unknowns (6 per domain and its coordinates); x0 (n, 3) rest positions; loads;
    snapshots (a SnapshotReport); build_seconds (the cubature's rollouts included);
    validation (a Validation, or None).
    A NewtonReport's residual here is the last Newton step's largest node move bound, m.
    """

    def __init__(self, scene, bands=BANDS, coordinates=COORDINATES, modes=MODES, loads=None,
                 cubature=CUBATURE_RESIDUAL, validate=True, progress=None):
        check_polynomial_scene(scene, "framed model")
        why = refusal(scene)
        if why:
            raise ValueError(why)
        scene.check_static()
        bands = _count(bands, "bands", 1)
        coordinates = _count(coordinates, "coordinates", 1)
        modes = _count(modes, "modes", 0)
        if modes >= scene.n_free:
            raise ValueError(f"modes: {modes} modes need more than the scene's {scene.n_free} "
                             f"unknowns")
        if not (isinstance(cubature, (int, float, np.floating)) and not isinstance(cubature, bool)
                and 0.0 <= cubature < 1.0):
            raise ValueError(f"cubature: expected a share from 0 (every joint element) to below "
                             f"1, got {cubature!r}")
        loads = default_loads(scene) if loads is None else loads
        if not isinstance(loads, Loads):
            raise TypeError(f"loads: expected an anisofem.reduced.Loads, got "
                            f"{type(loads).__name__}")
        loads.check(scene)
        say = progress or (lambda stage: None)
        t0 = time.perf_counter()
        self.scene, self.loads = scene, loads
        self.x0 = scene.initial_positions()
        self.labels, count = split(scene, bands)
        self.parent, pivots, self._order = tree(scene, self.labels)
        say(f"the full FEM's static equilibria under the declared loads ({count} domains)")
        states, self.snapshots = static_states(scene, loads)
        say("each domain's basis and polynomial")
        modes = rest_modes(scene, self.x0, modes)
        inner, joints = self._cut()
        self.domains, z, q = [], 0, 0
        for d in range(count):
            nodes = np.flatnonzero(self.labels == d)
            domain = build_domain(scene, self.x0, nodes, states, modes, coordinates, inner[d], z,
                             q)
            self.domains.append(domain)
            z, q = z + 6 + domain.r, q + domain.r
        self.r, self._q_size = z, q
        self._pack()
        self._plant(pivots)
        self.size = float(np.ptp(self.x0, axis=0).max())
        self._set_joints(joints)
        self._own = self._project(scene.external_force)
        if cubature > 0:
            say("a cubature of the joints, fitted to the model's own rollouts")
        self.cubature = self._fit_joints(joints, cubature) if cubature > 0 else None
        credit = max(self.snapshots.seconds - (time.perf_counter() - t0), 0.0)
        self.build_seconds = time.perf_counter() - t0 + credit
        if validate:
            say("its validation against the full FEM")
        self.validation = self.validate() if validate else None

    def _cut(self):
        """Each domain's inner elements (lists of element indices), and the joints (element
        indices), the elements across domains (and held nodes)."""
        owner = self.labels[self.scene.elements.tets]
        inner_mask = (owner == owner[:, :1]).all(axis=1) & (owner[:, 0] >= 0)
        inner = [np.flatnonzero(inner_mask & (owner[:, 0] == d))
                 for d in range(self.labels.max() + 1)]
        return inner, np.flatnonzero(~inner_mask & (owner >= 0).any(axis=1))

    def _set_joints(self, rows, weights=None):
        """The joints, elements `rows`, their energies times `weights` (len(rows),; default
        1), over a compact numbering of their nodes: their ElementData, the nodes' packed rows
        (labels, Y, U, x0) and the Hessian's node pairs."""
        elements = self.scene.elements
        nodes, local = np.unique(elements.tets[rows], return_inverse=True)
        tets = local.reshape(len(rows), -1)
        self.joint_nodes = nodes
        self._joint_elements = elements.subset(rows, tets)
        if weights is not None:
            self._joint_elements = replace(self._joint_elements, weights=(
                self._joint_elements.weights * np.asarray(weights)[:, None]))
        self._joint_rows = (self._labels[nodes], self._Y[nodes], self._U[nodes],
                            self.x0[nodes].copy())
        k = tets.shape[1]
        pairs = np.unique(np.concatenate([tets[:, [a, b]] for a in range(k) for b in range(k)]),
                          axis=0)
        self._pairs = np.ascontiguousarray(pairs, dtype=np.int64)
        self._pair_ptr = np.searchsorted(pairs[:, 0], np.arange(nodes.size + 1)).astype(np.int64)
        self._joint_map = block_map(tets, pairs, self.labels[nodes] >= 0)

    def _pack(self):
        """The domains' moments, polynomials and every node's rest offset and basis rows in
        the packed arrays of anisofem.reduced.framed_kernels."""
        D = self.domains
        self._r = np.array([d.r for d in D], np.int64)
        self._q0 = np.array([d.q.start for d in D], np.int64)
        self._z0 = np.array([d.z.start for d in D], np.int64)
        self._b0 = np.concatenate([[0], np.cumsum(self._r ** 2)[:-1]]).astype(np.int64)
        self._mass = np.array([d.mass for d in D])
        self._a = np.concatenate([d.a for d in D])
        self._J = np.array([d.J for d in D])
        self._A = np.concatenate([d.A for d in D])
        self._B = np.concatenate([d.B.reshape(-1, 3, 3) for d in D])
        n = self.x0.shape[0]
        self._Y = np.zeros((n, 3))          # every node's rest offset and basis rows in its
        self._U = np.zeros((n, 3, max(self._r.max(), 1)))     # domain (zero for held nodes)
        for d in D:
            self._Y[d.nodes] = d.y
            self._U[d.nodes, :, :d.r] = d.U
        self._labels = self.labels.astype(np.int64)
        P = [d.polynomial for d in D]
        sizes = np.array([[p.C2.size, p.S3.size, p.W4.size] for p in P])
        self._coefficients = (
            np.array([p.c0 for p in P]), np.concatenate([p.c1 for p in P]),
            np.concatenate([p.C2.ravel() for p in P]), np.concatenate([p.S3.ravel() for p in P]),
            np.concatenate([p.W4.ravel() for p in P]),
            np.vstack([np.zeros((1, 3), np.int64),
                       np.cumsum(sizes, axis=0)[:-1]]).astype(np.int64))
        self._zc = self._z0[:, None] + np.arange(3)
        self._zt = self._zc + 3
        self._zq = np.concatenate([np.arange(d.z.start + 6, d.z.stop) for d in D]).astype(int)
        self._radius = np.array([d.radius for d in D])
        self._reach = np.array([d.reach for d in D])

    # -- states and positions ------------------------------------------------------------

    def rest(self):
        """The rest state: every frame at its domain's rest centre, unturned, q = 0."""
        D = len(self.domains)
        return FramedState(np.array([d.centre for d in self.domains]),
                           np.tile(np.eye(3), (D, 1, 1)), np.zeros(self._q_size))

    def positions(self, state):
        """Full positions (n, 3), m, of a FramedState."""
        x = np.empty_like(self.x0)
        fk.node_positions(state.c, state.R, state.q, state.base, self._labels, self._Y, self._U,
                          self.x0, self._q0, self._r, x)
        return x

    def project(self, force):
        """The moments of nodal forces f (n, 3), N, on the domains: F0 (D, 3, 3) = sum f y^T,
        F (Q, 3, 3) = sum f U_b^T, Fsum (D, 3) = sum f, over each domain's nodes (the load
        term -f . x = -tr(R^T (F0 + q . F)) - c . Fsum)."""
        return self._project(as_float_array(force, "force",
                                            shape=(self.scene.mesh.n_vertices, 3)))

    def _project(self, f):
        return (np.array([f[d.nodes].T @ d.y for d in self.domains]),
                np.concatenate([np.einsum("ka,kbr->rab", f[d.nodes], d.U)
                                for d in self.domains]),
                np.array([f[d.nodes].sum(axis=0) for d in self.domains]))

    # -- stepping --------------------------------------------------------------------------

    def step(self, now, before, dt, force=None, base=None, max_iter=50):
        """One backward-Euler step of dt s from `now` (a FramedState), `before` being the
        state a step earlier (equal to now from rest): x_hat = 2 x(now) - x(before). Under the
        scene's loads plus nodal forces `force` (n, 3), N; base (3, 4) [R_g | c_g]: where the
        held nodes are at the step's end, x = R_g x0 + c_g (a rigid motion that carries the
        body: a hand, a character; default: where they are in now). Returns (next state,
        NewtonReport)."""
        if not dt > 0:
            raise ValueError(f"dt: the time step must be > 0 s, got {dt}")
        base = now.base if base is None else rigid_motion(base)
        inertia = 1.0 / dt ** 2
        targets = self._targets(self._load(force), inertia, ((now, 2.0), (before, -1.0)))
        return self._newton(self._extrapolated(now, before, base), targets, inertia, max_iter)

    def solve(self, force=None, start=None, max_iter=50):
        """The static equilibrium under the scene's loads plus nodal forces `force` (n, 3), N,
        from `start` (default: rest). Returns (FramedState, NewtonReport)."""
        start = self.rest() if start is None else start.copy()
        return self._newton(start, self._targets(self._load(force), 0.0, ()), 0.0, max_iter)

    def rollout(self, phases, dt, base=None):
        """Positions (k + 1, n, 3) from rest through phases ((extra nodal force (n, 3) N or
        None, steps), ...) of dt s, the held nodes carried by base (t -> (3, 4), or None), and
        whether every step converged."""
        states, ok = self._states(phases, dt, base)
        return np.array([self.positions(s) for s in states]), ok

    def _states(self, phases, dt, base=None):
        """rollout()'s FramedStates (k + 1,), and whether every step converged."""
        now = before = self.rest()
        states, ok, k = [now], True, 0
        for force, steps, *_ in phases:   # controls: the framed model takes none
            for _ in range(steps):
                k += 1
                at = None if base is None else base(k * dt)
                after, report = self.step(now, before, dt, force=force, base=at)
                ok &= report.converged
                now, before = after, now
                states.append(now)
        return states, ok

    def _fit_joints(self, rows, residual):
        """A Cubature of the joint elements `rows` (its elements index rows), fitted on the
        model's rollouts under CUBATURE_CASES drawn cases, and the joints set to it; None (the
        joints left whole) where it would take more than CUBATURE_SHARE of them, or where no
        pose loads the joints. Each pose weighs alike: its generalized forces over their sum's
        norm, its energies over their sum."""
        most = int(CUBATURE_SHARE * len(rows))
        if most < 1:
            return None
        t0 = time.perf_counter()
        zero = np.zeros_like(self.x0)
        m, k = self._joint_elements.tets.shape
        own = self._joint_elements.subset(np.arange(m), np.arange(m * k).reshape(m, k))
        blocks = []
        for _, force, base, _ in unseen_cases(self.scene, self.loads, CUBATURE_CASES,
                                           CUBATURE_SEED):
            states, _ = self._states(((force, HOLD_STEPS), (zero, HOLD_STEPS)), VALIDATION_DT,
                                     base)
            for state in states[CUBATURE_EVERY::CUBATURE_EVERY]:
                forces, energies = self._joint_element_forces(state, own)
                size = np.linalg.norm(forces.sum(axis=0))
                if size > 0 and np.isfinite(size) and np.isfinite(energies).all():
                    blocks.append(np.vstack([forces.T / size,
                                             energies / max(abs(energies.sum()), 1e-300)]))
        if not blocks:
            return None
        chosen, weights, missed = _cubature.select(np.vstack(blocks), residual, most)
        if missed > residual:
            return None
        self._set_joints(rows[chosen], weights)
        return _cubature.Cubature(chosen, weights, len(rows), missed, time.perf_counter() - t0)

    def _joint_element_forces(self, state, own):
        """Each joint element's generalized force (m, r) in the domains' (c, theta, q) at
        theta = 0, N, and its energy (m,), J, at a FramedState; own, the joint elements'
        ElementData with nodes of their own (numbered element by element), so that the
        assembled gradient is each element's."""
        elements = self._joint_elements
        m, k = elements.tets.shape
        x = self._joint_positions(state)
        e_iso, e_fib, grad = kernels.assemble(x[elements.tets].reshape(-1, 3), own,
                                              want_grad=True)
        dom, U = self._joint_rows[0], self._joint_rows[2]
        Jn = np.zeros((dom.size, 3, 6 + self._r.max()))
        fk.node_jacobians(x, state.c, state.R, dom, U, self._r, Jn)
        forces = np.zeros((m, self.r))
        fk.element_forces(elements.tets, grad.reshape(m, k, 3), Jn, dom, self._z0, self._r,
                          forces)
        return forces, e_iso + e_fib

    def validate(self, cases=None, seed=0):
        """The model against the full FEM on `cases` (default VALIDATION_CASES) short rollouts
        under unseen loads drawn from the declaration with `seed` (a Validation)."""
        cases = VALIDATION_CASES if cases is None else _count(cases, "cases", 1)
        return validate_rollouts(self, unseen_cases(self.scene, self.loads, REDRAWS * cases,
                                                    seed), cases)

    def _load(self, force):
        if force is None:
            return self._own
        return tuple(a + b for a, b in zip(self._own, self.project(force)))

    def _targets(self, load, inertia, history):
        """(T0 (D, 3, 3), T (Q, 3, 3), t (D, 3)): the loads' moments plus the inertia's pull
        towards x_hat = sum alpha x(state) over history ((state, alpha), ...), so that the
        step's energy is sum_d inertia/2 (2 a.q + |q|^2 + mass |c|^2) - tr(R^T (T0 + q . T))
        - t . c, plus the elastic energy."""
        T0, T, t = (v.copy() for v in load)
        if history:
            fk.targets(inertia, np.array([h.c for h, _ in history]),
                       np.array([h.R for h, _ in history]),
                       np.array([h.q for h, _ in history]),
                       np.array([alpha for _, alpha in history]), self._J, self._A, self._B,
                       self._mass, self._q0, self._r, self._b0, T0, T, t)
        return T0, T, t

    def energy(self, state, targets, inertia):
        """The step's energy (module docstring), J."""
        T0, T, t = targets
        total = fk.domain_energy(inertia, state.c, state.R, state.q, self._a, self._mass, T0,
                                 T, t, self._q0, self._r)
        total += self._polynomials(state.q, np.zeros(0), np.zeros((0, 0)))
        e_iso, e_fib, _ = kernels.assemble(self._joint_positions(state), self._joint_elements)
        return total + float(e_iso.sum() + e_fib.sum())

    def derivatives(self, state, targets, inertia):
        """(energy J, gradient (r,), Hessian (r, r)) in the Newton unknowns (per domain: the
        move t_d of its centre beyond what its parent's and its own turns carry, m; its turn
        theta_d, rad; its coordinates q_d), at t = theta = 0."""
        E, g, H, _ = self._derivatives(state, targets, inertia)
        return E, g, H

    def _derivatives(self, state, targets, inertia):
        """derivatives(), and N (3 D, r): the moves of the centres per unit move of the tree's
        unknowns, less the identity (framed_kernels.tree_chain)."""
        E, g, H = self._free_derivatives(state, targets, inertia)
        N = np.zeros((3 * len(self.domains), self.r))
        fk.tree_chain(state.R, self._chain, self._arms, self._zc, self._zt, g, H, N)
        return E, g, H, N

    def _free_derivatives(self, state, targets, inertia):
        """(energy J, gradient (r,), Hessian (r, r)) in each domain's centre c_d (m), its turn
        theta_d (rad) about it and its coordinates q_d, at theta = 0."""
        T0, T, t = targets
        g = np.zeros(self.r)
        H = np.zeros((self.r, self.r))
        E = fk.domain_energy(inertia, state.c, state.R, state.q, self._a, self._mass, T0, T, t,
                             self._q0, self._r)
        fk.domain_derivatives(inertia, state.c, state.R, state.q, self._a, self._mass, T0, T,
                              t, self._q0, self._r, self._z0, g, H)
        E += self._polynomials(state.q, g, H)
        x = self._joint_positions(state)
        blocks = np.zeros((self._pairs.shape[0], 3, 3))
        e_iso, e_fib, grad = kernels.assemble(x, self._joint_elements, want_grad=True,
                                              want_hess=True, hess_map=self._joint_map,
                                              hess_data=blocks.reshape(-1))
        fk.joint_derivatives(x, grad, blocks, self._pairs, self._pair_ptr, state.c, state.R,
                             self._joint_rows[0], self._joint_rows[2], self._r, self._z0, g, H)
        return E + float(e_iso.sum() + e_fib.sum()), g, H

    def _polynomials(self, q, g, H):
        return fk.polynomials(q, self._q0, self._r, *self._coefficients, self._z0, g, H)

    def _joint_positions(self, state):
        labels, Y, U, x0 = self._joint_rows
        x = np.empty_like(x0)
        fk.node_positions(state.c, state.R, state.q, state.base, labels, Y, U, x0, self._q0,
                          self._r, x)
        return x

    def retract(self, state, dz, alpha=1.0):
        """The state moved by alpha dz in the Newton unknowns: each R turned by
        exp(alpha [dtheta]), each centre's own move t by alpha dt, the centres carried by the
        turns (FramedModel._plant), q + alpha dq."""
        R = rotations(alpha * dz[self._zt]) @ state.R
        return FramedState(self._centres(self._moves(state) + alpha * dz[self._zc], R,
                                         state.base), R, state.q + alpha * dz[self._zq],
                           state.base)

    def _extrapolated(self, now, before, base):
        """Newton's start for the step after `now`, the held nodes moved to base: each frame
        turned on by its last turn (R_now R_before^T R_now), its own move and q carried on as
        far."""
        R = now.R @ before.R.transpose(0, 2, 1) @ now.R
        fk.nearest_rotations(R)
        return FramedState(self._centres(2 * self._moves(now) - self._moves(before), R, base),
                           R, 2 * now.q - before.q, base)

    def _plant(self, pivots):
        """The kinematic tree (anisofem.reduced.domains.tree): domain e's centre is
        c_e = c_p + R_p a_e + R_e b_e + t_e, p its parent (for the held nodes the base, c_g
        and R_g), a_e its pivot's rest offset from the parent's centre, b_e its centre's from
        its pivot, so that a turn of a domain carries the domains beyond it; t_e, its own
        move, is a Newton unknown. _chain (P, 2) lists (f, d) for each domain f on the path
        from the root to d, and _arms (P, 3) its rest arm v: R_f v is the arm by which f's
        turn moves d's centre."""
        centres = np.array([d.centre for d in self.domains])
        self._arm_parent = pivots - np.where(self.parent[:, None] >= 0,
                                             centres[self.parent], 0.0)
        self._arm_own = centres - pivots
        chain, arms = [], []
        for d in range(len(self.domains)):
            f, below = d, None
            while f >= 0:
                chain.append((f, d))
                arms.append(self._arm_own[f] + (0.0 if below is None
                                                else self._arm_parent[below]))
                f, below = self.parent[f], f
        self._chain = np.array(chain, np.int64)
        self._arms = np.array(arms)
        self._centre_rows = self._zc.ravel()

    def _moves(self, state):
        """(D, 3) each domain's own move t_e (FramedModel._plant) in state, m."""
        t = np.empty_like(state.c)
        fk.tree_centres(self._order, self.parent, self._arm_parent, self._arm_own, state.base,
                        state.R, t, state.c, True)
        return t

    def _centres(self, t, R, base):
        """(D, 3) the centres of own moves t (D, 3) and rotations R (D, 3, 3) with the held
        nodes at base (3, 4), m."""
        c = np.empty_like(t)
        fk.tree_centres(self._order, self.parent, self._arm_parent, self._arm_own, base, R, t,
                        c, False)
        return c

    def _bound(self, dz, N):
        """The largest node move of the step dz in the tree's unknowns, its centres carried
        by N (3 D, r) (_derivatives), bounded per domain, m."""
        moved = dz.copy()
        moved[self._centre_rows] += N @ dz
        return fk.step_bound(moved, self._z0, self._r, self._radius, self._reach)

    def _newton(self, state, targets, inertia, max_iter):
        """Minimize the step's energy from `state` by Newton with a backtracking line search
        (the Hessian's eigenvalues mirrored and floored where it is not positive definite);
        converged when a step moves no node more than STEP_TOLERANCE times the body's size."""
        tolerance = STEP_TOLERANCE * self.size
        bound = math.inf
        for it in range(1, max_iter + 1):
            E, g, H, N = self._derivatives(state, targets, inertia)
            if not (np.isfinite(E) and np.isfinite(g).all() and np.isfinite(H).all()):
                return state, NewtonReport(False, it, bound, "non-finite energy")
            dz = _descent(H, g)
            last, bound = bound, self._bound(dz, N)
            # the step after this one, at the rate of this one's decrease
            if bound <= tolerance or (bound < last < math.inf
                                      and bound * bound / last <= tolerance):
                return _orthonormal(self.retract(state, dz)), NewtonReport(True, it, bound,
                                                                           "converged")
            alpha, slope = 1.0, float(g @ dz)
            while True:
                trial = self.retract(state, dz, alpha)
                if self.energy(trial, targets, inertia) <= E + 1e-4 * alpha * slope:
                    break
                alpha *= 0.5
                if alpha * bound <= tolerance:
                    converged = bound <= 1e3 * tolerance  # round-off: no decrease resolved
                    return state, NewtonReport(converged, it, bound, "converged" if converged
                                               else "line search found no decrease")
            state = trial
        return _orthonormal(state), NewtonReport(False, max_iter, bound,
                                                 f"{max_iter} iterations spent")


def refusal(scene):
    """Why the framed model cannot take a StVK scene (a message naming the field), or None:
    pressures (a cavity's volume spans domains), activated fibers and controls, and nodes held
    along some axes only."""
    if scene.pressures or scene.cables:
        return (f"scene: the framed model does not take "
                f"{'pressures; use ReducedModel' if scene.pressures else 'cables'}")
    if scene.contact is not None:
        return ("scene: the framed model does not take contact (ReducedModel takes obstacles; "
                "the FEM takes them all)")
    if scene.activations or (scene.elements.rest2 != 1.0).any():
        return ("scene: the framed model takes passive fibers (no activation, no activation "
                "control); use ReducedModel")
    partial = scene.fixed_mask.any(axis=1) & ~scene.fixed_mask.all(axis=1)
    if partial.any():
        return (f"fixed: the framed model holds whole nodes; {int(partial.sum())} nodes are "
                f"held along some axes only (rollers)")
    return None


def _descent(H, g):
    """-H^-1 g, by Cholesky, or where H is not positive definite with its eigenvalues
    mirrored and floored at 1e-10 of the largest."""
    try:
        return -sla.cho_solve(sla.cho_factor(H, check_finite=False), g, check_finite=False)
    except np.linalg.LinAlgError:
        lam, V = np.linalg.eigh(H)
        lam = np.maximum(np.abs(lam), 1e-10 * np.abs(lam).max())
        return -V @ ((V.T @ g) / lam)


def rigid_motion(base):
    """base as a (3, 4) [R | c], R a rotation to 1e-9; ValueError naming `base` otherwise."""
    base = as_float_array(base, "base", shape=(3, 4))
    R = base[:, :3]
    if not (np.abs(R @ R.T - np.eye(3)).max() < 1e-9 and np.linalg.det(R) > 0):
        raise ValueError("base: its first 3 columns must be a rotation (orthonormal, det 1)")
    return base


def rotations(theta):
    """exp([theta_d]_x) (D, 3, 3) of rotation vectors theta (D, 3) (Rodrigues' formula)."""
    theta = np.ascontiguousarray(theta, dtype=float)
    out = np.empty((theta.shape[0], 3, 3))
    fk.rodrigues(theta, out)
    return out


def _orthonormal(state):
    """state with each R its nearest rotation (against round-off over many steps)."""
    fk.nearest_rotations(state.R)
    return state


