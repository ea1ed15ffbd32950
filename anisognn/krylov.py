"""Conjugate-gradient iterations after the network's step (ModelConfig.cg_iterations, not in
the paper): an accuracy knob between the network's step and backward Euler's.

The backward-Euler step minimizes G(x) = 1/(2 dt^2) |x - x_hat|^2_M + E(x) - f_ext . x with
x_hat = x + dt v. From the model's step s (x' = x_hat + s), k iterations of conjugate gradients
on the Newton system of G linearized there,

    A d = r,   r = f_elastic(x_hat + s) + f_ext - M s / dt^2,   A = M / dt^2 + d2E/dx2,

preconditioned by the lumped mass (M / dt^2), move the step to s + d on the free components.
With enough iterations d is the Newton step from the model's step, so the rollout approaches
anisofem's backward Euler (one Newton iteration from a good start); with few, the iterations
reduce the energy of the linearized step (the error in A's norm) monotonically from the model's.

Precision: the iterations run in float64 whatever the model's dtype (the force and its
derivatives from anisognn.elastic on a float64 copy of the graph's per-tet constants): the
step coefficients are ratios of sums over the whole mesh, and in float32 the directions lose
their conjugacy after tens of iterations (docs/experiments.md). The cost is one elastic force
and k Hessian products per step, without a network evaluation.

Guards, traced into the exported graph (no data-dependent branch): an iteration whose
direction has no positive curvature (A indefinite, or a zero residual) stops the iterations of
its batch member (its later steps are zero).
"""
from dataclasses import replace

import torch

from .elastic import elastic_force_and_differential
from .galerkin import member_sum, per_vertex

#: the per-tet and per-vertex graph fields the elastic force reads, cast to float64 here
PHYSICS = ("mass", "fixed", "tet_gradients", "tet_material", "tet_fiber")


def refine(step, u_hat, f_ext, graph, dt, iterations):
    """(n, 3) float64 m: the step s (n, 3) m (x' = x_hat + s) after `iterations`
    mass-preconditioned conjugate-gradient iterations on the backward-Euler Newton system
    linearized at x_hat + s (module docstring); u_hat (n, 3) m the predictor's displacement
    from rest, x_hat - X; f_ext (n, 3) N; dt s; one system per batch member (graph.sample)."""
    graph = _float64(graph)
    step, u_hat, f_ext = step.double(), u_hat.double(), f_ext.double()
    free = 1.0 - graph.fixed
    inertia = graph.mass / (dt * dt)                                        # (n, 1) kg/s^2
    force, differential = elastic_force_and_differential(u_hat + step, graph)
    residual = (force + f_ext - inertia * step) * free
    z = residual / inertia
    direction = z
    rz = member_sum((residual * z).sum(dim=1, keepdim=True), graph)       # (S, 1)
    active = torch.ones_like(rz)
    for _ in range(iterations):
        product = (inertia * direction - differential(direction.unsqueeze(1)).squeeze(1)) * free
        curvature = member_sum((direction * product).sum(dim=1, keepdim=True), graph)
        active = active * (curvature > 0).to(curvature.dtype)
        alpha = active * rz / torch.where(curvature > 0, curvature, 1.0)
        step = step + per_vertex(alpha, graph) * direction
        residual = residual - per_vertex(alpha, graph) * product
        z = residual / inertia
        rz_next = member_sum((residual * z).sum(dim=1, keepdim=True), graph)
        beta = rz_next / torch.where(rz > 0, rz, 1.0)
        direction = z + per_vertex(beta, graph) * direction
        rz = rz_next
    return step


def _float64(graph):
    """A shallow copy of graph whose PHYSICS fields are float64 (the integer tables shared)."""
    return replace(graph, **{name: getattr(graph, name).double() for name in PHYSICS})
