"""Numba element kernels: energy, gradient and Hessian of StVK + fiber, and their assembly.

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

Assembly runs over element colors (no two elements of a color share a vertex), so the
elements of one color are scattered in parallel without races, and results do not depend
on the thread count.
"""
import math

import numba
import numpy as np
from numba import njit, prange

#: Below this many elements the assembly runs on one thread (parallel launches cost more).
PARALLEL_MIN_ELEMENTS = 4000


@njit(cache=True, inline="always")
def _rotate_columns(M, p, q, c, s):
    """Columns p, q of the 3-row matrix M (or rows, given M.T) times the Givens rotation
    [[c, s], [-s, c]]."""
    for k in range(3):
        mkp = M[k, p]
        mkq = M[k, q]
        M[k, p] = c * mkp - s * mkq
        M[k, q] = s * mkp + c * mkq


@njit(cache=True, inline="always")
def _sym3_positive_part(S, out):
    """Write the positive part of the symmetric 3x3 matrix S into out (cyclic Jacobi)."""
    a = S.copy()
    V = np.eye(3)
    for _sweep in range(30):
        off = a[0, 1] ** 2 + a[0, 2] ** 2 + a[1, 2] ** 2
        scale = a[0, 0] ** 2 + a[1, 1] ** 2 + a[2, 2] ** 2 + off
        if off <= 1e-32 * scale or off == 0.0:
            break
        for p in range(2):
            for q in range(p + 1, 3):
                if a[p, q] == 0.0:
                    continue
                theta = (a[q, q] - a[p, p]) / (2.0 * a[p, q])
                t = math.copysign(1.0, theta) / (abs(theta) + math.sqrt(theta * theta + 1.0))
                c = 1.0 / math.sqrt(t * t + 1.0)
                s = t * c
                _rotate_columns(a, p, q, c, s)    # a <- J^T a J
                _rotate_columns(a.T, p, q, c, s)
                _rotate_columns(V, p, q, c, s)    # V <- V J
    for i in range(3):
        for j in range(3):
            out[i, j] = 0.0
    for k in range(3):
        lam_k = a[k, k]
        if lam_k > 0.0:
            for i in range(3):
                for j in range(3):
                    out[i, j] += lam_k * V[i, k] * V[j, k]


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


@njit(cache=True, inline="always")
def _stress(e, x, tets, grads, vol, mu, lam, kappa, fdir, has_fiber, F, S, Fd):
    """Fill F (deformation gradient) and S (total 2nd Piola-Kirchhoff stress, Pa) of element e,
    and Fd = F d when it has fibers. Returns (isotropic energy, fiber energy, kappa) in J, J, Pa.
    """
    G = grads[e]
    t = tets[e]
    for i in range(3):
        for j in range(3):
            acc = 0.0
            for a in range(4):
                acc += x[t[a], i] * G[a, j]
            F[i, j] = acc
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
    m_e = mu[e]
    l_e = lam[e]
    e_iso = vol[e] * (0.5 * l_e * trE * trE + m_e * EE)
    for i in range(3):
        for j in range(3):
            S[i, j] *= 2.0 * m_e
        S[i, i] += l_e * trE
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
def _scatter_gradient(e, tets, G, v, F, S, grad):
    """grad[vertex a] += v F S G_a for the four vertices of element e (N)."""
    for i in range(3):
        P0 = F[i, 0] * S[0, 0] + F[i, 1] * S[1, 0] + F[i, 2] * S[2, 0]
        P1 = F[i, 0] * S[0, 1] + F[i, 1] * S[1, 1] + F[i, 2] * S[2, 1]
        P2 = F[i, 0] * S[0, 2] + F[i, 1] * S[1, 2] + F[i, 2] * S[2, 2]
        for a in range(4):
            grad[tets[e, a], i] += v * (P0 * G[a, 0] + P1 * G[a, 1] + P2 * G[a, 2])


@njit(cache=True, inline="always")
def _element_hessian(G, v, m_e, l_e, k_e, d, F, S, Fd, project, Sg, B, q, He):
    """Fill He (12, 12), the element Hessian in N/m (projected: S+ in the geometric part)."""
    if project and _has_negative_eigenvalue(S):
        _sym3_positive_part(S, Sg)
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


@njit(cache=True)
def _run_gradient(lo, hi, order, x, tets, grads, vol, mu, lam, kappa, fdir, has_fiber, e_iso,
                  e_fib, grad, want_grad):
    """Energies (J) and, if want_grad, gradient contributions of elements order[lo:hi]."""
    F = np.empty((3, 3))
    S = np.empty((3, 3))
    Fd = np.empty(3)
    for idx in range(lo, hi):
        e = order[idx]
        e_iso[e], e_fib[e], _ = _stress(e, x, tets, grads, vol, mu, lam, kappa, fdir, has_fiber,
                                        F, S, Fd)
        if want_grad:
            _scatter_gradient(e, tets, grads[e], vol[e], F, S, grad)


@njit(cache=True)
def _run_hessian(lo, hi, order, x, tets, grads, vol, mu, lam, kappa, fdir, has_fiber, e_iso,
                 e_fib, grad, want_grad, project, hess_map, hess_data):
    """Energies, (gradient,) and Hessian contributions of elements order[lo:hi]; hess_map[e]
    (144,) gives the position in hess_data of each He entry (-1: dropped)."""
    F = np.empty((3, 3))
    S = np.empty((3, 3))
    Fd = np.empty(3)
    Sg = np.empty((3, 3))
    B = np.empty((3, 3))
    q = np.empty((4, 3))
    He = np.empty((12, 12))
    for idx in range(lo, hi):
        e = order[idx]
        ei, ef, k_e = _stress(e, x, tets, grads, vol, mu, lam, kappa, fdir, has_fiber, F, S, Fd)
        e_iso[e] = ei
        e_fib[e] = ef
        if want_grad:
            _scatter_gradient(e, tets, grads[e], vol[e], F, S, grad)
        _element_hessian(grads[e], vol[e], mu[e], lam[e], k_e, fdir[e], F, S, Fd, project, Sg,
                         B, q, He)
        row = hess_map[e]
        for r in range(12):
            for c in range(12):
                pos = row[12 * r + c]
                if pos >= 0:
                    hess_data[pos] += He[r, c]


@njit(cache=True)
def _run_range(mode, lo, hi, order, x, tets, grads, vol, mu, lam, kappa, fdir, has_fiber,
               e_iso, e_fib, grad, want_grad, project, hess_map, hess_data):
    """mode 0: energies (+ gradient if want_grad), 2: + Hessian."""
    if mode == 0:
        _run_gradient(lo, hi, order, x, tets, grads, vol, mu, lam, kappa, fdir, has_fiber,
                      e_iso, e_fib, grad, want_grad)
    else:
        _run_hessian(lo, hi, order, x, tets, grads, vol, mu, lam, kappa, fdir, has_fiber,
                     e_iso, e_fib, grad, want_grad, project, hess_map, hess_data)


@njit(cache=True, parallel=True)
def _run_colors(nthreads, order, color_ptr, mode, x, tets, grads, vol, mu, lam, kappa, fdir,
                has_fiber, e_iso, e_fib, grad, want_grad, project, hess_map, hess_data):
    """Parallel over the elements of each color, colors one after another."""
    for c in range(color_ptr.shape[0] - 1):
        start = color_ptr[c]
        count = color_ptr[c + 1] - start
        nchunk = min(count, 4 * nthreads)
        for k in prange(nchunk):
            lo = start + (count * k) // nchunk
            hi = start + (count * (k + 1)) // nchunk
            _run_range(mode, lo, hi, order, x, tets, grads, vol, mu, lam, kappa, fdir,
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
    args = (mode, x, elements.tets, elements.grads, elements.volumes, elements.mu, elements.lam,
            elements.kappa, elements.fiber, elements.has_fiber, e_iso, e_fib, grad, want_grad,
            project, hess_map, hess_data)
    if m < PARALLEL_MIN_ELEMENTS or numba.get_num_threads() == 1:
        _run_range(mode, 0, m, elements.serial_order, *args[1:])
    else:
        _run_colors(numba.get_num_threads(), elements.color_order, elements.color_ptr, *args)
    return e_iso, e_fib, (grad if want_grad else None)


EMPTY_GRAD = np.empty((0, 3))
_EMPTY_MAP = np.empty((0, 144), dtype=np.int64)
_EMPTY_DATA = np.empty(0)
