"""The fiber term at a point (numba, inlined into anisofem.physics.kernels): one family of fibers
along the unit material direction d, added to a base energy density.

    psi = kappa (I4 - s^2)^2,   I4 = d^T C d = |F d|^2                               (J/m^3)
    S = 4 kappa (I4 - s^2) d d^T                                       (2nd Piola-Kirchhoff, Pa)

s, the fiber's rest stretch: 1 for passive fibers, 1 - activation for fibers that contract
(anisofem.Material's activation; s2 = s^2 below).

Contracted with the point's shape gradients G_a (s_a = d . G_a), the Hessian blocks are a
material part, PSD,

    w 8 kappa (Fd)_i (Fd)_k s_a s_b,

and a geometric part w 4 kappa (I4 - s^2) s_a s_b delta_ik, negative where the fiber is
shorter than its rest length (I4 < s^2): projected, it is dropped there.
"""
from numba import njit


@njit(cache=True, inline="always")
def stress(F, d, kappa, s2, S, Fd):
    """Add the fiber stress to S (3, 3) and fill Fd = F d (3,) for the deformation gradient F
    (3, 3), fiber direction d (3,) and squared rest stretch s2; returns psi (J/m^3)."""
    for i in range(3):
        Fd[i] = F[i, 0] * d[0] + F[i, 1] * d[1] + F[i, 2] * d[2]
    I4m1 = Fd[0] * Fd[0] + Fd[1] * Fd[1] + Fd[2] * Fd[2] - s2
    c = 4.0 * kappa * I4m1
    for i in range(3):
        for j in range(3):
            S[i, j] += c * d[i] * d[j]
    return kappa * I4m1 * I4m1


@njit(cache=True, inline="always")
def hessian(G, n, w, kappa, s2, d, Fd, geometric, project, He):
    """Add the blocks a <= b of the Hessian above (N/m) for the n shape gradients G (n, 3), 1/m,
    and quadrature weight w (m^3) to He (3n, 3n): the material part, and the geometric part
    when `geometric` (a base law whose Hessian projects the total stress has it already)."""
    c = 4.0 * kappa * (Fd[0] * Fd[0] + Fd[1] * Fd[1] + Fd[2] * Fd[2] - s2)
    with_geometric = geometric and not (project and c < 0.0)
    for a in range(n):
        sa = d[0] * G[a, 0] + d[1] * G[a, 1] + d[2] * G[a, 2]
        geo = w * c * sa
        material = 8.0 * kappa * w * sa
        for b in range(a, n):
            sb = d[0] * G[b, 0] + d[1] * G[b, 1] + d[2] * G[b, 2]
            if with_geometric:
                for i in range(3):
                    He[3 * a + i, 3 * b + i] += geo * sb
            mab = material * sb
            for i in range(3):
                for k in range(3):
                    He[3 * a + i, 3 * b + k] += mab * Fd[i] * Fd[k]
