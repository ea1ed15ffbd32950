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
    fiber:        dP/dkappa = 4 (I4 - 1) F d d^T,

Young's modulus and Poisson's ratio follow by the chain rule through mu(E, nu) and
lam(E, nu). The fiber direction d (unit, in the rest frame) is two angles, d = (cos a cos b,
sin a cos b, sin b): azimuth a about z from x and elevation b toward z (so it stays unit; b =
+-90 degrees is the angles' pole). With h = G_lambda d and u = F d,

    lambda^T dg/dd = 4 kappa (2 (u . h) C d + (I4 - 1) (F^T h + G_lambda^T u)).

A pressure's magnitude p: g holds p dW/dx (anisofem.pressure), so lambda^T dg/dp is lambda
against the cavity's force at unit pressure.
"""
from dataclasses import dataclass

import numpy as np
import scipy.sparse.linalg as spla

from ._validate import as_float_array
from .densities import STVK
from .potential import Potential, check_positions
from .stability import stability

#: The parameter kinds: per element, except pressure (one per Scene.pressures entry).
KINDS = ("young", "poisson", "kappa", "fiber_angles", "pressure")


@dataclass
class Sensitivity:
    """dJ/dp at a static equilibrium: young, poisson, kappa (m,) per element (J per Pa, J);
    fiber_angles (m, 2) per element, d/d(azimuth, elevation) in J per radian; pressure (k,)
    one per scene pressure, J per Pa; adjoint (n, 3) the solution lambda of H lambda = dJ/dx
    (zero on fixed components), m/N times the objective's unit. Sum a per-element array over
    a region's elements for a parameter shared by the region."""
    young: np.ndarray
    poisson: np.ndarray
    kappa: np.ndarray
    fiber_angles: np.ndarray
    pressure: np.ndarray
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
    if not getattr(result, "converged", False):
        raise ValueError("result: the static solve did not converge; its derivative is not "
                         "defined")
    x = check_positions(scene, result.x, "result.x")
    dJ = as_float_array(gradient, "gradient", shape=(scene.mesh.n_vertices, 3))
    potential = Potential(scene)
    verdict = stability(potential, x)
    if not verdict.minimum:
        raise ValueError(f"result: the equilibrium is a saddle (smallest Hessian eigenvalue "
                         f"{verdict.smallest:.3g} N/m); its derivative is not defined")
    layout = scene.layout("csr")
    H = layout.matrix(potential.hessian_data(x, layout, want_grad=False)[2]).tocsc()
    free = scene.free_dofs
    lam = np.zeros(3 * scene.mesh.n_vertices)
    lam[free] = spla.splu(H).solve(dJ.ravel()[free])
    lam = lam.reshape(-1, 3)
    return Sensitivity(*(-s for s in force_derivatives(scene, x, lam)), adjoint=lam)


def force_derivatives(scene, x, lam):
    """lambda^T dg/dp at positions x (n, 3) for a vector lam (n, 3) over the vertices, per
    parameter kind (the module docstring): young, poisson, kappa (m,), fiber_angles (m, 2),
    pressure (k,)."""
    el = scene.elements
    F = np.einsum("eai,eqaj->eqij", x[el.tets], el.grads)              # (m, q, 3, 3)
    Gl = np.einsum("eai,eqaj->eqij", lam[el.tets], el.grads)
    w = el.weights
    C = np.einsum("eqki,eqkj->eqij", F, F)
    stvk = (el.model == STVK)[:, None, None, None]
    E = 0.5 * (C - np.eye(3))
    trE = np.trace(E, axis1=-2, axis2=-1)
    J = np.linalg.det(F)
    safe = np.where(J > 0, J, 1.0)
    FinvT = np.swapaxes(np.linalg.inv(np.where((J > 0)[..., None, None], F, np.eye(3))), -1, -2)
    dP_mu = np.where(stvk, 2.0 * F @ E, F - FinvT)
    dP_lam = np.where(stvk, trE[..., None, None] * F, np.log(safe)[..., None, None] * FinvT)
    s_mu = np.einsum("eq,eqij,eqij->e", w, dP_mu, Gl)
    s_lam = np.einsum("eq,eqij,eqij->e", w, dP_lam, Gl)
    d = el.fiber
    I4m1 = np.einsum("ei,eqij,ej->eq", d, C, d) - 1.0
    u = np.einsum("eqij,ej->eqi", F, d)
    h = np.einsum("eqij,ej->eqi", Gl, d)
    s_kappa = np.einsum("eq,eq,eqi,eqi->e", w, 4.0 * I4m1, u, h)
    g_d = 4.0 * el.kappa[:, None, None] * (
        2.0 * np.einsum("eqi,eqi->eq", u, h)[..., None] * np.einsum("eqij,ej->eqi", C, d)
        + I4m1[..., None] * (np.einsum("eqki,eqk->eqi", F, h)
                             + np.einsum("eqki,eqk->eqi", Gl, u)))
    s_d = np.einsum("eq,eqi->ei", w, g_d)                               # (m, 3)
    a, b = fiber_angles(d).T
    dd = np.stack([np.stack([-np.sin(a) * np.cos(b), np.cos(a) * np.cos(b), 0 * a], axis=1),
                   np.stack([-np.cos(a) * np.sin(b), -np.sin(a) * np.sin(b), np.cos(b)],
                            axis=1)], axis=1)                            # (m, 2, 3)
    s_angles = np.einsum("ei,eki->ek", s_d, dd)
    mu, lam_ = el.mu, el.lam
    E_y = mu * (3 * lam_ + 2 * mu) / (lam_ + mu)
    nu = lam_ / (2 * (lam_ + mu))
    s_young = (mu * s_mu + lam_ * s_lam) / E_y
    s_poisson = (-mu / (1 + nu)) * s_mu + (E_y * (1 + 2 * nu ** 2)
                                           / ((1 + nu) ** 2 * (1 - 2 * nu) ** 2)) * s_lam
    s_pressure = np.zeros(len(scene.pressures))
    for k, cavity in enumerate(scene.pressures):
        unit = np.zeros_like(x)
        cavity.at(1.0).add_gradient(x, unit)
        s_pressure[k] = float(np.sum(unit * lam))
    return s_young, s_poisson, s_kappa, s_angles, s_pressure
