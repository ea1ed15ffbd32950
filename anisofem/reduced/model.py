"""ReducedModel: a scene's motion restricted to x = x0 + U q, stepped in r dimensions.

The basis U (anisofem.reduced.basis) is mass-orthonormal, U^T M U = I with the lumped mass, so
backward Euler minimizes

    1/(2 dt^2) |q - q_hat|^2 + V(q) - f_r . q,   q_hat = q_n + dt v_n,  f_r = U^T f_ext,

and statics V(q) - f_r . q, with V the exact quartic of anisofem.reduced.polynomial. Both by
Newton with the Hessian's negative eigenvalues clamped and a backtracking line search whose
energy decrease is the exact quartic in the step length (no difference of two energies, so
the search ranks points below the energy's round-off).
"""
import copy
import math
import os
import time
import warnings
from dataclasses import dataclass

import numpy as np

from .._validate import as_float_array
from ..physics.densities import STVK
from ..physics.inversion import volume_change
from ..physics.metrics import moving_tip
from ..solvers.newton import InversionWarning
from ..solvers.solve import Stepper, solve
from ..physics.potential import Potential
from ..physics.scene import check_scene
from . import basis as _basis
from . import kernels
from .display import interpolate
from .loads import Loads, default_loads, unseen_cases
from .snapshots import static_states, principal_directions
from .polynomial import build_bytes, polynomial, with_pressure
from .reach import reach
from .contact import ReducedContact
from .controls import (control_parts, control_responses, control_values, controlled,
                       passive)

#: Default number of vibration modes; the basis holds them and their m (m + 1) / 2 modal
#: derivatives, less dependent directions (6 modes: r = 27).
MODES = 6

#: Newton iterations a reduced solve may take by default; with contact more (near a contact
#: starting, clipped steps and friction's stick-slip can take tens).
MAX_ITER, CONTACT_MAX_ITER = 50, 500

#: A free body's (a part of the mesh with no held vertex) lowest vibration modes in the basis,
#: beside its six rigid motions (translations exact; turns to first order).
FREE_BODY_MODES = 3

#: The validation of a model with declared loads: unseen load cases, each held for HOLD_STEPS
#: backward-Euler steps of VALIDATION_DT s from rest and released for as many.
VALIDATION_CASES = 3
HOLD_STEPS = 25
VALIDATION_DT = 0.02

#: Cases drawn per validation case wanted: a drawn case whose full rollout turns elements
#: inside out is left out and the next one taken.
REDRAWS = 3

#: The smallest gradient norm float64 resolves, over eps times the size of the terms summed
#: into it (|H| |q| and the loads).
ROUNDOFF_FACTOR = 1.0


@dataclass
class Validation:
    """The reduced model against the full FEM on cases it was not built from. Static (no
    declared loads): the equilibrium under the scene's loads. Rollouts (declared loads): from
    rest, each of `cases` unseen loads drawn from the declaration held for HOLD_STEPS steps of
    VALIDATION_DT and released for as many. tip_error: the largest |mean displacement
    difference over the tip| over the largest |full tip displacement| of its case (the tip: the
    drag's vertices, else anisofem.physics.metrics.moving_tip of the full answer); field_error: the
    largest vertex displacement difference over the largest full one; full_seconds, the full
    FEM's time; converged, whether every solve of both converged; cases, how many load cases
    (0: the static check); inverted, how many drawn cases were left out (and drawn again)
    because the full FEM turned elements inside out, where StVK is unphysical."""
    tip_error: float
    field_error: float
    full_seconds: float
    converged: bool
    cases: int = 0
    inverted: int = 0


@dataclass
class NewtonReport:
    """How a reduced solve ended: converged, iterations, the final reduced gradient norm
    (N per unit of q), and a message saying why it stopped."""
    converged: bool
    iterations: int
    residual: float
    message: str = ""


class ReducedModel:
    """The reduced model of a scene with the StVK base, with or without fibers.

    Parameters
    ----------
    scene : the Scene (mesh, material, fixed vertices, loads, controls). The basis moves its
        initial positions x0, its external force is projected on the basis and its pressures
        and activated fibers enter the polynomial (exact: a cavity's volume is cubic in the
        positions, an activation adds a quadratic). Its controls (named pressures,
        activations) keep their parts apart (anisofem.reduced.controls): step and solve take
        their values. Loads on load curves are taken as written.
    modes : vibration modes m of the rest Hessian with the lumped mass (default MODES).
    derivatives : add the modes' m (m + 1) / 2 modal derivatives (default: when snapshots is
        0). Linear modes alone do not follow large rotations.
    snapshots : add this many principal directions of the full FEM's static equilibria under
        the declared loads (anisofem.reduced.snapshots): a basis fitted to what the scene does,
        which follows bending through large rotations within the declaration.
    loads : a Loads, what the model must handle beyond the scene's own loads (default, where
        snapshots > 0: anisofem.reduced.loads.default_loads, a drag of up to half the
        body's weight at each free end). Declared loads also make the validation a set of
        unseen rollouts.
    validate : check the model against the full FEM on cases it was not built from
        (validation: the static equilibrium under the scene's loads, or with declared loads
        VALIDATION_CASES short rollouts under unseen loads drawn from them).
    progress : a callable(str) told each stage of the build as it starts, once the arguments
        are checked (None: silent).

    Attributes: basis (3n, r) over all vertex components (0 on fixed ones) in m per unit of q,
    with basis^T M basis = I; frequencies (m,) of the vibration modes, Hz; polynomial (the
    reduced energy, the controls at 0); parts (anisofem.reduced.controls.ControlPart, one per
    control); controls (their names); external (r,) the scene's projected load, N; loads (the
    Loads, or None);
    snapshots (a SnapshotReport, or None); fitted (how many of the r directions are fitted to
    the loads); build_seconds (basis and polynomial, with the snapshots' solves even where
    another model of the scene solved them); validation (a Validation, or None); free_bodies
    (the vertex indices of each part of the mesh with no held vertex: its rigid motions and
    FREE_BODY_MODES lowest modes are columns of the basis); carrying (n,) bool, the vertices of
    the parts that hold a held vertex (step's carried moves them).
    """

    def __init__(self, scene, modes=MODES, derivatives=None, snapshots=0, loads=None,
                 validate=True, progress=None):
        check_polynomial_scene(scene, "reduced model")
        scene.check_static()
        if validate and loads is None and _basis.bodies(scene)[0]:
            raise ValueError("validate: the scene has a part no held vertex holds, whose static "
                             "equilibrium is not unique; build with validate=False and compare "
                             "rollouts with the FEM's (examples/gripper_reduced.py)")
        modes = _count(modes, "modes", 1)
        snapshots = _count(snapshots, "snapshots", 0)
        derivatives = snapshots == 0 if derivatives is None else bool(derivatives)
        if modes >= scene.n_free:
            raise ValueError(f"modes: {modes} modes need more than the scene's {scene.n_free} "
                             f"unknowns")
        if loads is None and snapshots:
            loads = default_loads(scene)
        if loads is not None:
            if not isinstance(loads, Loads):
                raise TypeError(f"loads: expected an anisofem.reduced.Loads, got "
                                f"{type(loads).__name__}")
            loads.check(scene)
            if loads.carry is not None:
                raise ValueError("carry: the linear reduced model holds its held vertices in "
                                 "place; FramedModel carries them (its step's base)")
        _check_memory(scene, modes, derivatives, snapshots)
        say = progress or (lambda stage: None)
        say(f"the {modes} lowest vibration modes"
            + (" and their modal derivatives" if derivatives else ""))
        t0 = time.perf_counter()
        self.scene, self.loads, self.snapshots, self.fitted = scene, loads, None, 0
        self.x0 = scene.initial_positions()
        free = scene.free_dofs
        mass = np.repeat(scene.masses, 3)[free]
        layout = scene.layout("csr")
        potential = Potential(scene)
        K = _basis.free_hessian(potential, self.x0, layout)
        self.free_bodies, self.carrying = _basis.bodies(scene)
        at = np.full(3 * scene.mesh.n_vertices, -1)
        at[free] = np.arange(free.size)
        body_dofs = [d[d >= 0] for d in (at[(3 * v[:, None] + np.arange(3)).ravel()]
                                         for v in self.free_bodies)]
        held = np.ones(free.size, bool)
        for dofs in body_dofs:
            held[dofs] = False
        kept = np.flatnonzero(held)
        factor = _basis.HeldFactor(K, kept, free.size)
        omega2, phi = _basis.vibration_modes(factor.K, factor.lu, mass[kept], modes)
        self.frequencies = np.sqrt(np.maximum(omega2, 0.0)) / (2.0 * math.pi)
        columns = [np.zeros((free.size, modes)), control_responses(scene, self.x0, factor,
                                                                   free)]
        columns[0][kept] = phi
        if derivatives:
            both = _basis.mass_orthonormal(np.hstack(columns), mass)
            columns.append(_basis.modal_derivatives(potential, self.x0, layout, factor, both,
                                                    free))
        for vertices, dofs in zip(self.free_bodies, body_dofs):
            columns.append(_basis.rigid_motions(self.x0, vertices)[free])
            own = np.zeros((free.size, FREE_BODY_MODES))
            own[dofs] = _basis.free_body_modes(K[dofs][:, dofs], mass[dofs], FREE_BODY_MODES)
            columns.append(own)
        U = _basis.mass_orthonormal(np.hstack(columns), mass)
        credit = 0.0  # the static solves' time where another model of this scene ran them
        if snapshots:
            say("the full FEM's static equilibria under the declared loads")
            t1 = time.perf_counter()
            U = self._fit(U, snapshots, mass)
            credit = max(self.snapshots.seconds - (time.perf_counter() - t1), 0.0)
        n = scene.mesh.n_vertices
        self.basis = np.zeros((3 * n, U.shape[1]))
        self.basis[free] = U
        need = build_bytes(U.shape[1], scene.elements.weights.size)
        say(f"the energy's polynomial in r = {U.shape[1]} coordinates (about "
            f"{need / 2 ** 30:.2g} GiB at its peak; its quartic grows as r^4)")
        self._energy_polynomial(scene)
        self.external = self.project(scene.external_force)
        self.contact = (ReducedContact(scene, self.x0, self.basis, self.carrying)
                        if scene.contact is not None else None)
        translation = np.tile(np.eye(3), (n, 1))          # (3n, 3) every vertex by 1 m
        self._carried_mass = self.basis.T @ (
            np.repeat(scene.masses * self.carrying, 3)[:, None] * translation)
        self._free_translation = self.basis.T @ (   # the free bodies' translation's q
            np.repeat(scene.masses * ~self.carrying, 3)[:, None] * translation)
        self.build_seconds = time.perf_counter() - t0 + credit
        if validate:
            say("its validation against the full FEM")
        self.validation = self.validate() if validate else None

    def _fit(self, U, count, mass):
        """U (free unknowns, k; mass-orthonormal) with up to `count` principal directions of the
        full FEM's static equilibria under the declared loads added (snapshots, fitted)."""
        free = self.scene.free_dofs
        held = (self.scene.holding(np.concatenate(self.free_bodies)) if self.free_bodies
                else self.scene)   # a free body's equilibrium is not unique
        states, self.snapshots = static_states(held, self.loads)
        report = self.snapshots
        if report.inverted or report.failed:
            warnings.warn(
                f"reduced model: of the {report.kept + report.inverted + report.failed} static "
                f"snapshots, {report.inverted} turned elements inside out and {report.failed} "
                f"did not converge, and were left out (StVK's energy there is unphysical): the "
                f"fitted directions stand on {report.kept}. The declared loads fold this body; "
                f"solve the scene with Material(..., model='neohookean') to see what it does",
                InversionWarning, stacklevel=3)
        displacements = (states - self.x0).reshape(len(states), -1)[:, free].T
        fitted = principal_directions(displacements, mass, count, against=U)
        both = _basis.mass_orthonormal(np.hstack([U, fitted]), mass)
        self.fitted = both.shape[1] - U.shape[1]
        return both

    def with_material(self, material):
        """The same model (basis, loads) with the energy of another Material of the same
        densities: what a design or control loop evaluates at fixed basis (the polynomial
        rebuilt, no eigen-solve, no validation)."""
        moved = copy.copy(self)
        moved.scene = self.scene.with_material(material)
        if (moved.scene.elements.model != STVK).any():
            raise ValueError("material: the reduced model needs the StVK base material")
        moved._energy_polynomial(moved.scene)
        moved.validation = None
        moved.__dict__.pop("_stiffness_parts", None)  # reduced.sensitivity's, of the old one
        return moved

    def _energy_polynomial(self, scene):
        """Set polynomial (the energy with the controls at 0) and parts (each control's)."""
        unset = passive(scene)
        self.polynomial = with_pressure(polynomial(unset.elements, self.x0, self.basis),
                                        [p for p in unset.pressures if not p.name], self.x0,
                                        self.basis)
        self.parts = control_parts(scene, self.x0, self.basis)
        self.controls = tuple(p.name for p in self.parts)

    def control_values(self, values=None):
        """(k,) the controls' values: as the scene wrote them, replaced by values (a mapping
        name -> value or one value per control, in the order of `controls`)."""
        return control_values(self.parts, values)

    def energy_at(self, values=None):
        """(the energy's Polynomial, [(CablePart, tension)] of the cables pulled) with the
        controls at values (control_values): a cable's part is not a polynomial."""
        if not self.parts:
            return self.polynomial, []
        values = self.control_values(values)
        return (controlled(self.polynomial, self.parts, values),
                [(part, value) for part, value in zip(self.parts, values)
                 if part.kind == "tension" and value > 0])

    def reach(self, effector, target, bounds=None, tolerance=None, controls=None, q0=None):
        """The controls within bounds that bring `effector` (a vertex index, or a rest point
        (3,) m) to `target` (3,), m, at static equilibrium: an anisofem.reduced.reach.Reach
        (controls, q, position, distance, reached, message). bounds: a mapping name -> (low,
        high) over the ranges the model was built for; controls, q0: where to start (a
        previous answer's controls and q, in a control loop)."""
        return reach(self, effector, target, bounds, tolerance, controls, q0)

    def validate(self, cases=None, seed=0):
        """The model against the full FEM on cases it was not built from (a Validation): with
        declared loads, `cases` (default VALIDATION_CASES) short rollouts under unseen loads
        drawn from them with `seed`; else the static equilibrium under the scene's loads (None
        where the full answer does not move)."""
        if self.loads is not None:
            cases = VALIDATION_CASES if cases is None else _count(cases, "cases", 1)
            return validate_rollouts(self, unseen_cases(self.scene, self.loads, REDRAWS * cases,
                                                          seed), cases)
        t0 = time.perf_counter()
        full = solve(self.scene, warn=False)
        seconds = time.perf_counter() - t0
        u = full.x - self.x0
        if not np.abs(u).max() > 0:
            return None
        q, report = self.solve()
        d = self.positions(q) - full.x
        tip = moving_tip(u)
        return Validation(
            float(np.linalg.norm(d[tip].mean(0)) / np.linalg.norm(u[tip].mean(0))),
            float(np.linalg.norm(d, axis=1).max() / np.linalg.norm(u, axis=1).max()), seconds,
            bool(full.converged and report.converged))

    def rollout(self, phases, dt):
        """Positions (k + 1, n, 3) from rest through phases ((extra nodal force (n, 3) N or
        None, steps[, controls {name: value}]), ...) of dt s, and whether every step
        converged."""
        q, w = np.zeros(self.r), np.zeros(self.r)
        xs, ok = [self.positions(q)], True
        for force, steps, *controls in phases:
            for _ in range(steps):
                q, w, report = self.step(q, w, dt, force=force,
                                         controls=controls[0] if controls else None)
                ok &= report.converged
                xs.append(self.positions(q))
        return np.array(xs), ok

    @property
    def r(self):
        """Number of reduced coordinates."""
        return self.basis.shape[1]

    def positions(self, q, shift=None):
        """Full positions x0 + U q, (n, 3) in m, of reduced coordinates q (r,), the parts that
        hold the held vertices moved by shift (3,), m (step's carried)."""
        x = self.x0 + (self.basis @ q).reshape(-1, 3)
        return x if shift is None else x + self.carrying[:, None] * shift

    def basis_at(self, points):
        """The basis at rest points (p, 3), m, of the same body (the vertices of a coarser
        display mesh), interpolated in the tets holding them: (p, 3, r), so that those points
        move to points + basis_at(points) @ q (anisofem.reduced.display)."""
        return interpolate(self.scene.mesh, self.basis, points)

    def project(self, force):
        """The reduced force U^T f (r,) of nodal forces f (n, 3) in N (finite)."""
        f = as_float_array(force, "force", shape=(self.scene.mesh.n_vertices, 3))
        return self.basis.T @ f.ravel()

    def energy(self, q, controls=None):
        """The energy V(q), J: elastic, with the pressures', activations' and cables'
        (controls: see control_values)."""
        P, pulled = self.energy_at(controls)
        return P.energy(q) + sum(T * part.length(q) for part, T in pulled)

    def force(self, q, hessian=False, controls=None):
        """dV/dq (r,) in N (U^T of the full gradient of the elastic and actuators' energy at
        x0 + U q), and with hessian=True also d2V/dq2 (r, r) in N/m."""
        P, pulled = self.energy_at(controls)
        g, H = P.gradient(q, True) if hessian else (P.gradient(q), None)
        for part, T in pulled:
            g = g + T * part.slope(q)
            if hessian:
                H = H + T * part.hessian(q)
        return (g, H) if hessian else g

    def solve(self, force=None, q0=None, rtol=1e-8, max_iter=None, controls=None):
        """The static equilibrium under the scene's loads plus nodal forces `force` (n, 3), N,
        with controls (see control_values), from q0 (default 0), in at most max_iter Newton
        iterations (default MAX_ITER, CONTACT_MAX_ITER with contact): returns (q,
        NewtonReport)."""
        q = np.zeros(self.r) if q0 is None else as_float_array(q0, "q0", shape=(self.r,))
        load = self._load(force)
        return self._newton(controls, load, q, None, 0.0, rtol * _norm(load), rtol, max_iter)

    def step(self, q, v, dt, force=None, rtol=1e-8, max_iter=None, controls=None,
             carried=None):
        """One backward-Euler step of dt s from the reduced state (q, v) under the scene's
        loads plus nodal forces `force` (n, 3), N, with the controls at the step's end set to
        `controls` (a mapping name -> value or one value per control; None: as the scene
        wrote them), in at most max_iter Newton iterations (as solve): returns (q_next, v_next,
        NewtonReport). carried: the held vertices moved
        by a translation, (its value (3,) m at the step before, at this step's start, at its
        end): the parts that hold them go with it (positions(q, shift) at the end's), the
        step in their moving frame with its inertia (a translation strains nothing)."""
        if not dt > 0:
            raise ValueError(f"dt: the time step must be > 0 s, got {dt}")
        q_hat = q + dt * v
        load = self._load(force)
        shift = lag_shift = None
        if carried is not None:
            before, lag_shift, shift = (as_float_array(c, "carried", shape=(3,))
                                        for c in carried)
            load = load - self._carried_mass @ ((shift - 2.0 * lag_shift + before) / dt ** 2)
        q_next, report = self._newton(controls, load, q_hat.copy(), q_hat, 1.0 / dt ** 2,
                                      rtol * (_norm(load) + _norm(v) / dt), rtol, max_iter,
                                      q_start=q, shift=shift, lag_shift=lag_shift)
        return q_next, (q_next - q) / dt, report

    def _load(self, force):
        return self.external if force is None else self.external + self.project(force)

    def _newton(self, controls, load, q, q_hat, inertia, tolerance, rtol, max_iter,
                q_start=None, shift=None, lag_shift=None):
        """Minimize V(q) - load . q + inertia |q - q_hat|^2 / 2, V the energy under controls,
        from q (inertia 1/dt^2, or 0 for statics) to a gradient norm of tolerance + rtol
        |dV/dq(q)| (N: rtol times the problem's force size) or the round-off floor
        (anisofem.reduced.kernels.newton; with cables pulled or contact, extra_newton). A step
        starts at q_start (its friction lagged there, the carried vertices then moved by
        lag_shift; q moved back toward it as far as the contact asks); shift: where the
        carried vertices are (3,), m."""
        if max_iter is None:
            max_iter = MAX_ITER if self.contact is None else CONTACT_MAX_ITER
        P, pulled = self.energy_at(controls)
        extras = [Pulled(part, T) for part, T in pulled]
        if self.contact is not None:
            if q_start is None:
                extras += self.contact.touching(shift=shift)
            else:
                touching = self.contact.touching(q_start, 1.0 / math.sqrt(inertia), shift,
                                                 lag_shift)
                start = q_start
                if shift is not None and np.any(shift != lag_shift):
                    # the whole mesh translated with the carried move (the free bodies too):
                    # no distance between its parts changes, only the obstacles are tested
                    start = q_start + self._free_translation @ (shift - lag_shift)
                    if min(t.moved_share(q_start, lag_shift, start) for t in touching) < 1.0:
                        return q_start, NewtonReport(False, 0, math.inf, CARRIED_INTO_CONTACT)
                share = min(t.limit(start, q - start) for t in touching)
                q = start + share * (q - start)
                extras += touching
        q_hat = q if q_hat is None else q_hat
        if extras:
            return extra_newton(P, extras, load, q, q_hat, inertia, tolerance, rtol, max_iter)
        q, iterations, residual, status = kernels.newton(
            P.c1, P.C2, P.S3.reshape(self.r ** 2, self.r), P.W4, load, q,
            q_hat, inertia, tolerance, rtol, ROUNDOFF_FACTOR, max_iter)
        return q, NewtonReport(status == kernels.CONVERGED, iterations, residual,
                               _MESSAGES[status].format(max_iter))


class Pulled:
    """A pulled cable as an extra term of a reduced solve: T L(q) on its CablePart."""

    def __init__(self, part, tension):
        self.part, self.tension = part, tension

    def gradient(self, q):
        """T dL/dq (r,), N."""
        return self.tension * self.part.slope(q)

    def hessian(self, q):
        """(T d2L/dq2 (r, r) N/m, 0: no round-off floor of its own)."""
        return self.tension * self.part.hessian(q), 0.0

    def change(self, q, step):
        """T (L(q + step) - L(q)), free of the difference's cancellation."""
        return self.tension * self.part.change(q, step)

    def limit(self, q, p):
        return 1.0


def extra_newton(P, extras, load, q, q_hat, inertia, tolerance, rtol, max_iter):
    """ReducedModel._newton with terms beside the polynomial (pulled cables, Pulled; contact,
    anisofem.reduced.contact.Touching: each with gradient, hessian, change and limit):
    Newton with the Hessian's negative eigenvalues clamped and a backtracking Armijo search
    on the energy along the step, its polynomial part the exact quartic in the step length
    (as kernels.newton) and each term's change, from the share of the step the terms allow
    (contact: no surface node reaches an obstacle on the way)."""
    r = q.size
    S3 = P.S3.reshape(r * r, r)
    A = kernels.matvec(P.W4, q)
    eps = np.finfo(float).eps
    residual, status = math.inf, kernels.SPENT
    for it in range(max_iter + 1):
        g, H = kernels.derivatives(P.c1, P.C2, S3, A, q, inertia)
        extra_g = sum((term.gradient(q) for term in extras), np.zeros(r))
        if it == 0:
            tolerance += rtol * _norm(g + extra_g)
        g = g + extra_g - load + inertia * (q - q_hat)
        residual = _norm(g)
        if not math.isfinite(residual):
            status = kernels.NOT_FINITE
            break
        if residual <= tolerance:   # the terms' Hessians only where the step needs them
            status = kernels.CONVERGED
            break
        extra_H, floor = np.zeros((r, r)), 0.0
        for term in extras:
            term_H, term_floor = term.hessian(q)
            extra_H += term_H
            floor = max(floor, term_floor)
        terms = np.abs(H + extra_H) @ np.abs(q) + np.abs(load) + np.abs(P.c1)
        floor = max(floor, ROUNDOFF_FACTOR * eps * r * _norm(terms))
        if residual <= max(tolerance, floor):
            status = kernels.CONVERGED
            break
        if it == max_iter:
            break
        p = -kernels.positive_solve(H + extra_H, g)
        a1 = float(g @ p)
        if not a1 < 0:
            status = kernels.NO_DESCENT
            break
        a2 = 0.5 * float(p @ H @ p)                      # the quartic's part (with inertia)
        Ap = kernels.matvec(P.W4, p)
        mixed, a4 = kernels.cubic_forms(A, Ap, p)
        a3 = float(p @ (S3 @ p).reshape(r, r) @ p) + 4.0 * mixed
        pull = float(extra_g @ p)
        t = min([1.0] + [term.limit(q, p) for term in extras])
        while t >= kernels.MIN_STEP:
            change = sum(term.change(q, t * p) for term in extras)
            if (t * (a2 + t * (a3 + t * a4)) + (change / t - pull)
                    <= -(1.0 - kernels.ARMIJO) * a1):
                break
            t *= 0.5
        if t < kernels.MIN_STEP:
            status = kernels.NO_DESCENT
            break
        q, A = q + t * p, A + t * Ap
    return q, NewtonReport(status == kernels.CONVERGED, it, residual,
                           _MESSAGES[status].format(max_iter))


#: A step's report where the carried move (the whole mesh translated) alone brings the body
#: into an obstacle (a move no solve can undo).
CARRIED_INTO_CONTACT = "the carried move drives the body into an obstacle"

_MESSAGES = {kernels.CONVERGED: "converged", kernels.SPENT: "{} iterations spent",
             kernels.NO_DESCENT: "line search found no decrease",
             kernels.NOT_FINITE: "non-finite force"}


def validate_rollouts(model, drawn, cases):
    """A reduced model's Validation over rollouts of the first `cases` of `drawn` [(drag index or
    None, extra force (n, 3), base (t -> (3, 4)) or None, controls {name: value})] whose full
    rollout turns no element inside out (each case's loads and controls held, then released to
    the scene's own): `model` has scene, x0, loads and rollout(phases, dt[, base]) ->
    (positions (k + 1, n, 3), converged). Displacements are taken from where the base carries
    the rest shape."""
    tip_error = field_error = seconds = 0.0
    converged, used, inverted = True, 0, 0
    zero = np.zeros_like(model.x0)
    for which, force, base, controls in drawn:
        if used == cases:
            break
        phases = ((force, HOLD_STEPS, controls), (zero, HOLD_STEPS, {}))
        t0 = time.perf_counter()
        full, full_ok = full_rollout(model.scene, phases, VALIDATION_DT, base)
        seconds += time.perf_counter() - t0
        if any((volume_change(model.scene.mesh, x) <= -1.0).any() for x in full):
            inverted += 1
            continue
        used += 1
        extra = () if base is None else (base,)
        reduced, reduced_ok = model.rollout(phases, VALIDATION_DT, *extra)
        converged &= full_ok and reduced_ok
        u, d = full - carried(model.x0, base, len(full), VALIDATION_DT), reduced[:len(full)] - full
        size = np.linalg.norm(u, axis=2)
        tip = (np.asarray(model.loads.drags[which].vertices) if which is not None
               else moving_tip(u[int(np.argmax(size.max(axis=1)))]))
        tip_u = np.linalg.norm(u[:, tip].mean(axis=1), axis=1).max()
        if not tip_u > 0:   # a case that does not move the body: nothing to compare
            continue
        tip_error = max(tip_error, float(np.linalg.norm(d[:, tip].mean(axis=1),
                                                        axis=1).max() / tip_u))
        field_error = max(field_error, float(np.linalg.norm(d, axis=2).max() / size.max()))
    return Validation(tip_error if used else math.nan, field_error if used else math.nan,
                      seconds, bool(converged), used, inverted)


def moved(x, base):
    """Positions x (n, 3), m, moved by the rigid motion base (3, 4) [R_g | c_g]."""
    return x @ base[:, :3].T + base[:, 3]


def carried(x0, base, count, dt):
    """(count, n, 3) the rest positions x0 carried by base (t -> (3, 4)) at steps 0 .. count - 1
    of dt s (x0 each step where base is None)."""
    if base is None:
        return np.broadcast_to(x0, (count,) + x0.shape)
    return np.array([moved(x0, base(k * dt)) for k in range(count)])


def full_rollout(scene, phases, dt, base=None):
    """The full FEM's positions (k + 1, n, 3) from rest through phases ((extra nodal force (n,
    3) N, steps[, controls {name: value}]), ...) of dt s, exact backward Euler, the held
    vertices carried by base (t -> (3, 4) [R_g | c_g], or None), and whether every step
    converged (a failed step ends the rollout there): what ReducedModel.rollout is compared
    with."""
    x = scene.initial_positions()
    v = np.zeros_like(x)
    xs = [x]
    k = 0
    for force, steps, *controls in phases:
        loaded = scene.plus_force(force)
        if controls and controls[0]:
            loaded = loaded.with_controls(controls[0])
        stepper = Stepper(loaded, dt, warn=False)
        for _ in range(steps):
            k += 1
            if base is not None:
                stepper.scene = loaded.held_at(moved(scene.mesh.vertices, base(k * dt)))
            result = stepper(x, v)
            if result.newton.failed:
                return np.array(xs), False
            x, v = result.x, result.v
            xs.append(x)
    return np.array(xs), True


def check_polynomial_scene(scene, model):
    """TypeError unless scene is a Scene; ValueError unless every element has the StVK base,
    whose energy is a polynomial in a reduced model's coordinates (`model` names the
    model)."""
    check_scene(scene)
    if (scene.elements.model != STVK).any():
        raise ValueError(f"scene: the {model} needs the StVK base material (its energy is a "
                         f"polynomial in the reduced coordinates); this scene has Neo-Hookean "
                         f"elements")


def _count(value, name, smallest):
    """value as an int >= smallest, or ValueError naming `name`."""
    if not isinstance(value, (int, np.integer)) or isinstance(value, bool) or value < smallest:
        raise ValueError(f"{name}: expected an integer >= {smallest}, got {value!r}")
    return int(value)


def coordinates(modes, derivatives, unknowns, snapshots=0):
    """The most reduced coordinates of a basis of `modes` vibration modes (with their modal
    derivatives, or not) and `snapshots` principal directions on `unknowns` free components."""
    return min(modes + (modes * (modes + 1) // 2 if derivatives else 0) + snapshots, unknowns)


def _available_bytes():
    """Memory the system can give without swapping (/proc/meminfo's MemAvailable; else the free
    physical pages), or None where neither is known."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    try:
        return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (AttributeError, ValueError, OSError):
        return None


def _check_memory(scene, modes, derivatives, snapshots):
    """ValueError, before any work, when the polynomial of `modes` modes would not fit in the
    memory available now (polynomial.build_bytes), naming the estimate and the most modes that
    would fit."""
    available = _available_bytes()
    points = scene.elements.weights.size

    def need(m):
        return build_bytes(coordinates(m, derivatives, scene.n_free, snapshots), points)
    if available is None or need(modes) <= available:
        return
    fits = max((m for m in range(1, modes) if need(m) <= available), default=0)
    r = coordinates(modes, derivatives, scene.n_free, snapshots)
    raise ValueError(f"modes: {modes} modes make a basis of up to {r} coordinates, whose "
                     f"polynomial needs about {need(modes) / 2 ** 30:.3g} GiB to build (its "
                     f"quartic term grows as r^4) and this machine has "
                     f"{available / 2 ** 30:.3g} GiB available; "
                     + (f"at most {fits} modes fit" if fits else "not even 1 mode fits"))


def _norm(v):
    return math.sqrt(float(np.dot(v, v)))
