"""Saint Venant-Kirchhoff energy density at a point (numba, inlined into anisofem.physics.kernels).

    psi = lam/2 tr(E)^2 + mu tr(E^2),   E = (F^T F - I) / 2                          (J/m^3)
    S = 2 mu E + lam tr(E) I                                           (2nd Piola-Kirchhoff, Pa)

The 4th-order tangent dP/dF (P = F S) splits into a material part and a geometric part:

    A[ijkl] = mu (F_il F_kj + (F F^T)_ik delta_jl) + lam F_ij F_kl + delta_ik S_lj.

For a perturbation dF the material part gives 2 mu |sym(F^T dF)|^2 + lam tr(F^T dF)^2 >= 0 for
every admissible material (nu in (-1, 0.5)), and the geometric part gives sum_i dF_i^T S dF_i,
whose eigenvalues are those of S. Hence the PSD projection ("geometric projection"): replace S
in the geometric part by its positive part S+ (clamp negative principal stresses). It equals
the true tangent wherever S has no negative principal stress, and costs one closed-form 3x3
eigen-decomposition per point.

Contracted with the point's shape gradients G_a (q_a = F G_a), the Hessian blocks are

    H[3a+i, 3b+k] = w ( delta_ik G_a^T S G_b + mu q_b,i q_a,k + mu (F F^T)_ik G_a.G_b
                        + lam q_a,i q_b,k ).

The geometric part takes the point's total stress: a fiber term's stress is projected together
with this one (anisofem.physics.densities.point_hessian).
"""
from numba import njit

from ..sym3 import has_negative_eigenvalue, positive_part


@njit(cache=True, inline="always")
def stress(F, mu, lam, S):
    """Fill S (3, 3) of deformation gradient F (3, 3); returns psi (J/m^3)."""
    # Green strain E = (F^T F - I) / 2, kept in S for now
    for i in range(3):
        for j in range(i, 3):
            acc = 0.0
            for k in range(3):
                acc += F[k, i] * F[k, j]
            if i == j:
                acc -= 1.0
            S[i, j] = 0.5 * acc
            S[j, i] = 0.5 * acc
    trE = S[0, 0] + S[1, 1] + S[2, 2]
    EE = 0.0
    for i in range(3):
        for j in range(3):
            EE += S[i, j] * S[i, j]
    for i in range(3):
        for j in range(3):
            S[i, j] *= 2.0 * mu
        S[i, i] += lam * trE
    return 0.5 * lam * trE * trE + mu * EE


@njit(cache=True, inline="always")
def hessian(G, n, w, mu, lam, F, S, project, work, He):
    """Add the blocks a <= b of the Hessian above (N/m) for the n shape gradients G (n, 3), 1/m,
    and quadrature weight w (m^3) to He (3n, 3n). S (3, 3): the point's total stress (projected:
    its positive part). work: anisofem.physics.kernels.WORK_SHAPE scratch (rows 0-4)."""
    Sg, B, q = work[0, :3], work[1, :3], work[2, :n]
    if project and has_negative_eigenvalue(S):
        positive_part(S, Sg, work[3, 0], work[4, :3])
    else:
        for i in range(3):
            for j in range(3):
                Sg[i, j] = S[i, j]
    for a in range(n):
        for i in range(3):
            q[a, i] = F[i, 0] * G[a, 0] + F[i, 1] * G[a, 1] + F[i, 2] * G[a, 2]
    for i in range(3):
        for k in range(3):
            B[i, k] = mu * (F[i, 0] * F[k, 0] + F[i, 1] * F[k, 1] + F[i, 2] * F[k, 2])
    for a in range(n):
        for b in range(a, n):
            geo = 0.0
            for i in range(3):
                geo += G[a, i] * (Sg[i, 0] * G[b, 0] + Sg[i, 1] * G[b, 1] + Sg[i, 2] * G[b, 2])
            gg = G[a, 0] * G[b, 0] + G[a, 1] * G[b, 1] + G[a, 2] * G[b, 2]
            for i in range(3):
                for k in range(3):
                    h = mu * q[b, i] * q[a, k] + lam * q[a, i] * q[b, k] + B[i, k] * gg
                    He[3 * a + i, 3 * b + k] += w * h
            for i in range(3):
                He[3 * a + i, 3 * b + i] += w * geo
