"""Compressible Neo-Hookean energy density at a point (numba, inlined into
anisofem.physics.kernels).

    psi = mu/2 (tr C - 3) - mu ln J + lam/2 (ln J)^2,   C = F^T F, J = det F     (J/m^3)
    psi = +inf for J <= 0
    S = mu (I - C^-1) + lam ln J C^-1                                  (2nd Piola-Kirchhoff, Pa)

Contracted with the point's shape gradients G_a (r_a = F^-T G_a, c = mu - lam ln J), the
Hessian blocks are

    H[3a+i, 3b+k] = w (mu delta_ik G_a.G_b + lam r_a,i r_b,k + c r_a,k r_b,i).

It is written through the analytic eigensystem of isotropic energies (F = U Sigma V^T from
the eigen-decomposition of C; Teran et al. 2005, Smith et al. 2019): with psi_i = mu s_i - c / s_i
for the singular values s_i,
- three scaling modes U diag(z) V^T, z the eigenvectors of the 3x3 matrix
  d2psi/ds_i ds_j = delta_ij (mu + c / s_i^2) + lam / (s_i s_j);
- for each pair i < j a twist mode U (e_i e_j^T - e_j e_i^T) V^T / sqrt 2, eigenvalue
  mu - c / (s_i s_j), and a flip mode U (e_i e_j^T + e_j e_i^T) V^T / sqrt 2, eigenvalue
  mu + c / (s_i s_j).
The exact Hessian sums all nine modes; the projected one drops those with negative
eigenvalues (exactly the F-space eigenvalue clamp). The geometric part of a fiber term is not
in these modes: anisofem.physics.densities.fiber adds it.
"""
import math

from numba import njit

from ..sym3 import cofactor, eigen


@njit(cache=True, inline="always")
def stress(F, mu, lam, S):
    """Fill S (3, 3) of deformation gradient F (3, 3); returns psi (J/m^3), +inf (and S = 0)
    where J = det F <= 0. C^-1 = cof(F)^T cof(F) / J^2."""
    c00 = F[1, 1] * F[2, 2] - F[1, 2] * F[2, 1]
    c01 = F[1, 2] * F[2, 0] - F[1, 0] * F[2, 2]
    c02 = F[1, 0] * F[2, 1] - F[1, 1] * F[2, 0]
    J = F[0, 0] * c00 + F[0, 1] * c01 + F[0, 2] * c02
    if not J > 0.0:
        for i in range(3):
            for j in range(3):
                S[i, j] = 0.0
        return math.inf
    c10 = F[0, 2] * F[2, 1] - F[0, 1] * F[2, 2]
    c11 = F[0, 0] * F[2, 2] - F[0, 2] * F[2, 0]
    c12 = F[0, 1] * F[2, 0] - F[0, 0] * F[2, 1]
    c20 = F[0, 1] * F[1, 2] - F[0, 2] * F[1, 1]
    c21 = F[0, 2] * F[1, 0] - F[0, 0] * F[1, 2]
    c22 = F[0, 0] * F[1, 1] - F[0, 1] * F[1, 0]
    log_j = math.log(J)
    coef = (lam * log_j - mu) / (J * J)
    # S_ij = mu delta_ij + coef sum_k cof_ki cof_kj
    S[0, 0] = coef * (c00 * c00 + c10 * c10 + c20 * c20) + mu
    S[1, 1] = coef * (c01 * c01 + c11 * c11 + c21 * c21) + mu
    S[2, 2] = coef * (c02 * c02 + c12 * c12 + c22 * c22) + mu
    S[0, 1] = S[1, 0] = coef * (c00 * c01 + c10 * c11 + c20 * c21)
    S[0, 2] = S[2, 0] = coef * (c00 * c02 + c10 * c12 + c20 * c22)
    S[1, 2] = S[2, 1] = coef * (c01 * c02 + c11 * c12 + c21 * c22)
    trC = 0.0
    for i in range(3):
        for j in range(3):
            trC += F[i, j] * F[i, j]
    return 0.5 * mu * (trC - 3.0) - mu * log_j + 0.5 * lam * log_j * log_j


@njit(cache=True, inline="always")
def hessian(G, n, w, mu, lam, F, project, work, He):
    """Add the blocks a <= b of the Hessian above (N/m; projected: minus its modes with
    negative eigenvalues) for the n shape gradients G (n, 3), 1/m, and quadrature weight w
    (m^3) to He (3n, 3n). Adds nothing where det F <= 0 (outside the energy's domain).
    work: anisofem.physics.kernels.WORK_SHAPE scratch (rows 0-9)."""
    cof = work[0, :3]
    cofactor(F, cof)
    J = F[0, 0] * cof[0, 0] + F[0, 1] * cof[0, 1] + F[0, 2] * cof[0, 2]
    if not J > 0.0:
        return
    r = work[1, :n]
    for a in range(n):
        for i in range(3):
            r[a, i] = (cof[i, 0] * G[a, 0] + cof[i, 1] * G[a, 1] + cof[i, 2] * G[a, 2]) / J
    c = mu - lam * math.log(J)
    for a in range(n):
        for b in range(a, n):
            gg = mu * (G[a, 0] * G[b, 0] + G[a, 1] * G[b, 1] + G[a, 2] * G[b, 2])
            for i in range(3):
                for k in range(3):
                    h = lam * r[a, i] * r[b, k] + c * r[a, k] * r[b, i]
                    if i == k:
                        h += gg
                    He[3 * a + i, 3 * b + k] += w * h
    if project:
        _drop_negative_modes(G, n, w, mu, lam, F, J, c, work, He)


@njit(cache=True, inline="always")
def _drop_negative_modes(G, n, w, mu, lam, F, J, c, work, He):
    """Subtract from He the point's eigenmodes with negative eigenvalues (F = U diag(sig) V^T
    from the eigen-decomposition of C = F^T F, J = det F > 0)."""
    C, V, U, A, Z = work[2, :3], work[3, :3], work[4, :3], work[5, :3], work[6, :3]
    P = work[8, :n]
    ev, z, sig = work[9, 0], work[9, 1], work[9, 2]
    b = work[0].reshape(work.shape[1] * 3)[:3 * n]  # the cofactor rows are no longer needed
    for i in range(3):
        for j in range(3):
            C[i, j] = F[0, i] * F[0, j] + F[1, i] * F[1, j] + F[2, i] * F[2, j]
    eigen(C, ev, V)
    for k in range(3):
        sig[k] = math.sqrt(max(ev[k], 0.0))
    # rescale so that the product of the singular values is J exactly
    scale = (J / max(sig[0] * sig[1] * sig[2], 1e-300)) ** (1.0 / 3.0)
    for k in range(3):
        sig[k] *= scale
    for i in range(3):
        for k in range(3):
            U[i, k] = (F[i, 0] * V[0, k] + F[i, 1] * V[1, k] + F[i, 2] * V[2, k]) / sig[k]
    for a in range(n):
        for k in range(3):
            P[a, k] = V[0, k] * G[a, 0] + V[1, k] * G[a, 1] + V[2, k] * G[a, 2]
    # twist (sign -1) and flip (+1) modes of each pair of singular values: dF = U D V^T with
    # D = (e_i e_j^T + sign e_j e_i^T) / sqrt 2, eigenvalue mu + sign c / (s_i s_j); at most
    # one of the two is negative
    h = 1.0 / math.sqrt(2.0)
    for i in range(2):
        for j in range(i + 1, 3):
            ratio = c / (sig[i] * sig[j])
            sign = -1.0 if ratio > 0.0 else 1.0
            eigenvalue = mu - abs(ratio)
            if eigenvalue < 0.0:
                for a in range(n):
                    for k in range(3):
                        b[3 * a + k] = h * (U[k, i] * P[a, j] + sign * U[k, j] * P[a, i])
                _add_outer(He, -w * eigenvalue, b)
    # scaling modes: d2psi / ds_i ds_j = delta_ij (mu + c / s_i^2) + lam / (s_i s_j), PSD when
    # its diagonal part is
    if min(sig[0] ** 2, sig[1] ** 2, sig[2] ** 2) * mu + c >= 0.0:
        return
    for i in range(3):
        for j in range(3):
            A[i, j] = lam / (sig[i] * sig[j])
        A[i, i] += mu + c / (sig[i] * sig[i])
    eigen(A, z, Z)
    for k in range(3):
        if z[k] < 0.0:
            for a in range(n):
                for i in range(3):
                    b[3 * a + i] = (U[i, 0] * Z[0, k] * P[a, 0] + U[i, 1] * Z[1, k] * P[a, 1]
                                    + U[i, 2] * Z[2, k] * P[a, 2])
            _add_outer(He, -w * z[k], b)


@njit(cache=True, inline="always")
def _add_outer(He, coef, b):
    """He += coef b b^T over b's length (only the blocks a <= b are read later)."""
    for r in range(b.shape[0]):
        br = coef * b[r]
        for col in range(b.shape[0]):
            He[r, col] += br * b[col]
