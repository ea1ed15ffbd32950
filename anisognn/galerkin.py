"""The Galerkin step (ModelConfig.galerkin, not in the paper): the network's acceleration
projected, with the forces, onto the backward-Euler step.

One backward-Euler step minimizes G(x) = 1/(2 dt^2) |x - x_hat|^2_M + E(x) - f_ext . x with
x_hat = x + dt v. Its second-order model at the predictor x_hat, in the step s = x' - x_hat,

    G(x_hat + s) ~ G(x_hat) - r . s + 1/2 s^T A s,   r = f_elastic(x_hat) + f_ext,
                                                     A = M / dt^2 + d2E/dx2 (x_hat),

is minimized here over s in the span of four directions on the free components:
    a_net  the network's acceleration,
    r / m  the force acceleration at the predictor (a gradient step's direction),
    v      the velocity, and
    x - X  the displacement from the rest shape (X: the graph's fixed_positions, the rest
           positions of the free components).
The step is then dt^2 a = sum_i c_i p_i over the A-conjugate directions p_i (Gram-Schmidt in
A's inner product, no linear solve: ONNX has none), c_i = (p_i . r) / (p_i . A p_i); a
direction whose curvature is not positive, or that the previous ones already span, is left
out. Hessian products are anisognn.elastic.force_differentials (exact, in the model's dtype).

What it guarantees: the step is zero only where the forces balance (r = 0 gives a zero step,
and r != 0 gives a step at least as good, in the model, as the best gradient step), so a
rollout rests only at anisofem's equilibrium; and each step is the best combination of the
network's direction with the physical ones, which dissipates the motion along v like backward
Euler. What the network adds is a direction the other three do not contain: the measured
difference between converging and not (README, "What we learned").
"""
import torch

from .elastic import elastic_force, force_differentials

#: a direction counts only if its curvature after conjugation keeps this share of its own
REDUNDANT = 1e-4


def galerkin_acceleration(a_net, x, v, f_ext, graph, dt):
    """(n, 3) m/s^2: the Galerkin step over dt^2 (module docstring) for the network's
    acceleration a_net (n, 3) m/s^2 at positions x (n, 3) m, velocities v (n, 3) m/s and
    external force f_ext (n, 3) N on graph; one system per batch member (graph.sample)."""
    free = 1.0 - graph.fixed
    x_hat = x + dt * v
    # fixed_positions is float64 where the exported step reads it, x float32
    displacement = (x - graph.fixed_positions).to(x.dtype)
    residual = (elastic_force(x_hat, graph) + f_ext) * free
    basis = [b * free for b in (a_net, residual / graph.mass, v, displacement)]
    basis = torch.stack([b / _rms(b, graph) for b in basis], dim=1)   # (n, 4, 3)
    differentials = force_differentials(x_hat, basis, graph)
    products = (graph.mass.unsqueeze(-1) / (dt * dt) * basis - differentials) * free.unsqueeze(1)
    step = torch.zeros_like(x)
    conjugate = []  # (p, A p, p . A p) of the directions kept so far
    for b, Ab in zip(basis.unbind(dim=1), products.unbind(dim=1)):
        own = _dot(b, Ab, graph)
        p, Ap = b, Ab
        for q, Aq, qAq in conjugate:
            coef = _dot(b, Aq, graph) / qAq
            p, Ap = p - coef * q, Ap - coef * Aq
        pAp = _dot(p, Ap, graph)
        kept = (pAp > REDUNDANT * own) & (own > 0)
        pAp = torch.where(kept, pAp, torch.ones_like(pAp))
        p, Ap = p * kept, Ap * kept
        step = step + _dot(p, residual, graph) / pAp * p
        conjugate.append((p, Ap, pAp))
    return step / (dt * dt)


def _dot(a, b, graph):
    """(n, 1) the inner product of a and b (n, 3) over each vertex's batch member."""
    per_vertex = (a * b).sum(dim=1, keepdim=True)
    if graph.sample is None:
        return per_vertex.sum(dim=0, keepdim=True).expand_as(per_vertex)
    members = torch.zeros(int(graph.sample.max()) + 1, 1, dtype=a.dtype, device=a.device)
    return members.index_add(0, graph.sample, per_vertex)[graph.sample]


def _rms(b, graph, floor=1e-15):
    """(n, 1) the root mean square of b (n, 3) over each batch member, floored (sqrt(ms +
    floor^2), differentiable at zero): a zero direction stays zero."""
    count = _dot(torch.ones_like(b), torch.ones_like(b), graph)
    return torch.sqrt(_dot(b, b, graph) / count + floor * floor)
