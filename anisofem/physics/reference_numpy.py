"""A plain numpy-vectorized implementation of the same element energy, gradient and projected
Hessian, assembled the usual numpy way (COO triplets summed into CSR). It is the baseline of
`python -m anisofem bench` and an independent cross-check of the numba kernels in the tests."""
import numpy as np
import scipy.sparse as sp

from .potential import Potential


def _deformation(scene, x):
    el = scene.elements
    if scene.neohookean.any():
        raise ValueError("scene: anisofem.physics.reference_numpy implements the StVK base "
                         "material only, and this scene has Neo-Hookean elements")
    F = np.einsum("eai,eaj->eij", x[el.tets], scene.mesh.shape_gradients)
    C = np.einsum("eki,ekj->eij", F, F)
    E = 0.5 * (C - np.eye(3))
    trE = np.trace(E, axis1=1, axis2=2)
    d = el.fiber
    I4m1 = np.einsum("ei,eij,ej->e", d, C, d) - el.rest2   # I4 - s^2, s the rest stretch
    S = (2 * el.mu[:, None, None] * E + (el.lam * trE)[:, None, None] * np.eye(3)
         + (4 * el.kappa * I4m1)[:, None, None] * np.einsum("ei,ej->eij", d, d))
    psi = 0.5 * el.lam * trE ** 2 + el.mu * np.einsum("eij,eij->e", E, E) + el.kappa * I4m1 ** 2
    return F, S, psi


def elastic_energy_gradient(scene, x):
    """(elastic energy in J, gradient (n, 3) in N)."""
    F, S, psi = _deformation(scene, x)
    return float((scene.mesh.rest_volumes * psi).sum()), _gradient(scene, x, F, S)


def _gradient(scene, x, F, S):
    el = scene.elements
    P = F @ S
    mesh = scene.mesh
    ge = mesh.rest_volumes[:, None, None] * np.einsum("eij,eaj->eai", P, mesh.shape_gradients)
    grad = np.zeros_like(x)
    for i in range(3):
        grad[:, i] = np.bincount(el.tets.ravel(), ge[:, :, i].ravel(), minlength=x.shape[0])
    return grad


def element_hessians(scene, x, project=True):
    """(m, 144) element Hessians, row-major 12x12 per tet, N/m; project: clamp negative
    principal stresses in the geometric part (the same projection as the numba kernels)."""
    F, S, _ = _deformation(scene, x)
    return _hessians(scene, F, S, project)


def _hessians(scene, F, S, project):
    el = scene.elements
    if project:
        w, V = np.linalg.eigh(S)
        S = np.einsum("eik,ek,ejk->eij", V, np.maximum(w, 0.0), V)
    G = scene.mesh.shape_gradients
    q = np.einsum("eij,eaj->eai", F, G)
    B = np.einsum("eik,ejk->eij", F, F)
    gg = np.einsum("eai,ebi->eab", G, G)
    geo = np.einsum("eai,eij,ebj->eab", G, S, G)
    Fd = np.einsum("eij,ej->ei", F, el.fiber)
    s = np.einsum("eai,ei->ea", G, el.fiber)
    mu, lam, k = (a[:, None, None, None, None] for a in (el.mu, el.lam, el.kappa))
    H = (mu * np.einsum("ebi,eak->eaibk", q, q) + lam * np.einsum("eai,ebk->eaibk", q, q)
         + mu * np.einsum("eik,eab->eaibk", B, gg)
         + np.einsum("eab,ik->eaibk", geo, np.eye(3))
         + 8 * k * np.einsum("ea,eb,ei,ek->eaibk", s, s, Fd, Fd))
    return (H * scene.mesh.rest_volumes[:, None, None, None, None]).reshape(-1, 144)


def elastic_hessian(scene, x, project=True):
    """Elastic Hessian (3n, 3n) as CSR (N/m), from COO triplets."""
    el = scene.elements
    H = element_hessians(scene, x, project)
    dofs = (3 * el.tets[:, :, None] + np.arange(3)).reshape(-1, 12)
    rows = np.repeat(dofs, 12, axis=1).ravel()
    cols = np.tile(dofs, (1, 12)).ravel()
    n = 3 * x.shape[0]
    return sp.coo_matrix((H.ravel(), (rows, cols)), shape=(n, n)).tocsr()


class NumpyPotential(Potential):
    """Potential whose elastic part is computed by this module (for Newton with numpy)."""

    def _elastic(self, x, want_grad=False, layout=None, project=False):
        F, S, psi = _deformation(self.scene, x)
        e = self.scene.mesh.rest_volumes * psi
        grad = _gradient(self.scene, x, F, S) if want_grad else None
        if layout is None:
            return e, np.zeros_like(e), grad, None
        H = _hessians(self.scene, F, S, project)
        keep = layout.map >= 0
        data = np.bincount(layout.map[keep], H[keep], minlength=layout.zeros().size)
        return e, np.zeros_like(e), grad, data
