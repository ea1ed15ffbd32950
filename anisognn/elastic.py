"""The elastic force of a deformed tet mesh in torch, and its directional derivatives: the
same potential as anisofem,

    psi = lam/2 tr(E)^2 + mu tr(E^2) + kappa (d^T C d - 1)^2,   E = (C - I) / 2,  C = F^T F,
    S = 2 mu E + lam tr(E) I + 4 kappa (d^T C d - 1) d d^T,      P = F S,

with the force on corner a of a tet -V P grad N_a, gathered onto the vertices through the
graph's corner table (Gather and a sum, no scatter: it exports to ONNX like the aggregation).
Read by models with ModelConfig.galerkin (the step's projection, anisognn.galerkin).

Layout: per-tet values keep the tets on the last axis (k matrices: (k, 3, 3, m); corner
vectors: (4, k, 3, m)), so that a 3 x 3 product is a broadcast multiply and a sum over long
rows. As m k tiny matrix products (MatMul) with Transposes between them, onnxruntime ran the
Galerkin step of a 10,000-tet mesh about 3 times slower than torch; this layout needs two 2-D
transposes per call, which are fast (export/README.md, Latency).
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
    gradients = _tets_last(graph.tet_gradients).reshape(4, 3, -1)   # (4 corners, 3, m) 1/m
    volume, mu, lam, kappa = _tets_last(graph.tet_material).unbind(dim=0)  # (m,) m^3, Pa
    fiber = _tets_last(graph.tet_fiber)                             # (3, m)
    dd = fiber[:, None] * fiber[None]                               # (3, 3, m)
    eye = torch.eye(3, dtype=x.dtype, device=x.device)[:, :, None]
    F = _deformation_gradient(x.unsqueeze(1), gradients, graph)     # (1, 3, 3, m)
    S = _second_piola(F, mu, lam, kappa, dd)

    def differential(p):
        dF = _deformation_gradient(p, gradients, graph)             # (k, 3, 3, m)
        half = _product(dF.transpose(1, 2), F)
        dC = half + half.transpose(1, 2)
        d_stretch = (dC * dd).sum(dim=(1, 2), keepdim=True)         # d^T dC d
        d_trace = 0.5 * (dC * eye).sum(dim=(1, 2), keepdim=True)
        dS = mu * dC + lam * d_trace * eye + 4.0 * kappa * d_stretch * dd
        return _vertex_forces(_product(dF, S) + _product(F, dS), volume, gradients, graph)
    force = _vertex_forces(_product(F, S), volume, gradients, graph).squeeze(1)
    return force, differential


def _tets_last(values):
    """(c, m): per-tet values (m, ...) flattened to c columns and transposed (one 2-D
    Transpose)."""
    return values.reshape(values.shape[0], -1).transpose(0, 1)


def _product(a, b):
    """(k, 3, 3, m) the products a b of k matrices a and b (k, 3, 3, m) per tet."""
    return (a.unsqueeze(3) * b.unsqueeze(1)).sum(dim=2)


def _deformation_gradient(x, gradients, graph):
    """(k, 3, 3, m) sum_a (x_a - x_0) grad N_a^T for k sets of positions x (n, k, 3): F, or
    for displacements their differentials dF (the gradients sum to zero, so the edge-sized
    terms give the same F and keep the strains of small deformations in float32); gradients
    (4, 3, m) the shape-function gradients grad N_a."""
    n, k = x.shape[:2]
    corner = _tets_last(x.reshape(n, 3 * k)[graph.tets]).reshape(4, k, 3, -1)
    edges = corner[1:] - corner[:1]                                 # (3 corners, k, 3, m)
    return (edges.unsqueeze(3) * gradients[1:, None, None]).sum(dim=0)


def _second_piola(F, mu, lam, kappa, dd):
    """(k, 3, 3, m) Pa: S of the deformation gradients F (k, 3, 3, m), for the per-tet Lame
    constants and fiber stiffness mu, lam, kappa (m,) Pa and fiber outer products dd (3, 3, m)."""
    C = _product(F.transpose(1, 2), F)
    eye = torch.eye(3, dtype=F.dtype, device=F.device)[:, :, None]
    stretch = (C * dd).sum(dim=(1, 2), keepdim=True)                # d^T C d
    trace = 0.5 * ((C * eye).sum(dim=(1, 2), keepdim=True) - 3.0)
    return mu * (C - eye) + lam * trace * eye + 4.0 * kappa * (stretch - 1.0) * dd


def _vertex_forces(P, volume, gradients, graph):
    """(n, k, 3) N: the corner forces -V P grad N_a of first Piola-Kirchhoff stresses P
    (k, 3, 3, m) (or their differentials), summed onto the vertices; volume (m,) m^3,
    gradients (4, 3, m) 1/m."""
    per_corner = -volume * (P.unsqueeze(0) * gradients[:, None, None]).sum(dim=3)  # (4,k,3,m)
    k, m = P.shape[0], P.shape[-1]
    slots = per_corner.reshape(12 * k, m).transpose(0, 1).reshape(4 * m, k, 3)  # slot 4 t + a
    valid = graph.corners < 4 * m
    gathered = slots[torch.where(valid, graph.corners, 0)]         # (n, C, k, 3)
    return (gathered * valid[..., None, None].to(P.dtype)).sum(dim=1)
