"""Numba element kernels: energy, gradient and Hessian of StVK or Neo-Hookean + fiber, and
their assembly.

Per linear tetrahedron e with rest volume v, shape-function gradients G (4, 3) (row a is
grad N_a in material space, 1/m), deformation gradient F = sum_a x_a G_a^T (3, 3):

    psi = lam/2 tr(E)^2 + mu tr(E^2) + kappa (d^T C d - 1)^2,   Psi_e = v psi     (J)

with C = F^T F, E = (C - I)/2 and the unit fiber direction d (material space).

Total second Piola-Kirchhoff stress   S = 2 mu E + lam tr(E) I + 4 kappa (I4 - 1) d d^T,
first Piola-Kirchhoff stress          P = F S,
nodal gradient                        g_a = v P G_a                                (N)

The 4th-order tangent dP/dF splits into a material part and a geometric part:

    A[ijkl] = mu (F_il F_kj + (F F^T)_ik delta_jl) + lam F_ij F_kl + 8 kappa (Fd)_i d_j (Fd)_k d_l
              + delta_ik S_lj.

For a perturbation dF the material part gives 2 mu |sym(F^T dF)|^2 + lam tr(F^T dF)^2
+ 8 kappa ((Fd).(dF d))^2 >= 0 for every admissible material (nu in (-1, 0.5), kappa >= 0),
and the geometric part gives sum_i dF_i^T S dF_i, whose eigenvalues are those of S. Hence the
PSD projection used here ("geometric projection"): replace S in the geometric part by its
positive part S+ (clamp negative principal stresses). The projected element Hessian is PSD,
and it equals the true Hessian wherever S has no negative principal stress. It is analytic
and costs one symmetric 3x3 eigen-decomposition per element, which is why it is used instead
of a numerical 12x12 eigen-decomposition.

Element Hessian entries (a, b vertices; i, k components), with q_a = F G_a and s_a = d . G_a:

    H[3a+i, 3b+k] = v ( delta_ik G_a^T S G_b + mu q_b,i q_a,k + mu (F F^T)_ik G_a.G_b
                        + lam q_a,i q_b,k + 8 kappa (Fd)_i (Fd)_k s_a s_b ).

Neo-Hookean base (model code NEOHOOKEAN; see anisofem.material for when to pick it), with
J = det F and the same fiber term:

    psi = mu/2 (tr C - 3) - mu ln J + lam/2 (ln J)^2 + kappa (d^T C d - 1)^2,   psi = +inf for J <= 0

S = mu (I - C^-1) + lam ln J C^-1 + 4 kappa (I4 - 1) d d^T, so the gradient is the same
v F S G_a. Its isotropic Hessian is written through the analytic eigensystem of isotropic
energies (F = U Sigma V^T from the eigen-decomposition of C; Teran et al. 2005, Smith et al.
2019): with psi_i = mu s_i - c / s_i and c = mu - lam ln J for the singular values s_i,
- three scaling modes U diag(z) V^T, z the eigenvectors of the 3x3 matrix
  d2psi/ds_i ds_j = delta_ij (mu + c / s_i^2) + lam / (s_i s_j);
- for each pair i < j a twist mode U (e_i e_j^T - e_j e_i^T) V^T / sqrt 2, eigenvalue
  mu - c / (s_i s_j), and a flip mode U (e_i e_j^T + e_j e_i^T) V^T / sqrt 2, eigenvalue
  mu + c / (s_i s_j).
The exact Hessian sums all nine modes; the projected one drops those with negative
eigenvalues. The fiber term adds 8 kappa (Fd)(Fd)^T s_a s_b (PSD) and the geometric
4 kappa (I4 - 1) s_a s_b delta_ik, dropped when projecting with I4 < 1.

Assembly runs over colored blocks of consecutive elements (anisofem.mesh.ASSEMBLY_BLOCK; no
two blocks of a color share a vertex), so the blocks of one color are scattered in parallel
without races, each thread reading and adding to one neighbourhood at a time, and results do
not depend on the thread count.
"""
import math

import numpy as np
from numba import njit, prange

from .mesh import ASSEMBLY_BLOCK

#: Below this many elements the assembly runs on one thread (parallel launches cost more).
PARALLEL_MIN_ELEMENTS = 4000


@njit(cache=True, inline="always")
def _sym3_eigen(a, w, V):
    """Eigenvalues w (3,) and orthonormal eigenvectors (columns of V, 3x3) of the symmetric
    3x3 matrix a (read only). Closed form, after Eberly's robust scheme: of B = (a - tr(a)/3 I)
    / p, the root of the characteristic cubic farthest from the other two (trigonometric
    solution; it is accurate where the other two nearly coincide), its eigenvector as the
    longest cross product of two rows of B - beta I, the other two from the 2x2 restriction
    of B to the orthogonal plane, diagonalized by one Jacobi rotation; the eigenvalues are the
    Rayleigh quotients. No iteration, accurate for nearly repeated eigenvalues too."""
    m = max(abs(a[0, 0]), abs(a[0, 1]), abs(a[0, 2]), abs(a[1, 1]), abs(a[1, 2]),
            abs(a[2, 2]))
    for i in range(3):
        for j in range(3):
            V[i, j] = 1.0 if i == j else 0.0
    if m == 0.0:
        w[0] = w[1] = w[2] = 0.0
        return
    q = (a[0, 0] + a[1, 1] + a[2, 2]) / (3.0 * m)
    b00, b11, b22 = a[0, 0] / m - q, a[1, 1] / m - q, a[2, 2] / m - q
    b01, b02, b12 = a[0, 1] / m, a[0, 2] / m, a[1, 2] / m
    p = math.sqrt((b00 * b00 + b11 * b11 + b22 * b22
                   + 2.0 * (b01 * b01 + b02 * b02 + b12 * b12)) / 6.0)
    if p == 0.0:
        w[0] = w[1] = w[2] = q * m
        return
    b00, b11, b22, b01, b02, b12 = b00 / p, b11 / p, b22 / p, b01 / p, b02 / p, b12 / p
    half_det = 0.5 * (b00 * (b11 * b22 - b12 * b12) - b01 * (b01 * b22 - b12 * b02)
                      + b02 * (b01 * b12 - b11 * b02))
    phi = math.acos(min(1.0, max(-1.0, half_det))) / 3.0
    # the root farthest from the other two: the largest when half_det >= 0, else the smallest
    beta = 2.0 * math.cos(phi if half_det >= 0.0 else phi + 2.0 * math.pi / 3.0)
    e0, e1, e2 = V[:, 0], V[:, 1], V[:, 2]
    if not _null_vector(b00 - beta, b01, b02, b11 - beta, b12, b22 - beta, e0):
        e0[0], e0[1], e0[2] = 1.0, 0.0, 0.0
    # u, v: an orthonormal basis of the plane orthogonal to e0
    if abs(e0[0]) > abs(e0[1]):
        inv = 1.0 / math.sqrt(e0[0] * e0[0] + e0[2] * e0[2])
        u0, u1, u2 = -e0[2] * inv, 0.0, e0[0] * inv
    else:
        inv = 1.0 / math.sqrt(e0[1] * e0[1] + e0[2] * e0[2])
        u0, u1, u2 = 0.0, e0[2] * inv, -e0[1] * inv
    v0, v1, v2 = e0[1] * u2 - e0[2] * u1, e0[2] * u0 - e0[0] * u2, e0[0] * u1 - e0[1] * u0
    # the 2x2 restriction [u v]^T B [u v], diagonalized by one Jacobi rotation
    bu0 = b00 * u0 + b01 * u1 + b02 * u2
    bu1 = b01 * u0 + b11 * u1 + b12 * u2
    bu2 = b02 * u0 + b12 * u1 + b22 * u2
    bv0 = b00 * v0 + b01 * v1 + b02 * v2
    bv1 = b01 * v0 + b11 * v1 + b12 * v2
    bv2 = b02 * v0 + b12 * v1 + b22 * v2
    m00 = u0 * bu0 + u1 * bu1 + u2 * bu2
    m01 = u0 * bv0 + u1 * bv1 + u2 * bv2
    m11 = v0 * bv0 + v1 * bv1 + v2 * bv2
    c, s = 1.0, 0.0
    if m01 != 0.0:
        theta = (m11 - m00) / (2.0 * m01)
        t = math.copysign(1.0, theta) / (abs(theta) + math.sqrt(theta * theta + 1.0))
        c = 1.0 / math.sqrt(t * t + 1.0)
        s = t * c
    e1[0], e1[1], e1[2] = c * u0 - s * v0, c * u1 - s * v1, c * u2 - s * v2
    e2[0], e2[1], e2[2] = s * u0 + c * v0, s * u1 + c * v1, s * u2 + c * v2
    # Rayleigh quotients: accurate where the trigonometric roots are not (nearly double ones)
    for k in range(3):
        e = V[:, k]
        w[k] = m * (q + p * (b00 * e[0] * e[0] + b11 * e[1] * e[1] + b22 * e[2] * e[2]
                             + 2.0 * (b01 * e[0] * e[1] + b02 * e[0] * e[2] + b12 * e[1] * e[2])))


@njit(cache=True, inline="always")
def _null_vector(a00, a01, a02, a11, a12, a22, out):
    """Write into out a unit vector orthogonal to the rows of the symmetric 3x3 matrix given
    by its upper triangle (rank 2): their longest cross product. False where all vanish."""
    x0, y0, z0 = a01 * a12 - a02 * a11, a02 * a01 - a00 * a12, a00 * a11 - a01 * a01
    x1, y1, z1 = a01 * a22 - a02 * a12, a02 * a02 - a00 * a22, a00 * a12 - a01 * a02
    x2, y2, z2 = a11 * a22 - a12 * a12, a12 * a02 - a01 * a22, a01 * a12 - a11 * a02
    n0 = x0 * x0 + y0 * y0 + z0 * z0
    n1 = x1 * x1 + y1 * y1 + z1 * z1
    n2 = x2 * x2 + y2 * y2 + z2 * z2
    if n0 >= n1 and n0 >= n2:
        x, y, z, n = x0, y0, z0, n0
    elif n1 >= n2:
        x, y, z, n = x1, y1, z1, n1
    else:
        x, y, z, n = x2, y2, z2, n2
    if n == 0.0:
        return False
    inv = 1.0 / math.sqrt(n)
    out[0], out[1], out[2] = x * inv, y * inv, z * inv
    return True


@njit(cache=True, inline="always")
def _sym3_positive_part(S, out, w, V):
    """Write the positive part of the symmetric 3x3 matrix S into out (w (3,), V (3, 3):
    scratch)."""
    for i in range(3):
        for j in range(3):
            out[i, j] = S[i, j]
    _sym3_eigen(out, w, V)
    for i in range(3):
        for j in range(3):
            out[i, j] = 0.0
    for k in range(3):
        if w[k] > 0.0:
            for i in range(3):
                for j in range(3):
                    out[i, j] += w[k] * V[i, k] * V[j, k]


@njit(cache=True, inline="always")
def _has_negative_eigenvalue(S):
    """True when the symmetric 3x3 matrix S is not positive semi-definite (Sylvester test)."""
    if S[0, 0] < 0.0 or S[1, 1] < 0.0 or S[2, 2] < 0.0:
        return True
    if S[0, 0] * S[1, 1] - S[0, 1] ** 2 < 0.0:
        return True
    if S[0, 0] * S[2, 2] - S[0, 2] ** 2 < 0.0:
        return True
    if S[1, 1] * S[2, 2] - S[1, 2] ** 2 < 0.0:
        return True
    det = (S[0, 0] * (S[1, 1] * S[2, 2] - S[1, 2] * S[2, 1])
           - S[0, 1] * (S[1, 0] * S[2, 2] - S[1, 2] * S[2, 0])
           + S[0, 2] * (S[1, 0] * S[2, 1] - S[1, 1] * S[2, 0]))
    return det < 0.0


#: Model codes of ElementData.model.
STVK, NEOHOOKEAN = 0, 1


@njit(cache=True, inline="always")
def _stress(e, x, tets, grads, vol, model, mu, lam, kappa, fdir, has_fiber, F, S, Fd):
    """Fill F (deformation gradient) and S (total 2nd Piola-Kirchhoff stress, Pa) of element e,
    and Fd = F d when it has fibers. Returns (isotropic energy, fiber energy, kappa) in J, J, Pa;
    a Neo-Hookean element with det F <= 0 has isotropic energy +inf (and S = 0)."""
    G = grads[e]
    t = tets[e]
    for i in range(3):
        for j in range(3):
            acc = 0.0
            for a in range(4):
                acc += x[t[a], i] * G[a, j]
            F[i, j] = acc
    m_e = mu[e]
    l_e = lam[e]
    if model[e] == NEOHOOKEAN:
        e_iso = _neohookean_stress(F, m_e, l_e, S) * vol[e]
    else:
        e_iso = _stvk_stress(F, m_e, l_e, S) * vol[e]
    k_e = kappa[e] if has_fiber else 0.0
    if k_e == 0.0:
        return e_iso, 0.0, 0.0
    d = fdir[e]
    for i in range(3):
        Fd[i] = F[i, 0] * d[0] + F[i, 1] * d[1] + F[i, 2] * d[2]
    I4m1 = Fd[0] * Fd[0] + Fd[1] * Fd[1] + Fd[2] * Fd[2] - 1.0
    c = 4.0 * k_e * I4m1
    for i in range(3):
        for j in range(3):
            S[i, j] += c * d[i] * d[j]
    return e_iso, vol[e] * k_e * I4m1 * I4m1, k_e


@njit(cache=True, inline="always")
def _stvk_stress(F, m_e, l_e, S):
    """S = 2 mu E + lam tr(E) I of Saint Venant-Kirchhoff; returns psi (J/m^3)."""
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
            S[i, j] *= 2.0 * m_e
        S[i, i] += l_e * trE
    return 0.5 * l_e * trE * trE + m_e * EE


@njit(cache=True, inline="always")
def _neohookean_stress(F, m_e, l_e, S):
    """S = mu (I - C^-1) + lam ln J C^-1 of Neo-Hookean; returns psi (J/m^3), +inf (S = 0)
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
    coef = (l_e * log_j - m_e) / (J * J)
    # S_ij = mu delta_ij + coef sum_k cof_ki cof_kj
    S[0, 0] = coef * (c00 * c00 + c10 * c10 + c20 * c20) + m_e
    S[1, 1] = coef * (c01 * c01 + c11 * c11 + c21 * c21) + m_e
    S[2, 2] = coef * (c02 * c02 + c12 * c12 + c22 * c22) + m_e
    S[0, 1] = S[1, 0] = coef * (c00 * c01 + c10 * c11 + c20 * c21)
    S[0, 2] = S[2, 0] = coef * (c00 * c02 + c10 * c12 + c20 * c22)
    S[1, 2] = S[2, 1] = coef * (c01 * c02 + c11 * c12 + c21 * c22)
    trC = 0.0
    for i in range(3):
        for j in range(3):
            trC += F[i, j] * F[i, j]
    return 0.5 * m_e * (trC - 3.0) - m_e * log_j + 0.5 * l_e * log_j * log_j


@njit(cache=True, inline="always")
def _scatter_gradient(e, tets, G, v, F, S, grad):
    """grad[vertex a] += v F S G_a for the four vertices of element e (N)."""
    for i in range(3):
        P0 = F[i, 0] * S[0, 0] + F[i, 1] * S[1, 0] + F[i, 2] * S[2, 0]
        P1 = F[i, 0] * S[0, 1] + F[i, 1] * S[1, 1] + F[i, 2] * S[2, 1]
        P2 = F[i, 0] * S[0, 2] + F[i, 1] * S[1, 2] + F[i, 2] * S[2, 2]
        for a in range(4):
            grad[tets[e, a], i] += v * (P0 * G[a, 0] + P1 * G[a, 1] + P2 * G[a, 2])


@njit(cache=True, inline="always")
def _element_hessian(G, v, model, m_e, l_e, k_e, d, F, S, Fd, project, Sg, B, q, work, He):
    """Fill He (12, 12), the element Hessian in N/m (projected: see the module docstring)."""
    if model == NEOHOOKEAN:
        _neohookean_hessian(G, v, m_e, l_e, F, project, work, He)
        if k_e != 0.0:
            c = 4.0 * k_e * (Fd[0] * Fd[0] + Fd[1] * Fd[1] + Fd[2] * Fd[2] - 1.0)
            if not (project and c < 0.0):
                for a in range(4):
                    sa = v * c * (d[0] * G[a, 0] + d[1] * G[a, 1] + d[2] * G[a, 2])
                    for b in range(a, 4):
                        sab = sa * (d[0] * G[b, 0] + d[1] * G[b, 1] + d[2] * G[b, 2])
                        for i in range(3):
                            He[3 * a + i, 3 * b + i] += sab
    else:
        _stvk_hessian(G, v, m_e, l_e, F, S, project, Sg, B, q, work, He)
    if k_e != 0.0:
        for a in range(4):
            sa = 8.0 * k_e * v * (d[0] * G[a, 0] + d[1] * G[a, 1] + d[2] * G[a, 2])
            for b in range(a, 4):
                sab = sa * (d[0] * G[b, 0] + d[1] * G[b, 1] + d[2] * G[b, 2])
                for i in range(3):
                    for k in range(3):
                        He[3 * a + i, 3 * b + k] += sab * Fd[i] * Fd[k]
    for a in range(4):
        for b in range(a + 1, 4):
            for i in range(3):
                for k in range(3):
                    He[3 * b + k, 3 * a + i] = He[3 * a + i, 3 * b + k]


@njit(cache=True, inline="always")
def _stvk_hessian(G, v, m_e, l_e, F, S, project, Sg, B, q, work, He):
    """Blocks a <= b of the StVK element Hessian with the total stress S in its geometric part
    (projected: S+), N/m. work: WORK_SHAPE scratch."""
    if project and _has_negative_eigenvalue(S):
        _sym3_positive_part(S, Sg, work[9, 0], work[3, :3])
    else:
        for i in range(3):
            for j in range(3):
                Sg[i, j] = S[i, j]
    for a in range(4):
        for i in range(3):
            q[a, i] = F[i, 0] * G[a, 0] + F[i, 1] * G[a, 1] + F[i, 2] * G[a, 2]
    for i in range(3):
        for k in range(3):
            B[i, k] = m_e * (F[i, 0] * F[k, 0] + F[i, 1] * F[k, 1] + F[i, 2] * F[k, 2])
    for a in range(4):
        for b in range(a, 4):
            geo = 0.0
            for i in range(3):
                geo += G[a, i] * (Sg[i, 0] * G[b, 0] + Sg[i, 1] * G[b, 1] + Sg[i, 2] * G[b, 2])
            gg = G[a, 0] * G[b, 0] + G[a, 1] * G[b, 1] + G[a, 2] * G[b, 2]
            for i in range(3):
                for k in range(3):
                    h = m_e * q[b, i] * q[a, k] + l_e * q[a, i] * q[b, k] + B[i, k] * gg
                    He[3 * a + i, 3 * b + k] = v * h
            for i in range(3):
                He[3 * a + i, 3 * b + i] += v * geo


#: Shape of the scratch array of _neohookean_hessian.
WORK_SHAPE = (10, 4, 3)


@njit(cache=True, inline="always")
def _neohookean_hessian(G, v, m_e, l_e, F, project, work, He):
    """Blocks a <= b of the isotropic Neo-Hookean element Hessian, N/m:

        H[3a+i, 3b+k] = v (mu delta_ik G_a.G_b + lam r_a,i r_b,k + c r_a,k r_b,i),

    r_a = F^-T G_a, c = mu - lam ln J; projected: minus its modes with negative eigenvalues
    (see the module docstring). work: WORK_SHAPE scratch. Zero where det F <= 0 (outside the
    energy's domain)."""
    for r in range(12):
        for col in range(12):
            He[r, col] = 0.0
    cof = work[0, :3]
    _cofactor(F, cof)
    J = F[0, 0] * cof[0, 0] + F[0, 1] * cof[0, 1] + F[0, 2] * cof[0, 2]
    if not J > 0.0:
        return
    r = work[1]
    for a in range(4):
        for i in range(3):
            r[a, i] = (cof[i, 0] * G[a, 0] + cof[i, 1] * G[a, 1] + cof[i, 2] * G[a, 2]) / J
    c = m_e - l_e * math.log(J)
    for a in range(4):
        for b in range(a, 4):
            gg = m_e * (G[a, 0] * G[b, 0] + G[a, 1] * G[b, 1] + G[a, 2] * G[b, 2])
            for i in range(3):
                for k in range(3):
                    h = l_e * r[a, i] * r[b, k] + c * r[a, k] * r[b, i]
                    if i == k:
                        h += gg
                    He[3 * a + i, 3 * b + k] = v * h
    if project:
        _drop_negative_modes(G, v, m_e, l_e, F, J, c, work, He)


@njit(cache=True, inline="always")
def _cofactor(F, cof):
    """cof = the cofactor matrix of the 3x3 F (det F = F[0] . cof[0])."""
    cof[0, 0] = F[1, 1] * F[2, 2] - F[1, 2] * F[2, 1]
    cof[0, 1] = F[1, 2] * F[2, 0] - F[1, 0] * F[2, 2]
    cof[0, 2] = F[1, 0] * F[2, 1] - F[1, 1] * F[2, 0]
    cof[1, 0] = F[0, 2] * F[2, 1] - F[0, 1] * F[2, 2]
    cof[1, 1] = F[0, 0] * F[2, 2] - F[0, 2] * F[2, 0]
    cof[1, 2] = F[0, 1] * F[2, 0] - F[0, 0] * F[2, 1]
    cof[2, 0] = F[0, 1] * F[1, 2] - F[0, 2] * F[1, 1]
    cof[2, 1] = F[0, 2] * F[1, 0] - F[0, 0] * F[1, 2]
    cof[2, 2] = F[0, 0] * F[1, 1] - F[0, 1] * F[1, 0]


@njit(cache=True, inline="always")
def _drop_negative_modes(G, v, m_e, l_e, F, J, c, work, He):
    """Subtract from the Neo-Hookean element Hessian its eigenmodes with negative eigenvalues
    (F = U diag(sig) V^T from the eigen-decomposition of C = F^T F, J = det F > 0)."""
    C, V, U, A, Z = work[2, :3], work[3, :3], work[4, :3], work[5, :3], work[6, :3]
    P = work[8]
    w, z, sig = work[9, 0], work[9, 1], work[9, 2]
    b = work[0].reshape(12)  # the cofactor rows are no longer needed
    for i in range(3):
        for j in range(3):
            C[i, j] = F[0, i] * F[0, j] + F[1, i] * F[1, j] + F[2, i] * F[2, j]
    _sym3_eigen(C, w, V)
    for k in range(3):
        sig[k] = math.sqrt(max(w[k], 0.0))
    # rescale so that the product of the singular values is J exactly
    scale = (J / max(sig[0] * sig[1] * sig[2], 1e-300)) ** (1.0 / 3.0)
    for k in range(3):
        sig[k] *= scale
    for i in range(3):
        for k in range(3):
            U[i, k] = (F[i, 0] * V[0, k] + F[i, 1] * V[1, k] + F[i, 2] * V[2, k]) / sig[k]
    for a in range(4):
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
            eigenvalue = m_e - abs(ratio)
            if eigenvalue < 0.0:
                for a in range(4):
                    for k in range(3):
                        b[3 * a + k] = h * (U[k, i] * P[a, j] + sign * U[k, j] * P[a, i])
                _add_outer(He, -v * eigenvalue, b)
    # scaling modes: d2psi / ds_i ds_j = delta_ij (mu + c / s_i^2) + lam / (s_i s_j), PSD when
    # its diagonal part is
    if min(sig[0] ** 2, sig[1] ** 2, sig[2] ** 2) * m_e + c >= 0.0:
        return
    for i in range(3):
        for j in range(3):
            A[i, j] = l_e / (sig[i] * sig[j])
        A[i, i] += m_e + c / (sig[i] * sig[i])
    _sym3_eigen(A, z, Z)
    for k in range(3):
        if z[k] < 0.0:
            for a in range(4):
                for i in range(3):
                    b[3 * a + i] = (U[i, 0] * Z[0, k] * P[a, 0] + U[i, 1] * Z[1, k] * P[a, 1]
                                    + U[i, 2] * Z[2, k] * P[a, 2])
            _add_outer(He, -v * z[k], b)


@njit(cache=True, inline="always")
def _add_outer(He, coef, b):
    """He += coef b b^T (12x12; only the blocks a <= b are read later)."""
    for r in range(12):
        br = coef * b[r]
        for col in range(12):
            He[r, col] += br * b[col]


@njit(cache=True)
def _run_gradient(lo, hi, x, tets, grads, vol, model, mu, lam, kappa, fdir, has_fiber,
                  e_iso, e_fib, grad, want_grad):
    """Energies (J) and, if want_grad, gradient contributions of elements lo to hi - 1."""
    F = np.empty((3, 3))
    S = np.empty((3, 3))
    Fd = np.empty(3)
    for e in range(lo, hi):
        e_iso[e], e_fib[e], _ = _stress(e, x, tets, grads, vol, model, mu, lam, kappa, fdir,
                                        has_fiber, F, S, Fd)
        if want_grad:
            _scatter_gradient(e, tets, grads[e], vol[e], F, S, grad)


@njit(cache=True)
def _run_hessian(lo, hi, x, tets, grads, vol, model, mu, lam, kappa, fdir, has_fiber,
                 e_iso, e_fib, grad, want_grad, project, hess_map, hess_data):
    """Energies, (gradient,) and Hessian contributions of elements lo to hi - 1; hess_map[e]
    (144,) gives the position in hess_data of each He entry (-1: dropped)."""
    F = np.empty((3, 3))
    S = np.empty((3, 3))
    Fd = np.empty(3)
    Sg = np.empty((3, 3))
    B = np.empty((3, 3))
    q = np.empty((4, 3))
    He = np.empty((12, 12))
    work = np.empty(WORK_SHAPE)
    for e in range(lo, hi):
        ei, ef, k_e = _stress(e, x, tets, grads, vol, model, mu, lam, kappa, fdir, has_fiber, F,
                              S, Fd)
        e_iso[e] = ei
        e_fib[e] = ef
        if want_grad:
            _scatter_gradient(e, tets, grads[e], vol[e], F, S, grad)
        _element_hessian(grads[e], vol[e], model[e], mu[e], lam[e], k_e, fdir[e], F, S, Fd,
                         project, Sg, B, q, work, He)
        row = hess_map[e]
        for r in range(12):
            for c in range(12):
                pos = row[12 * r + c]
                if pos >= 0:
                    hess_data[pos] += He[r, c]


@njit(cache=True)
def _run_range(mode, lo, hi, x, tets, grads, vol, model, mu, lam, kappa, fdir,
               has_fiber, e_iso, e_fib, grad, want_grad, project, hess_map, hess_data):
    """mode 0: energies (+ gradient if want_grad), 2: + Hessian."""
    if mode == 0:
        _run_gradient(lo, hi, x, tets, grads, vol, model, mu, lam, kappa, fdir,
                      has_fiber, e_iso, e_fib, grad, want_grad)
    else:
        _run_hessian(lo, hi, x, tets, grads, vol, model, mu, lam, kappa, fdir,
                     has_fiber, e_iso, e_fib, grad, want_grad, project, hess_map, hess_data)


@njit(cache=True, parallel=True)
def _run_colors(starts, color_ptr, mode, x, tets, grads, vol, model, mu, lam, kappa, fdir,
                has_fiber, e_iso, e_fib, grad, want_grad, project, hess_map, hess_data):
    """The assembly blocks of each color in parallel (each block's tets in order), colors one
    after another: every sum over elements runs in the same order whatever the threads."""
    m = tets.shape[0]
    for c in range(color_ptr.shape[0] - 1):
        for k in prange(color_ptr[c + 1] - color_ptr[c]):
            lo = starts[color_ptr[c] + k]
            hi = min(lo + ASSEMBLY_BLOCK, m)
            _run_range(mode, lo, hi, x, tets, grads, vol, model, mu, lam, kappa, fdir,
                       has_fiber, e_iso, e_fib, grad, want_grad, project, hess_map, hess_data)


@njit(cache=True)
def loads_and_inertia(x, f_ext, mass_over_dt2, x_hat, grad):
    """Energies of the external load, -f_ext . x, and of inertia,
    1/2 sum_i m_i/dt^2 |x_i - x_hat_i|^2 (0 when mass_over_dt2 is empty: statics), in J;
    their gradient is added to grad unless grad is empty. x, f_ext, x_hat, grad: (n, 3)."""
    external = 0.0
    kinetic = 0.0
    dynamic = mass_over_dt2.shape[0] > 0
    with_grad = grad.shape[0] > 0
    for i in range(x.shape[0]):
        for c in range(3):
            external -= f_ext[i, c] * x[i, c]
            g = -f_ext[i, c]
            if dynamic:
                dx = x[i, c] - x_hat[i, c]
                kinetic += 0.5 * mass_over_dt2[i] * dx * dx
                g += mass_over_dt2[i] * dx
            if with_grad:
                grad[i, c] += g
    return external, kinetic


def assemble(x, elements, *, want_grad=False, want_hess=False, project=False, hess_map=None,
             hess_data=None):
    """Element energies, and optionally the assembled elastic gradient and Hessian.

    x: (n, 3) float64 positions (m). elements: an ElementData (see anisofem.scene).
    hess_map: (m, 144) int64 positions of each element-matrix entry in hess_data (-1: dropped),
    hess_data: float64 array to which the Hessian entries are added (caller zeroes it).
    Returns (e_iso (m,), e_fiber (m,), grad (n, 3) or None), energies in J, gradient in N.
    """
    m = elements.tets.shape[0]
    e_iso = np.empty(m)
    e_fib = np.empty(m)
    grad = np.zeros_like(x) if want_grad else EMPTY_GRAD
    if not want_hess:
        hess_map, hess_data = _EMPTY_MAP, _EMPTY_DATA
    mode = 2 if want_hess else 0
    args = (mode, x, elements.tets, elements.grads, elements.volumes, elements.model,
            elements.mu, elements.lam, elements.kappa, elements.fiber, elements.has_fiber, e_iso,
            e_fib, grad, want_grad, project, hess_map, hess_data)
    if m < PARALLEL_MIN_ELEMENTS:
        _run_range(mode, 0, m, *args[1:])
    else:
        _run_colors(elements.block_starts, elements.color_ptr, *args)
    return e_iso, e_fib, (grad if want_grad else None)


EMPTY_GRAD = np.empty((0, 3))
_EMPTY_MAP = np.empty((0, 144), dtype=np.int64)
_EMPTY_DATA = np.empty(0)
