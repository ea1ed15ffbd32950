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
    u      the displacement from the rest shape, x - X.
The step is then dt^2 a = sum_i c_i p_i over the A-conjugate directions p_i (Gram-Schmidt in
A's inner product on the 4 x 4 Gram matrix, no linear solve: ONNX has none), c_i = (p_i . r)
/ (p_i . A p_i); a direction whose curvature is not positive, or that the previous ones
already span, is left out. Hessian products are anisognn.elastic's (exact, in the model's
dtype).

What it guarantees: the step is zero only where the forces balance (r = 0 gives a zero step,
and r != 0 gives a step at least as good, in the model, as the best gradient step), so a
rollout rests only at anisofem's equilibrium; and, with v in the span, the residual of the
step's equation is orthogonal to the displacement over the step, so for a linear material the
energy 1/2 v^T M v + E - f_ext . x cannot grow, as under backward Euler (which dissipates
more: it solves in every direction). What the network adds is a direction the other three do
not contain, which decides how fast a rollout converges (docs/experiments.md).
"""
import torch

from .elastic import elastic_force_and_differential

#: a direction counts only if its curvature after conjugation keeps this share of its own
REDUNDANT = 1e-4
#: floor of a direction's rms (its unit): a zero direction stays zero
FLOOR = 1e-15


def galerkin_acceleration(a_net, u, v, f_ext, graph, dt, passes=1):
    """(n, 3) m/s^2: the Galerkin step over dt^2 (module docstring) for the network's
    acceleration a_net (n, 3) m/s^2 at displacements u (n, 3) m from the rest shape,
    velocities v (n, 3) m/s and external force f_ext (n, 3) N on graph; one system per batch
    member (graph.sample).
    passes > 1 solves again from the point the previous pass reached, over its residual
    acceleration, the step so far, v and the displacement (the same model of G, now at that
    point: its inertia term no longer vanishes). The step so far enters as its part along the
    passes' first two directions: the same span, but the whole step is mostly v and the
    displacement, and with it among the directions the Gram matrix was near singular (float32
    then moved the step by up to 1e-3 of itself; tests/test_gnn_galerkin.py)."""
    free = 1.0 - graph.fixed
    u_hat = u + dt * v
    inertia = graph.mass / (dt * dt)
    step, first = torch.zeros_like(u), a_net
    for k in range(passes):
        force, differential = elastic_force_and_differential(u_hat + step, graph)
        residual = (force + f_ext - inertia * step) * free
        basis = torch.stack([first, residual / graph.mass, v, u], dim=1) * free[:, None]
        parts = _subspace_parts(basis, residual, differential, inertia, graph)
        step = step + parts.sum(dim=1)
        if k + 1 < passes:
            first = parts[:, :2].sum(dim=1) + (first if k > 0 else 0.0)
    return step / (dt * dt)


def _subspace_parts(basis, residual, differential, inertia, graph):
    """(n, k, 3) m: the minimizer of -r . s + 1/2 s^T A s over the span of the directions basis
    (n, k, 3) (zero off the free components), A = M / dt^2 - differential (inertia (n, 1) the
    mass over dt^2), r = residual (n, 3) N, as its part along each direction (s is their
    sum)."""
    free = 1.0 - graph.fixed
    count = member_sum(3.0 * torch.ones_like(graph.mass), graph)            # (S, 1)
    rms = torch.sqrt(member_sum((basis * basis).sum(dim=2), graph) / count + FLOOR ** 2)
    basis = basis / per_vertex(rms, graph)[:, :, None]                      # (n, k, 3)
    products = (inertia[:, None] * basis - differential(basis)) * free[:, None]
    gram = _gram(basis, products, graph)                                     # (S, k, k)
    rhs = member_sum((basis * residual[:, None]).sum(dim=2), graph)          # (S, k)
    weights = _conjugate_solve(gram, rhs)                                    # (S, k)
    return basis * per_vertex(weights, graph)[:, :, None]


def _conjugate_solve(gram, rhs):
    """(S, k) w with p = sum_i w_i b_i the minimizer of 1/2 p.A p - p.r over the span of the
    directions kept: gram (S, k, k) <b_i, A b_j>, rhs (S, k) <b_i, r>. Gauss-Jordan elimination
    of [gram | rhs] in the directions' order, i.e. Gram-Schmidt in A's inner product: a pivot is
    the curvature direction i keeps after the previous ones, and a direction whose pivot is below
    REDUNDANT of its own curvature (or not positive) is left out, with weight zero."""
    k = gram.shape[-1]
    others = 1.0 - torch.eye(k, dtype=gram.dtype, device=gram.device)
    own = torch.diagonal(gram, dim1=1, dim2=2)                               # (S, k)
    thresholds = torch.where(own > 0, REDUNDANT * own, float("inf")).unbind(dim=1)
    table = torch.cat([gram, rhs.unsqueeze(2)], dim=2)                       # (S, k, k + 1)
    inverse_pivots = []
    for i in range(k):
        row = table[:, i]                                                    # (S, k + 1)
        keep = row[:, i] > thresholds[i]
        inverse = keep.to(gram.dtype) / torch.where(keep, row[:, i], 1.0)
        # the other rows lose their multiple of row i, which stays (nothing if it is dropped)
        factor = table[:, :, i] * others[i] * inverse.unsqueeze(1)           # (S, k)
        table = table - factor.unsqueeze(2) * row.unsqueeze(1)
        inverse_pivots.append(inverse)
    return table[:, :, k] * torch.stack(inverse_pivots, dim=1)


def _gram(a, b, graph):
    """(S, k, k) the inner products <a_i, b_j> over each batch member of k fields a, b
    (n, k, 3): one matrix product for a single mesh (the exported case)."""
    if graph.sample is None:
        flat_a = a.transpose(0, 1).reshape(a.shape[1], -1)
        flat_b = b.transpose(0, 1).reshape(b.shape[1], -1)
        return torch.matmul(flat_a, flat_b.transpose(0, 1)).unsqueeze(0)
    return member_sum(torch.matmul(a, b.transpose(1, 2)), graph)


def member_sum(values, graph):
    """(S, ...) the sums of per-vertex values (n, ...) over each batch member (S = 1 for a
    single mesh)."""
    if graph.sample is None:
        return values.sum(dim=0, keepdim=True)
    members = torch.zeros((int(graph.sample.max()) + 1,) + values.shape[1:], dtype=values.dtype,
                          device=values.device)
    return members.index_add(0, graph.sample, values)


def per_vertex(values, graph):
    """(n, ...) each vertex's batch member's entry of values (S, ...)."""
    if graph.sample is None:
        return values.expand((graph.n_vertices,) + values.shape[1:])
    return values[graph.sample]
