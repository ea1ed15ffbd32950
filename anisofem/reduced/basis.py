"""The reduced basis of a scene: its lowest vibration modes about the initial positions and
their modal derivatives (Barbic and James 2005), mass-orthonormal over the free unknowns.

Modes: K phi = omega^2 M phi with K the true Hessian of the free unknowns at x0 and M the
lumped mass. Modal derivatives: Psi_ij = -K^-1 (dK/dphi_i) phi_j for i <= j, the second-order
response of a static solve to a load along phi_i and phi_j; they carry the large rotations
that linear modes alone cannot.
"""
import math

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.sparse.csgraph import connected_components

from .domains import edge_graph

#: A candidate direction is dropped from the basis when mass-orthogonalization leaves less
#: than this share of its norm (it depends on the others).
DEPENDENT = 1e-8

#: Step of the Hessian's central difference along a mode, in units of the mesh's size (its
#: RMS distance from the centroid) for the mode's largest vertex displacement. The Hessian of
#: StVK and fiber energies is quadratic in x, so the difference is exact up to round-off at
#: any step; this one keeps the round-off small.
DIFFERENCE_STEP = 1e-3


def free_hessian(potential, x, layout):
    """The true Hessian of the free unknowns at positions x (n, 3), scipy CSC, N/m."""
    _, _, data = potential.hessian_data(x, layout, want_grad=False)
    return layout.matrix(data).tocsc()


def vibration_modes(K, factor, mass, modes):
    """The `modes` lowest (omega^2 (1/s^2), phi (N, modes)) of K phi = omega^2 M phi, M =
    diag(mass) (kg per free unknown), by shift-invert Lanczos on factor (scipy's splu of K)
    from a fixed start (so a model is built the same way every time). phi is M-orthonormal."""
    inverse = spla.LinearOperator(K.shape, matvec=factor.solve, dtype=float)
    lam, phi = spla.eigsh(K, k=modes, M=sp.diags(mass).tocsc(), sigma=0.0, which="LM",
                          v0=np.sqrt(mass), OPinv=inverse)
    order = np.argsort(lam)
    return lam[order], phi[:, order]


def modal_derivatives(potential, x0, layout, factor, phi, free):
    """Psi_ij = -K^-1 (dK/dphi_i) phi_j for i <= j, (N, m (m + 1) / 2), K^-1 by factor (splu
    of K), each dK/dphi_i the central difference of the Hessian along phi_i (exact for StVK
    and fiber energies)."""
    solve = factor.solve
    n = x0.shape[0]
    size = math.sqrt(float(np.mean(np.sum((x0 - x0.mean(0)) ** 2, axis=1))))
    slopes = []
    for i in range(phi.shape[1]):
        u = np.zeros(3 * n)
        u[free] = phi[:, i]
        u = u.reshape(n, 3)
        h = DIFFERENCE_STEP * size / np.abs(u).max()
        plus = free_hessian(potential, x0 + h * u, layout)
        minus = free_hessian(potential, x0 - h * u, layout)
        slopes.append((plus - minus) / (2.0 * h))
    columns = [-solve(slopes[i] @ phi[:, j]) for i in range(phi.shape[1])
               for j in range(i, phi.shape[1])]
    return np.column_stack(columns)


def mass_orthonormal(V, mass):
    """Columns of V (N, c) made orthonormal in the lumped-mass inner product by modified
    Gram-Schmidt (twice), dropping those that depend on the earlier ones (DEPENDENT)."""
    kept = []
    for k in range(V.shape[1]):
        v = V[:, k].copy()
        norm0 = math.sqrt(float(v @ (mass * v)))
        if norm0 == 0.0:
            continue
        for _ in range(2):
            for u in kept:
                v -= (u @ (mass * v)) * u
        norm = math.sqrt(float(v @ (mass * v)))
        if norm > DEPENDENT * norm0:
            kept.append(v / norm)
    return np.column_stack(kept)


def bodies(scene):
    """(the vertex indices of each free body: a connected part of the mesh with no held
    vertex, whose static stiffness is singular; (n,) bool, the vertices of the parts that
    hold a held vertex, which carry the held vertices' motion)."""
    mesh = scene.mesh
    count, label = connected_components(edge_graph(mesh), directed=False)
    used = np.zeros(mesh.n_vertices, bool)
    used[mesh.cells.ravel()] = True
    holding = np.zeros(count, bool)
    holding[label[scene.fixed_mask.any(axis=1) & used]] = True
    free = [np.flatnonzero(label == c) for c in range(count)
            if not holding[c] and used[label == c].any()]
    return free, holding[label] & used


def rigid_motions(x, vertices):
    """(3n, 6) the rigid motions of the vertices `vertices` of positions x (n, 3), m: three
    translations (1 m) and three small turns (1 rad) about their centroid, 0 elsewhere."""
    arm = x[vertices] - x[vertices].mean(axis=0)
    out = np.zeros((x.shape[0], 3, 6))
    for k in range(3):
        out[vertices, k, k] = 1.0
        out[vertices, :, 3 + k] = np.cross(np.eye(3)[k], arm)
    return out.reshape(-1, 6)


def free_body_modes(K, mass, count):
    """The `count` lowest vibration modes (N, count) of a free body, K its (singular) free
    Hessian (N, N), mass its lumped mass per unknown (N,): shift-invert Lanczos about a
    negative shift, below its six rigid motions' 0 (K + |shift| M is positive definite), the
    six left out."""
    shift = -SHIFT_SHARE * float(K.diagonal().sum() / mass.sum())
    lam, phi = spla.eigsh(K.tocsc(), k=min(count + 6, K.shape[0] - 1),
                          M=sp.diags(mass).tocsc(), sigma=shift, which="LM", v0=np.sqrt(mass))
    return phi[:, np.argsort(lam)[6:]]


#: free_body_modes' shift over the body's mean squared frequency (trace K / trace M): far
#: below its elastic modes, yet a shifted K that float64 factors well.
SHIFT_SHARE = 1e-6


class HeldFactor:
    """K^-1 over the unknowns outside the free bodies (`kept`, indices among N free unknowns),
    the free bodies' left at 0: the held part's static responses (a free body's K is
    singular). K: that part of K (CSC); solve(b) (N,) -> (N,)."""

    def __init__(self, K, kept, size):
        self.kept, self.size = kept, size
        self.K = K[kept][:, kept].tocsc()
        self.lu = spla.splu(self.K)

    def solve(self, b):
        out = np.zeros(self.size)
        out[self.kept] = self.lu.solve(np.ascontiguousarray(b[self.kept]))
        return out
