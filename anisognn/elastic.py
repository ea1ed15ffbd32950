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


def elastic_force(u, graph):
    """(n, 3) N: minus the gradient of the elastic energy at displacements u (n, 3) m from the
    rest shape, on anisognn.graph.Graph graph (its tets, tet_gradients, tet_material,
    tet_fiber, corners)."""
    return elastic_force_and_differential(u, graph)[0]


def elastic_force_and_differential(u, graph):
    """((n, 3) N, function): elastic_force at displacements u (n, 3) m, and the function that
    maps k directions p (n, k, 3) m to the force's derivatives along them (n, k, 3) N, i.e.
    minus the elastic energy's Hessian at u times each (the exact Hessian, not its PSD
    projection). The strain is formed from the displacement gradient H = F - I, as
    2 E = H + H^T + H^T H, never as F^T F - I (which cancels to 2-3 digits in float32 at
    strains of 1e-3). F and S are computed once for both."""
    gradients = _tets_last(graph.tet_gradients).reshape(4, 3, -1)   # (4 corners, 3, m) 1/m
    volume, mu, lam, kappa = _tets_last(graph.tet_material).unbind(dim=0)  # (m,) m^3, Pa
    fiber = _tets_last(graph.tet_fiber)                             # (3, m)
    dd = fiber[:, None] * fiber[None]                               # (3, 3, m)
    eye = torch.eye(3, dtype=u.dtype, device=u.device)[:, :, None]
    H = _gradient(u.unsqueeze(1), gradients, graph)                 # (1, 3, 3, m)
    F = eye + H
    S = _second_piola(H, mu, lam, kappa, dd)

    def differential(p):
        dF = _gradient(p, gradients, graph)                         # (k, 3, 3, m)
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


def _gradient(w, gradients, graph):
    """(k, 3, 3, m) sum_a (w_a - w_0) grad N_a^T for k vector fields w (n, k, 3): the
    displacement gradient H = F - I of displacements, or dF of directions (the shape-function
    gradients sum to zero, so the edge differences give the same sum with smaller terms);
    gradients (4, 3, m) the shape-function gradients grad N_a."""
    n, k = w.shape[:2]
    corner = _tets_last(w.reshape(n, 3 * k)[graph.tets]).reshape(4, k, 3, -1)
    edges = corner[1:] - corner[:1]                                 # (3 corners, k, 3, m)
    return (edges.unsqueeze(3) * gradients[1:, None, None]).sum(dim=0)


def _second_piola(H, mu, lam, kappa, dd):
    """(k, 3, 3, m) Pa: S of the displacement gradients H = F - I (k, 3, 3, m), for the
    per-tet Lame constants and fiber stiffness mu, lam, kappa (m,) Pa and fiber outer products
    dd (3, 3, m)."""
    strain2 = H + H.transpose(1, 2) + _product(H.transpose(1, 2), H)  # 2 E = C - I
    eye = torch.eye(3, dtype=H.dtype, device=H.device)[:, :, None]
    stretch = (strain2 * dd).sum(dim=(1, 2), keepdim=True)          # d^T C d - 1
    trace = 0.5 * (strain2 * eye).sum(dim=(1, 2), keepdim=True)      # tr E
    return mu * strain2 + lam * trace * eye + 4.0 * kappa * stretch * dd


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
