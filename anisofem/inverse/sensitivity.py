"""Exact derivatives of a static equilibrium with respect to the scene's parameters (adjoint).

At an equilibrium g(x, p) = dG/dx = 0 of the static potential, an objective J(x) changes with
the parameters p as

    dJ/dp = -lambda^T dg/dp,   H lambda = dJ/dx   (H: the true Hessian over the free unknowns),

one more linear solve with the Hessian at the answer. dg/dp is hand-derived here per parameter
kind, per element: with G_lambda = sum_a lambda_a grad N_a^T at each quadrature point (the
adjoint's "deformation gradient"), lambda^T dg/dp_e = sum_q w_q dP/dp_e (F_q) : G_lambda,q,
P the first Piola stress. Every energy here is linear in mu, lam and kappa, so

    StVK:         dP/dmu = 2 F E,          dP/dlam = tr(E) F,
    Neo-Hookean:  dP/dmu = F - F^-T,       dP/dlam = ln J F^-T,
    fiber:        dP/dkappa = 4 (I4 - s^2) F d d^T   (s = 1 - a: the fibers' rest stretch),
    activation:   dP/da = 8 kappa (1 - a) F d d^T,

Young's modulus and Poisson's ratio follow by the chain rule through mu(E, nu) and
lam(E, nu). The fiber direction d (unit, in the rest frame) is two angles, d = (cos a cos b,
sin a cos b, sin b): azimuth a about z from x and elevation b toward z (so it stays unit; b =
+-90 degrees is the angles' pole). With h = G_lambda d and u = F d,

    lambda^T dg/dd = 4 kappa (2 (u . h) C d + (I4 - s^2) (F^T h + G_lambda^T u)).

A pressure's magnitude p: g holds p dW/dx (anisofem.physics.pressure), so lambda^T dg/dp is lambda
against the cavity's force at unit pressure; a cable's tension T: g holds T dL/dx
(anisofem.physics.cables), so lambda^T dg/dT is lambda against dL/dx.
"""
from dataclasses import dataclass, fields

import numpy as np

from ..solvers import linsolve
from .._validate import as_float_array
from ..physics.densities import STVK
from ..physics.material import lame_slopes
from ..physics.potential import Potential, check_positions
from ..solvers.stability import stability

#: The parameter kinds: per element, except pressure (one per Scene.pressures entry) and
#: tension (one per Scene.cables entry).
KINDS = ("young", "poisson", "kappa", "fiber_angles", "pressure", "activation", "tension")


@dataclass
class Sensitivity:
    """dJ/dp at a static equilibrium: young, poisson, kappa (m,) per element (J per Pa, J);
    fiber_angles (m, 2) per element, d/d(azimuth, elevation) in J per radian;
    fiber_direction (m, 3) per element, d/dd of the direction taken as free (its part along d
    is no change of a unit direction; any other parametrization chains through it); pressure (k,)
    one per scene pressure, J per Pa; activation (m,) per element, J per unit activation (at
    the scene's activations: a fiber's rest stretch s = 1 - a); tension (c,) one per cable, J
    per N; adjoint (n, 3) the solution
    lambda of H lambda = dJ/dx
    (zero on fixed components), m/N times the objective's unit. Sum a per-element array over
    a region's elements for a parameter shared by the region."""
    young: np.ndarray
    poisson: np.ndarray
    kappa: np.ndarray
    fiber_angles: np.ndarray
    fiber_direction: np.ndarray
    pressure: np.ndarray
    activation: np.ndarray
    tension: np.ndarray
    adjoint: np.ndarray


def fiber_angles(d):
    """(azimuth, elevation) (m, 2) in radians of unit directions d (m, 3)."""
    d = np.atleast_2d(d)
    return np.stack([np.arctan2(d[:, 1], d[:, 0]), np.arcsin(np.clip(d[:, 2], -1, 1))], axis=1)


def fiber_direction(angles):
    """Unit directions (m, 3) of (azimuth, elevation) angles (m, 2), radians."""
    a, b = np.atleast_2d(angles).T
    return np.stack([np.cos(a) * np.cos(b), np.sin(a) * np.cos(b), np.sin(b)], axis=1)


def static_sensitivity(scene, result, gradient):
    """The Sensitivity of an objective J(x) at the static equilibrium result (the NewtonResult of
    anisofem.solve on scene), whose gradient dJ/dx (n, 3) is given (components on fixed
    vertices are ignored: those do not move with the parameters).

    Refused (ValueError) where the solve did not converge or stopped at a saddle: the
    derivative is not defined there. One factorization of the true Hessian at the answer."""
    dJ = as_float_array(gradient, "gradient", shape=(scene.mesh.n_vertices, 3))
    rows = static_jacobian(scene, result, dJ[None])
    return Sensitivity(*(getattr(rows, f.name)[0] for f in fields(Sensitivity)))


def static_jacobian(scene, result, gradients):
    """static_sensitivity of several objectives at once, gradients (r, n, 3): one
    factorization and the state's terms once, then r back-substitutions; a Sensitivity whose
    arrays have a leading axis r (the rows of a Jacobian, as a least-squares fit wants) and
    adjoint (r, n, 3)."""
    x = _converged(scene, result, "result")
    dJ = as_float_array(gradients, "gradients", shape=(None, scene.mesh.n_vertices, 3))
    solve = _definite(Potential(scene), x, "result")
    terms = _StateTerms(scene, x)
    free = ~scene.fixed_mask
    rows, adjoints = [], np.zeros_like(dJ)
    for k in range(dJ.shape[0]):
        adjoints[k][free] = solve(dJ[k][free])
        rows.append([-s for s in terms.contract(adjoints[k])])
    return Sensitivity(*(np.array(kind) for kind in zip(*rows)), adjoint=adjoints)


def rollout_sensitivity(scene, rollout, gradients, dt):
    """The Sensitivity of J = sum_k j_k(x_k) over a backward-Euler rollout (the Rollout of
    anisofem.simulate on scene with step dt, s, from a start that does not depend on the
    parameters), given gradients (k + 1, n, 3), dj_k/dx_k at each state (zero where a state
    does not count). Its adjoint is the first step's.

    Step k solves g_k = M (x_k+1 - 2 x_k + x_k-1) / dt^2 + dPsi/dx(x_k+1) - f = 0, so the
    adjoint runs backward from the last step: H_k+1 mu_k = dj_k+1/dx + M (2 mu_k+1 - mu_k+2)
    / dt^2, with H_k+1 the step's true Hessian at x_k+1, and dJ/dp = -sum_k mu_k^T dg_k/dp.
    One factorization per step. Refused where a step did not converge or its Hessian is not
    positive definite."""
    if not getattr(rollout, "converged", False):
        raise ValueError("rollout: a step did not converge (or the rollout stopped early); "
                         "its derivative is not defined")
    positions = np.asarray(rollout.positions)
    steps = len(positions) - 1
    dJ = as_float_array(gradients, "gradients", shape=(steps + 1,) + positions.shape[1:])
    free = ~scene.fixed_mask
    inertia = (scene.masses[:, None] * np.ones(3))[free] / dt ** 2
    later, latest = np.zeros(free.sum()), np.zeros(free.sum())   # mu_k+1, mu_k+2
    totals, first = None, None
    for k in reversed(range(steps)):
        now = scene.at((k + 1) * dt)
        x = positions[k + 1]
        step = Potential(now, x, dt)
        mu = _definite(step, x, f"rollout step {k}")(dJ[k + 1][free] + inertia
                                                     * (2.0 * later - latest))
        full = np.zeros_like(x)
        full[free] = mu
        parts = _StateTerms(now, x, scene).contract(full)
        totals = [-s for s in parts] if totals is None else [t - s for t, s in
                                                              zip(totals, parts)]
        later, latest, first = mu, later, full
    if totals is None:
        raise ValueError("rollout: it holds no step")
    return Sensitivity(*totals, adjoint=first)


def _converged(scene, result, name):
    if not getattr(result, "converged", False):
        raise ValueError(f"{name}: the static solve did not converge; its derivative is not "
                         f"defined")
    return check_positions(scene, result.x, f"{name}.x")


def _definite(potential, x, name):
    """The solve of the true Hessian of potential at x over the free unknowns (a function of
    the right-hand side), refused where it is not positive definite: a saddle."""
    layout = potential.scene.layout("csr")
    data = potential.hessian_data(x, layout, want_grad=False)[2]
    try:
        return linsolve.SuperLU().factor(layout, data,
                                         potential.coupled_hessian(x, layout))
    except linsolve.FactorizationError:
        verdict = stability(potential, x)
        raise ValueError(f"{name}: the Hessian there is not positive definite (smallest "
                         f"eigenvalue {verdict.smallest:.3g} N/m: a saddle, or a singular "
                         f"state); the derivative is not defined") from None


def _unit_force(load, value, written, x):
    """(n, 3) the gradient at x of a load (a CavityLoad or a CableLoad, linear in its value)
    per unit of the value as written: the load at value / written (1 where written is 0)."""
    unit = np.zeros_like(x)
    load.at(value / written if written else 1.0).energy(x, unit)
    return unit


class _StateTerms:
    """What lambda^T dg/dp needs of a state x (n, 3), computed once: each quadrature point's F,
    C, dP/dmu, dP/dlam and fiber terms, and each pressure's force at unit magnitude. written:
    the scene as written, where `scene` is it at a time of its load curves (Scene.at):
    pressures are parameters of the written scene."""

    def __init__(self, scene, x, written=None):
        el = self.el = scene.elements
        F = self.F = np.einsum("eai,eqaj->eqij", x[el.tets], el.grads)       # (m, q, 3, 3)
        C = self.C = np.einsum("eqki,eqkj->eqij", F, F)
        stvk = (el.model == STVK)[:, None, None, None]
        E = 0.5 * (C - np.eye(3))
        trE = np.trace(E, axis1=-2, axis2=-1)
        J = np.linalg.det(F)
        safe = np.where(J > 0, J, 1.0)
        FinvT = np.swapaxes(np.linalg.inv(np.where((J > 0)[..., None, None], F, np.eye(3))),
                            -1, -2)
        self.dP_mu = np.where(stvk, 2.0 * F @ E, F - FinvT)
        self.dP_lam = np.where(stvk, trE[..., None, None] * F,
                               np.log(safe)[..., None, None] * FinvT)
        d = el.fiber
        self.I4m1 = np.einsum("ei,eqij,ej->eq", d, C, d) - el.rest2[:, None]   # I4 - s^2
        self.u = np.einsum("eqij,ej->eqi", F, d)
        self.Cd = np.einsum("eqij,ej->eqi", C, d)
        a, b = fiber_angles(d).T
        self.dd = np.stack([np.stack([-np.sin(a) * np.cos(b), np.cos(a) * np.cos(b), 0 * a],
                                     axis=1),
                            np.stack([-np.cos(a) * np.sin(b), -np.sin(a) * np.sin(b),
                                      np.cos(b)], axis=1)], axis=1)          # (m, 2, 3)
        as_written = written or scene
        self.units = [_unit_force(cavity, cavity.magnitude, now.magnitude, x) for cavity, now
                      in zip(scene.pressures, as_written.pressures)]
        self.cable_units = [_unit_force(cable, cable.tension, now.tension, x) for cable, now
                            in zip(scene.cables, as_written.cables)]

    def contract(self, lam):
        """(young, poisson, kappa (m,), fiber_angles (m, 2), fiber_direction (m, 3), pressure
        (k,), activation (m,), tension (c,)): lambda^T dg/dp for lam (n, 3)."""
        el, w = self.el, self.el.weights
        Gl = np.einsum("eai,eqaj->eqij", lam[el.tets], el.grads)
        s_mu = np.einsum("eq,eqij,eqij->e", w, self.dP_mu, Gl)
        s_lam = np.einsum("eq,eqij,eqij->e", w, self.dP_lam, Gl)
        h = np.einsum("eqij,ej->eqi", Gl, el.fiber)
        s_kappa = np.einsum("eq,eq,eqi,eqi->e", w, 4.0 * self.I4m1, self.u, h)
        s_activation = 8.0 * el.kappa * np.sqrt(el.rest2) * np.einsum("eq,eqi,eqi->e", w,
                                                                      self.u, h)
        g_d = 4.0 * el.kappa[:, None, None] * (
            2.0 * np.einsum("eqi,eqi->eq", self.u, h)[..., None] * self.Cd
            + self.I4m1[..., None] * (np.einsum("eqki,eqk->eqi", self.F, h)
                                      + np.einsum("eqki,eqk->eqi", Gl, self.u)))
        s_d = np.einsum("eq,eqi->ei", w, g_d)                                # (m, 3)
        s_young, s_poisson = lame_slopes(el.mu, el.lam, s_mu, s_lam)
        return (s_young, s_poisson, s_kappa, np.einsum("ei,eki->ek", s_d, self.dd), s_d,
                np.array([float(np.sum(unit * lam)) for unit in self.units]), s_activation,
                np.array([float(np.sum(unit * lam)) for unit in self.cable_units]))
