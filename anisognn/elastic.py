"""The elastic force of a deformed tet mesh in torch, an input of models with
ModelConfig.elastic_force: the same potential as anisofem,

    psi = lam/2 tr(E)^2 + mu tr(E^2) + kappa (d^T C d - 1)^2,   E = (C - I) / 2,  C = F^T F,
    S = 2 mu E + lam tr(E) I + 4 kappa (d^T C d - 1) d d^T,      P = F S,

with the force on corner a of a tet -V P grad N_a, gathered onto the vertices through the
graph's corner table (Gather and a sum, no scatter: it exports to ONNX like the aggregation).
"""
import torch


def elastic_force(x, graph):
    """(n, 3) N: minus the gradient of the elastic energy at positions x (n, 3) m, on
    anisognn.graph.Graph graph (its tets, tet_gradients, tet_material, tet_fiber, corners)."""
    corner = x[graph.tets]                        # (m, 4, 3)
    grads = graph.tet_gradients                   # (m, 4, 3)
    # F = sum_a (x_a - x_0) grad N_a^T: the same F (the gradients sum to zero) with edge-sized
    # terms, so float32 keeps the strains of small deformations
    F = torch.matmul((corner[:, 1:] - corner[:, :1]).transpose(1, 2), grads[:, 1:])
    C = torch.matmul(F.transpose(1, 2), F)
    eye = torch.eye(3, dtype=x.dtype, device=x.device)
    E = 0.5 * (C - eye)
    volume, mu, lam, kappa = graph.tet_material.unbind(dim=1)
    d = graph.tet_fiber
    stretch = (d * torch.matmul(C, d.unsqueeze(-1)).squeeze(-1)).sum(dim=1)
    trace = E.diagonal(dim1=1, dim2=2).sum(dim=1)
    S = (2.0 * mu[:, None, None] * E + (lam * trace)[:, None, None] * eye
         + (4.0 * kappa * (stretch - 1.0))[:, None, None] * d.unsqueeze(2) * d.unsqueeze(1))
    P = torch.matmul(F, S)
    per_corner = -volume[:, None, None] * torch.matmul(grads, P.transpose(1, 2))  # (m, 4, 3)
    slots = per_corner.reshape(-1, 3)
    valid = graph.corners < slots.shape[0]
    gathered = slots[torch.where(valid, graph.corners, 0)]  # (n, C, 3)
    return (gathered * valid.unsqueeze(-1).to(x.dtype)).sum(dim=1)
