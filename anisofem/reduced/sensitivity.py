"""Exact gradients of a reduced model's backward-Euler rollout with respect to the body's
stiffnesses (Young's modulus, Poisson's ratio, the fiber stiffness kappa, each scaled over the
whole body), at r^4 a step.

Every coefficient of the reduced energy (anisofem.reduced.polynomial) is linear in each
element's mu, lam and kappa, so the polynomial of dV/dmu (and of dV/dlam, dV/dkappa) is the
difference of two builds, one with the stiffness doubled, over it: exact up to round-off.
Young's modulus scales mu and lam together; Poisson's ratio moves them by the chain rule.

The reduced step k solves g_k = (q_k+1 - 2 q_k + q_k-1) / dt^2 + dV/dq(q_k+1) - f = 0 (the
basis is mass-orthonormal), so the adjoint runs backward as the full FEM's does
(anisofem.inverse.sensitivity.rollout_sensitivity):

    H_k+1 mu_k = dj_k+1/dq + (2 mu_k+1 - mu_k+2) / dt^2,    dJ/dp = -sum_k mu_k . dV_p/dq(q_k+1),

with H_k+1 = I / dt^2 + d2V/dq2(q_k+1), r x r.
"""
import dataclasses

import numpy as np

from .._validate import as_float_array
from ..physics.material import lame_slopes
from .polynomial import polynomial

#: The whole-body stiffnesses a reduced rollout's gradient is taken for.
STIFFNESSES = ("young", "poisson", "kappa")


def stiffness_polynomials(model):
    """{"mu", "lam", "kappa": the Polynomial of dV/ds, s scaling that stiffness of every element
    by (1 + s) (None where it is zero everywhere)}: the model's polynomial with the stiffness
    doubled, less the model's (pressure left out of both: it does not depend on them). Built
    once per model."""
    # built once per model (a pass over the mesh's quadrature points, like the model's own
    # build), so that later gradients cost r^4 a step; ReducedModel.with_material drops it
    if "_stiffness_parts" not in model.__dict__:
        model._stiffness_parts = _build_parts(model)
    return model._stiffness_parts


def _build_parts(model):
    el = model.scene.elements
    base = polynomial(el, model.x0, model.basis)
    out = {}
    for name in ("mu", "lam", "kappa"):
        values = getattr(el, name)
        if not (values > 0).any():
            out[name] = None
            continue
        doubled = dataclasses.replace(el, **{name: 2.0 * values})
        out[name] = _difference(polynomial(doubled, model.x0, model.basis), base)
    return out


def _difference(a, b):
    """The Polynomial a - b (same r)."""
    return type(a)(a.c0 - b.c0, a.c1 - b.c1, a.C2 - b.C2, a.S3 - b.S3, a.W4 - b.W4)


def rollout_sensitivity(model, positions, gradients, dt):
    """dJ/dp {young (J/Pa), poisson (J), kappa (J/Pa)} of J = sum_k j_k(x_k) over a rollout of
    the reduced model (positions (k + 1, n, 3) from model.rollout, from rest, dt s), given
    gradients (k + 1, n, 3) dj_k/dx_k, for each stiffness changed over the whole body (the
    scene's uniform value; a non-uniform one is scaled by a common factor, and the derivative
    is per Pa of its mean). kappa's is NaN where the scene has no fibers."""
    positions = as_float_array(positions, "positions", shape=(None,) + model.x0.shape)
    steps = positions.shape[0] - 1
    dJ = as_float_array(gradients, "gradients", shape=positions.shape)
    mass = np.repeat(model.scene.masses, 3)
    q = ((positions - model.x0).reshape(steps + 1, -1) * mass) @ model.basis     # (k + 1, r)
    dq = dJ.reshape(steps + 1, -1) @ model.basis                                   # dj/dq
    parts = stiffness_polynomials(model)
    r = model.r
    inertia = 1.0 / dt ** 2
    later, latest = np.zeros(r), np.zeros(r)
    totals = {name: 0.0 for name in parts}
    for k in reversed(range(steps)):
        _, H = model.force(q[k + 1], hessian=True)
        mu = np.linalg.solve(H + inertia * np.eye(r), dq[k + 1] + inertia * (2 * later - latest))
        for name, part in parts.items():
            if part is not None:
                totals[name] -= float(mu @ part.gradient(q[k + 1]))
        later, latest = mu, later
    return _chain(model.scene, totals)


def _chain(scene, per_scale):
    """From dJ/ds for each of mu, lam, kappa scaled by (1 + s) over the body to dJ/dp per Pa
    of the body's mean Young's modulus and kappa, and per unit of Poisson's ratio."""
    el = scene.elements
    mu, lam, kappa = float(np.mean(el.mu)), float(np.mean(el.lam)), float(np.mean(el.kappa))
    young, poisson = lame_slopes(mu, lam, per_scale["mu"] / mu, per_scale["lam"] / lam)
    return {"young": young, "poisson": poisson,
            "kappa": per_scale["kappa"] / kappa if kappa > 0 else float("nan")}
