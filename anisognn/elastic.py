"""The elastic force of a deformed tet mesh in torch, and its directional derivatives: the
same potential as anisofem,

    psi = lam/2 tr(E)^2 + mu tr(E^2) + kappa (d^T C d - 1)^2,   E = (C - I) / 2,  C = F^T F,
    S = 2 mu E + lam tr(E) I + 4 kappa (d^T C d - 1) d d^T,      P = F S,

with the force on corner a of a tet -V P grad N_a, gathered onto the vertices through the
graph's corner table (Gather and a sum, no scatter: it exports to ONNX like the aggregation).
Read by models with ModelConfig.elastic_force (an input) and ModelConfig.galerkin (the step's
projection, anisognn.galerkin).
"""
import torch


def elastic_force(x, graph):
    """(n, 3) N: minus the gradient of the elastic energy at positions x (n, 3) m, on
    anisognn.graph.Graph graph (its tets, tet_gradients, tet_material, tet_fiber, corners)."""
    return elastic_force_and_differential(x, graph)[0]


def elastic_force_and_differential(x, graph):
    """((n, 3) N, function): elastic_force at positions x (n, 3) m, and the function that maps
    k displacements p (n, k, 3) m to the force's derivatives along them (n, k, 3) N, i.e.
    minus the elastic energy's Hessian at x times each (the exact Hessian, not its PSD
    projection). F and S are computed once for both."""
    F = _deformation_gradient(x.unsqueeze(1), graph)            # (m, 1, 3, 3)
    eye = torch.eye(3, dtype=x.dtype, device=x.device)
    mu, lam, kappa, dd = _material(graph)
    S = _second_piola(F, mu, lam, kappa, dd)

    def differential(p):
        dF = _deformation_gradient(p, graph)                    # (m, k, 3, 3)
        # two products rather than A + A^T: onnxruntime folds a transposed MatMul operand into
        # the product, but runs a standalone Transpose of (m, k, 3, 3) slowly
        dC = torch.matmul(dF.transpose(-1, -2), F) + torch.matmul(F.transpose(-1, -2), dF)
        d_stretch = (dC * dd).sum(dim=(-2, -1), keepdim=True)   # d^T dC d
        d_trace = 0.5 * (dC * eye).sum(dim=(-2, -1), keepdim=True)
        dS = mu * dC + lam * d_trace * eye + 4.0 * kappa * d_stretch * dd
        return _vertex_forces(torch.matmul(dF, S) + torch.matmul(F, dS), graph)
    return _vertex_forces(torch.matmul(F, S), graph).squeeze(1), differential


def _deformation_gradient(x, graph):
    """(m, k, 3, 3) sum_a (x_a - x_0) grad N_a^T for k sets of positions x (n, k, 3): F, or
    for displacements their differentials dF (the gradients sum to zero, so the edge-sized
    terms give the same F and keep the strains of small deformations in float32)."""
    corner = x[graph.tets]                                      # (m, 4, k, 3)
    edges = (corner[:, 1:] - corner[:, :1]).permute(0, 2, 3, 1)  # (m, k, 3, 3 corners)
    return torch.matmul(edges, graph.tet_gradients[:, None, 1:])


def _material(graph):
    """(mu, lam, kappa, d d^T): the per-tet constants shaped (m, 1, 1, 1) and (m, 1, 3, 3),
    Pa and unit."""
    _, mu, lam, kappa = (c[:, None, None, None] for c in graph.tet_material.unbind(dim=1))
    d = graph.tet_fiber[:, None, :]
    return mu, lam, kappa, (d.unsqueeze(-1) * d.unsqueeze(-2))


def _second_piola(F, mu, lam, kappa, dd):
    """(m, k, 3, 3) Pa: S of the deformation gradients F (m, k, 3, 3), for _material's per-tet
    constants."""
    C = torch.matmul(F.transpose(-1, -2), F)
    eye = torch.eye(3, dtype=F.dtype, device=F.device)
    stretch = (C * dd).sum(dim=(-2, -1), keepdim=True)          # d^T C d
    trace = 0.5 * ((C * eye).sum(dim=(-2, -1), keepdim=True) - 3.0)
    return mu * (C - eye) + lam * trace * eye + 4.0 * kappa * (stretch - 1.0) * dd


def _vertex_forces(P, graph):
    """(n, k, 3) N: the corner forces -V P grad N_a of first Piola-Kirchhoff stresses P
    (m, k, 3, 3) (or their differentials), summed onto the vertices."""
    volume = graph.tet_material[:, 0, None, None, None]
    per_corner = -volume * torch.matmul(graph.tet_gradients[:, None], P.transpose(-1, -2))
    m, k = per_corner.shape[:2]
    slots = per_corner.transpose(1, 2).reshape(4 * m, k, 3)     # slot 4 t + a
    valid = graph.corners < 4 * m
    gathered = slots[torch.where(valid, graph.corners, 0)]     # (n, C, k, 3)
    return (gathered * valid[..., None, None].to(P.dtype)).sum(dim=1)
