"""The exact elastic energy of a reduced model, a quartic polynomial in its coordinates q (r,).

With x = x0 + U q, Green's strain at a quadrature point is E(q) = E0 + sum_j q_j L_j + 1/2
sum_jk q_j q_k M_jk, where F0 is the deformation gradient of x0, B_j that of the basis column
U_j, L_j = sym(F0^T B_j) and M_jk = sym(B_j^T B_k). Saint Venant-Kirchhoff and the fiber term
are quadratic forms of E:

    psi = 1/2 a(E, E),  a(X, Y) = lam tr X tr Y + 2 mu X : Y + 8 kappa (d^T X d)(d^T Y d),

so the energy V(q) = sum_p w_p psi(E_p(q)) over every element's quadrature points is

    V(q) = c0 + c1 . q + 1/2 q^T C2 q + S3[q, q, q] + S4[q, q, q, q],

S3 and S4 fully symmetric tensors. The coefficients are summed once per quadrature point of
any element type (anisofem.physics.scene.ElementData), whatever the mesh; afterwards an evaluation
costs O(r^4 / 6) and no mesh data. With Y = S3[q] and X = S4[q, q] (r, r):

    V = c0 + c1 . q + q^T (C2 / 2 + Y + X) q,   dV/dq = c1 + (C2 + 3 Y + 4 X) q,
    d2V/dq2 = C2 + 6 Y + 12 X.

S4 is stored as W4 (T, r), T = r (r + 1) (r + 2) / 6: row t holds S4[a, b, c, :] for the t-th
sorted triple a <= b <= c, so X costs one pass over W4 (anisofem.reduced.kernels).

A pressure on a cavity (anisofem.physics.pressure) adds -p times the cavity's volume, a cubic of the
positions: its part is summed into c0 to S3 (with_pressure), exact too.

Activated fibers (rest stretch s, b = 1 - s^2) add to the passive fiber term
kappa (I4 - 1)^2 the term kappa (2 b (I4 - 1) + b^2) = 4 kappa b d^T E d + kappa b^2, a
quadratic of q scaled by b (activation_terms): polynomial() sums it in for the elements'
own activation, and a model's activation controls keep it apart (anisofem.reduced.controls).
"""
import itertools
import math
from dataclasses import dataclass

import numpy as np

from . import kernels

#: Quadrature points whose strains a coefficient sum forms at once (memory: about 6 * CHUNK *
#: r^2 / 2 floats).
CHUNK = 256

#: Voigt order of a symmetric 3x3 tensor: (00, 11, 22, 01, 02, 12); off-diagonal entries are
#: scaled by sqrt 2 so that X : Y is the dot product.
_VOIGT = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))
_ROOT2 = math.sqrt(2.0)


@dataclass
class Polynomial:
    """V(q) (module docstring): c0 J, c1 (r,) N, C2 (r, r) N/m, S3 (r, r, r) N/m^2, W4 (T, r)
    N/m^3, its rows the sorted triples a <= b <= c in lexicographic order (q in m sqrt(kg)
    of a mass-orthonormal basis, so N here is per sqrt(kg))."""
    c0: float
    c1: np.ndarray
    C2: np.ndarray
    S3: np.ndarray
    W4: np.ndarray

    @property
    def r(self):
        return self.c1.size

    def _arguments(self, q):
        q = np.ascontiguousarray(q, dtype=float)
        return self.S3.reshape(self.r ** 2, self.r), kernels.matvec(self.W4, q), q

    def energy(self, q):
        """V(q), J."""
        return kernels.energy(self.c0, self.c1, self.C2, *self._arguments(q))

    def gradient(self, q, hessian=False):
        """dV/dq (r,), N; with hessian=True also d2V/dq2 (r, r), N/m."""
        g, H = kernels.derivatives(self.c1, self.C2, *self._arguments(q), 0.0)
        return (g, H) if hessian else g


def build_bytes(r, points):
    """Bytes the largest arrays of polynomial() hold at once for r coordinates and `points`
    quadrature points (an upper estimate, float64 and int64): the pair sums Q4 (P^2, P = r (r +
    1) / 2) and T3, a chunk's strains, and the symmetrization's index and value arrays (about
    6 T r for W4, T = r (r + 1) (r + 2) / 6, and 8 r^3 for S3). The build's measured peak
    growth on the 200-tet beam was 1.14x this at r = 44, 0.75x at r = 90."""
    pairs = r * (r + 1) // 2
    triples = r * (r + 1) * (r + 2) // 6
    chunk = min(CHUNK, points)
    return 8 * (pairs ** 2 + r * pairs + 18 * chunk * pairs + 8 * r ** 3 + 6 * triples * r)


def polynomial(elements, x0, basis):
    """The Polynomial of the StVK + fiber energy of `elements` (ElementData) at positions
    x0 + basis q, x0 (n, 3) m, basis (3n, r)."""
    r = basis.shape[1]
    U = basis.reshape(-1, 3, r)
    pi, pj = np.triu_indices(r)
    multiplicity = np.where(pi == pj, 1.0, 2.0)
    c0, c1, C2 = 0.0, np.zeros(r), np.zeros((r, r))
    T3, Q4 = np.zeros((r, pi.size)), np.zeros((pi.size, pi.size))
    m, nq = elements.weights.shape
    block = max(1, CHUNK // nq)
    for lo in range(0, m, block):
        e0, L, M = _whitened_strains(elements, slice(lo, lo + block), x0, U, pi, pj)
        c0 += 0.5 * float(e0 @ e0)
        c1 += L.T @ e0
        C2 += L.T @ L
        C2[pi, pj] += M.T @ e0
        M *= multiplicity
        T3 += L.T @ M
        Q4 += M.T @ M
    C2 = np.triu(C2) + np.triu(C2, 1).T  # the M part was summed on the upper triangle
    S3, W4 = _symmetric(T3, Q4, r, pi, pj, multiplicity)
    share = 1.0 - elements.rest2
    if share.any():
        (a0, a1, A2), constant = activation_terms(elements, share, x0, basis)
        c0, c1, C2 = c0 + a0 + constant, c1 + a1, C2 + A2
    return Polynomial(c0, c1, C2, S3, W4)


def activation_terms(elements, share, x0, basis):
    """The activated fibers' part of the energy at x0 + basis q with b = share (m,) per element
    (b = 1 - s^2): ((c0 J, c1 (r,) N, C2 (r, r) N/m) of sum 4 w kappa b d^T E(q) d, and the
    constant sum w kappa b^2, J). With F0 d = f and B_j d = g_j at a quadrature point,
    d^T E d = (|f|^2 - 1) / 2 + q_j f . g_j + q_j q_k g_j . g_k / 2."""
    r = basis.shape[1]
    U = basis.reshape(-1, 3, r)
    rows = np.flatnonzero(share * elements.kappa)
    c0, c1, C2 = 0.0, np.zeros(r), np.zeros((r, r))
    nq = elements.weights.shape[1]
    block = max(1, CHUNK // nq)
    for lo in range(0, rows.size, block):
        e = rows[lo:lo + block]
        tets = elements.tets[e]
        gd = np.einsum("eqaj,ej->eqa", elements.grads[e], elements.fiber[e])   # grad N_a . d
        f = np.einsum("eai,eqa->eqi", x0[tets], gd)                            # F0 d
        g = np.einsum("eair,eqa->eqri", U[tets], gd)                           # B_j d
        weight = 4.0 * elements.weights[e] * (elements.kappa[e] * share[e])[:, None]
        c0 += 0.5 * float((weight * ((f * f).sum(-1) - 1.0)).sum())
        c1 += np.einsum("eq,eqi,eqri->r", weight, f, g)
        C2 += np.einsum("eq,eqri,eqsi->rs", weight, g, g)
    constant = float((elements.weights.sum(1) * elements.kappa * share ** 2).sum())
    return (c0, c1, C2), constant


def _symmetric(T3, Q4, r, pi, pj, multiplicity):
    """S3 (r, r, r) and W4 (T, r) from the pair-indexed sums
    T3[j, (kl)] = sum c_kl a(L_j, M_kl) and Q4[(jk), (lm)] = sum c_jk c_lm a(M_jk, M_lm) (c a
    pair's multiplicity): the energy's cubic part is 1/2 sum a(L_j, M_kl) q_j q_k q_l over all
    j, k, l and its quartic part 1/8 sum a(M_jk, M_lm) q_j q_k q_l q_m, symmetrized over the
    index orders that give the same monomial."""
    pair = np.zeros((r, r), dtype=np.int64)
    pair[pi, pj] = pair[pj, pi] = np.arange(pi.size)
    count = multiplicity[pair]
    j, k, l = np.meshgrid(*(np.arange(r),) * 3, indexing="ij")

    def cubic(a, b, c):
        return 0.5 * T3[a, pair[b, c]] / count[b, c]
    S3 = (cubic(j, k, l) + cubic(k, j, l) + cubic(l, j, k)) / 3.0
    triples = np.array(list(itertools.combinations_with_replacement(range(r), 3)),
                       dtype=np.int64).reshape(-1, 3)
    a, b, c = (triples[:, i, None] for i in range(3))
    d = np.arange(r)[None, :]

    def quartic(a, b, c, d):
        return 0.125 * Q4[pair[a, b], pair[c, d]] / (count[a, b] * count[c, d])
    W4 = (quartic(a, b, c, d) + quartic(a, c, b, d) + quartic(a, d, b, c)) / 3.0
    return S3, W4


def _whitened_strains(elements, block, x0, U, pi, pj):
    """The whitened strains of a block of elements' quadrature points: e0 (6P,), L (6P, r) and
    M (6P, pairs), each point's rows sqrt(w) R (its Voigt strain) with R^T R the point's 6x6
    form a, so that a(X, Y) summed over points is a dot product."""
    tets = elements.tets[block]
    G = elements.grads[block]                                # (e, q, k, 3)
    F0 = np.einsum("eai,eqaj->eqij", x0[tets], G)
    B = np.einsum("eair,eqaj->eqrij", U[tets], G)            # (e, q, r, 3, 3)
    E0 = 0.5 * (np.einsum("eqki,eqkj->eqij", F0, F0) - np.eye(3))
    FB = np.einsum("eqki,eqrkj->eqrij", F0, B)
    L = 0.5 * (FB + np.swapaxes(FB, -1, -2))
    # M_rs = sym(B_r^T B_s), one Voigt component at a time: column i of every B_r is
    # P_i[r, k] = B_r[k, i], and (B_r^T B_s)_ij = (P_i P_j^T)[r, s] (a batched matrix product)
    P = [np.ascontiguousarray(B[..., i]) for i in range(3)]  # (e, q, r, 3)
    M = np.empty(B.shape[:2] + (pi.size, 6))
    for c, (i, j) in enumerate(_VOIGT):
        product = P[i] @ np.swapaxes(P[j], -1, -2)           # (e, q, r, r)
        if i == j:
            M[..., c] = product[:, :, pi, pj]
        else:
            M[..., c] = (_ROOT2 / 2) * (product[:, :, pi, pj] + product[:, :, pj, pi])
    Rt = np.swapaxes(_whitening(elements, block), -1, -2)    # (e, q, 6, 6), R^T
    r = U.shape[2]
    e0 = (_voigt(E0)[:, :, None, :] @ Rt).reshape(-1)
    L = np.swapaxes(_voigt(L) @ Rt, -1, -2).reshape(-1, r)
    M = np.swapaxes(M @ Rt, -1, -2).reshape(-1, pi.size)
    return e0, L, M


def _voigt(X):
    """(..., 6) Voigt vectors of symmetric (..., 3, 3) tensors (off-diagonals times sqrt 2)."""
    out = np.empty(X.shape[:-2] + (6,))
    for s, (i, j) in enumerate(_VOIGT):
        out[..., s] = X[..., i, j] if i == j else _ROOT2 * X[..., i, j]
    return out


def _whitening(elements, block):
    """(e, q, 6, 6) sqrt(w) R with R^T R = D, the Voigt matrix of the form a: lam 1 1^T + 2 mu
    I + 8 kappa delta delta^T, delta the Voigt vector of d d^T (so d^T X d = delta . x)."""
    mu, lam, kappa = (elements.mu[block], elements.lam[block], elements.kappa[block])
    d = elements.fiber[block]
    one = np.array([1.0, 1.0, 1.0, 0.0, 0.0, 0.0])
    delta = _voigt(np.einsum("ei,ej->eij", d, d))
    D = (lam[:, None, None] * one[:, None] * one + 2.0 * mu[:, None, None] * np.eye(6)
         + 8.0 * kappa[:, None, None] * delta[:, :, None] * delta[:, None, :])
    R = np.swapaxes(np.linalg.cholesky(D), -1, -2)  # D = R^T R
    return np.sqrt(elements.weights[block])[:, :, None, None] * R[:, None]


def with_pressure(poly, cavities, x0, basis):
    """poly with the pressures' energy -p (V(x0 + basis q) - V(X)) of cavities (CavityLoads)
    added, each at its magnitude (pressure_terms)."""
    c0, c1, C2, S3 = poly.c0, poly.c1.copy(), poly.C2.copy(), poly.S3.copy()
    for cavity in cavities:
        d0, d1, D2, D3 = pressure_terms(cavity, x0, basis)
        p = cavity.magnitude
        c0, c1, C2, S3 = c0 + p * d0, c1 + p * d1, C2 + p * D2, S3 + p * D3
    return Polynomial(c0, c1, C2, S3, poly.W4)


def pressure_terms(cavity, x0, basis):
    """The polynomial (c0 m^3, c1 (r,), C2 (r, r), S3 (r, r, r)) of a cavity's
    -(V(x0 + basis q) - V(X)), the energy of a unit pressure (times p, Pa, in J): V = -sum_K
    w a . (b x c) with each slot linear in q (CavityLoad.reduced_slots)."""
    w, a0, b0, c00, A, B, C = cavity.reduced_slots(x0, basis)
    bc = np.cross(b0, c00)
    c0 = float(w @ np.einsum("ki,ki->k", a0, bc)) + cavity.rest_volume
    Bc = np.cross(B, c00[:, :, None], axis=1)                    # B_j x c0 (K, 3, r)
    bC = np.cross(b0[:, :, None], C, axis=1)                     # b0 x C_j
    c1 = np.einsum("k,kir,ki->r", w, A, bc) + np.einsum("k,ki,kir->r", w, a0, Bc + bC)
    BC = np.cross(B[:, :, :, None], C[:, :, None, :], axis=1)    # B_j x C_k (K, 3, r, r)
    quadratic = (np.einsum("k,kir,kis->rs", w, A, Bc + bC)
                 + np.einsum("k,ki,kirs->rs", w, a0, BC))
    C2 = quadratic + quadratic.T                                 # 1/2 q C2 q
    cubic = np.einsum("k,kir,kist->rst", w, A, BC)
    S3 = (cubic + cubic.transpose(0, 2, 1) + cubic.transpose(1, 0, 2)
          + cubic.transpose(1, 2, 0) + cubic.transpose(2, 0, 1)
          + cubic.transpose(2, 1, 0)) / 6.0
    return c0, c1, C2, S3
