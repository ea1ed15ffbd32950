"""Numba kernels of the reduced model: the quartic's derivatives at q and the whole Newton
solve of one step in r dimensions (anisofem.reduced.polynomial defines the coefficients).

A Newton iteration passes over W4 (T x r, T = r (r + 1) (r + 2) / 6) once: A = W4 q holds
S4[a, b, c, q] for the sorted triples, and a step q + t p has A + t W4 p, the same product
the line search needs for its quartic along p.
"""
import numpy as np
from numba import njit

#: Reassociated sums vectorize; no flag that assumes away NaN or infinity.
_SUMS = {"reassoc", "contract"}

#: Status codes of newton().
CONVERGED, SPENT, NO_DESCENT, NOT_FINITE = 0, 1, 2, 3

ARMIJO = 1e-4
MIN_STEP = 1e-12
#: Eigenvalues of an indefinite reduced Hessian are clamped to this share of the largest.
CLAMP = 1e-8


@njit(cache=True, fastmath=_SUMS)
def matvec(M, x):
    """M x for M (a, b) and x (b,), without BLAS: numba's BLAS is another thread pool than
    numpy's, and the two spin against each other on small products (10x slower steps)."""
    out = np.empty(M.shape[0])
    for i in range(M.shape[0]):
        s = 0.0
        for j in range(x.size):
            s += M[i, j] * x[j]
        out[i] = s
    return out


@njit(cache=True, fastmath=_SUMS)
def dot(x, y):
    s = 0.0
    for i in range(x.size):
        s += x[i] * y[i]
    return s


@njit(cache=True)
def quartic_matrix(A, q, X):
    """X = S4[q, q] (r, r) from A = W4 q (T,), W4's rows the sorted triples a <= b <= c in
    lexicographic order: X[a, b] = sum_c S4[a, b, c, q] q_c. A sorted triple adds to the upper
    triangle once for each distinct index it can give up to q; the lower one is mirrored."""
    r = q.size
    X[:, :] = 0.0
    t = 0
    for a in range(r):
        qa = q[a]
        for b in range(a, r):
            qb = q[b]
            v = A[t]            # c = b: (a, b) gets q_b; (b, b) gets q_a unless a = b
            acc = v * qb
            if a != b:
                X[b, b] += v * qa
            t += 1
            for c in range(b + 1, r):
                v = A[t]
                acc += v * q[c]
                X[a, c] += v * qb
                if a != b:
                    X[b, c] += v * qa
                t += 1
            X[a, b] += acc
    for i in range(r):
        for j in range(i):
            X[i, j] = X[j, i]


@njit(cache=True)
def cubic_forms(A, Ap, p):
    """(S4[q, p, p, p], S4[p, p, p, p]) for A = W4 q and Ap = W4 p (T,): sums over the sorted
    triples (lexicographic, as W4's rows) of their number of orderings times A[t] p_a p_b
    p_c."""
    r = p.size
    mixed, pure = 0.0, 0.0
    t = 0
    for a in range(r):
        for b in range(a, r):
            pab = p[a] * p[b]
            w = pab * p[b] * (1.0 if a == b else 3.0)      # c = b
            mixed += w * A[t]
            pure += w * Ap[t]
            t += 1
            w = 3.0 * pab if a == b else 6.0 * pab          # c > b
            for c in range(b + 1, r):
                mixed += w * p[c] * A[t]
                pure += w * p[c] * Ap[t]
                t += 1
    return mixed, pure


@njit(cache=True)
def cubic_quartic(S3, A, q):
    """(Y, X) = (S3[q], S4[q, q]), each (r, r), for S3 (r * r, r) and A = W4 q (T,)."""
    r = q.size
    X = np.empty((r, r))
    quartic_matrix(A, q, X)
    return matvec(S3, q).reshape(r, r), X


@njit(cache=True)
def energy(c0, c1, C2, S3, A, q):
    """V(q) = c0 + c1 . q + q^T (C2 / 2 + Y + X) q, J, with Y = S3[q] and X = S4[q, q];
    S3 (r * r, r), A = W4 q (T,)."""
    Y, X = cubic_quartic(S3, A, q)
    e = c0
    for i in range(q.size):
        s = 0.0
        for j in range(q.size):
            s += (0.5 * C2[i, j] + Y[i, j] + X[i, j]) * q[j]
        e += (c1[i] + s) * q[i]
    return e


@njit(cache=True)
def derivatives(c1, C2, S3, A, q, inertia):
    """(g, H): dV/dq = c1 + (C2 + 3 Y + 4 X) q and d2V/dq2 + inertia I = C2 + 6 Y + 12 X +
    inertia I, with Y = S3[q] and X = S4[q, q] (r, r); S3 (r * r, r), A = W4 q (T,)."""
    r = q.size
    Y, X = cubic_quartic(S3, A, q)
    g = c1.copy()
    H = np.empty((r, r))
    for i in range(r):
        s = 0.0
        for j in range(r):
            y, x = Y[i, j], X[i, j]
            s += (C2[i, j] + 3.0 * y + 4.0 * x) * q[j]
            H[i, j] = C2[i, j] + 6.0 * y + 12.0 * x
        g[i] += s
        H[i, i] += inertia
    return g, H


@njit(cache=True)
def positive_solve(H, g):
    """H^-1 g by Cholesky where H (r, r) is positive definite, else with H's eigenvalues
    clamped to CLAMP times the largest (the projected Newton step)."""
    r = g.size
    Lf = np.zeros((r, r))
    definite = True
    for j in range(r):
        s = H[j, j]
        for k in range(j):
            s -= Lf[j, k] * Lf[j, k]
        if not s > 0.0:
            definite = False
            break
        d = np.sqrt(s)
        Lf[j, j] = d
        for i in range(j + 1, r):
            s = H[i, j]
            for k in range(j):
                s -= Lf[i, k] * Lf[j, k]
            Lf[i, j] = s / d
    if not definite:
        w, V = np.linalg.eigh(H)
        w = np.maximum(w, CLAMP * np.abs(w).max())
        return matvec(V, matvec(V.T.copy(), g) / w)
    y = np.empty(r)
    for i in range(r):
        s = g[i]
        for k in range(i):
            s -= Lf[i, k] * y[k]
        y[i] = s / Lf[i, i]
    x = np.empty(r)
    for i in range(r - 1, -1, -1):
        s = y[i]
        for k in range(i + 1, r):
            s -= Lf[k, i] * x[k]
        x[i] = s / Lf[i, i]
    return x


@njit(cache=True)
def newton(c1, C2, S3, W4, load, q, q_hat, inertia, tolerance, rtol,
           roundoff, max_iter):
    """Minimize V(q) - load . q + inertia |q - q_hat|^2 / 2 from q by Newton with a
    backtracking Armijo search on the exact quartic along each step. Converged when the
    gradient norm is at most tolerance + rtol |dV/dq at the start| (N), or the round-off
    floor: `roundoff` times eps r |(|H| |q| + |c1| + |load|)|. Returns (q, iterations,
    residual, status)."""
    r = q.size
    A = matvec(W4, q)
    eps = np.finfo(np.float64).eps
    residual = np.inf
    for it in range(max_iter + 1):
        g, H = derivatives(c1, C2, S3, A, q, inertia)
        if it == 0:
            tolerance += rtol * np.sqrt(dot(g, g))
        g = g - load + inertia * (q - q_hat)
        residual = np.sqrt(dot(g, g))
        if not np.isfinite(residual):
            return q, it, residual, NOT_FINITE
        terms = matvec(np.abs(H), np.abs(q)) + np.abs(load) + np.abs(c1)
        if residual <= max(tolerance, roundoff * eps * r * np.sqrt(dot(terms, terms))):
            return q, it, residual, CONVERGED
        if it == max_iter:
            break
        p = -positive_solve(H, g)
        a1 = dot(g, p)
        if not a1 < 0.0:
            return q, it, residual, NO_DESCENT
        a2 = 0.5 * dot(p, matvec(H, p))
        Ap = matvec(W4, p)
        Yp = matvec(S3, p).reshape(r, r)
        mixed, a4 = cubic_forms(A, Ap, p)
        a3 = dot(p, matvec(Yp, p)) + 4.0 * mixed
        t = 1.0
        while t * (a2 + t * (a3 + t * a4)) > -(1.0 - ARMIJO) * a1:
            t *= 0.5
            if t < MIN_STEP:
                return q, it, residual, NO_DESCENT
        q = q + t * p
        A = A + t * Ap
    return q, max_iter, residual, SPENT
