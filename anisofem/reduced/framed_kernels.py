"""Numba kernels of the framed model (anisofem.reduced.framed): its domains' inertia and load
terms from the basis moments, the joint nodes' positions, and the joints' gradient and Hessian
chained through each node's frame.

Packed arrays: domain d's unknowns start at z0[d] (c, theta, then its r[d] coordinates), its
coordinates at q0[d] in q and in the packed a (Q,), A (Q, 3, 3) and T (Q, 3, 3); B (sum r^2,
3, 3) holds B[a, b] of domain d at b0[d] + a r[d] + b. A joint node i belongs to domain
dom[i] (-1: held) with rest offset Y[i] (3,) and basis rows U[i] (3, rmax), zero past its
domain's r.
"""
import numpy as np
from numba import njit

from .kernels import _SUMS, derivatives, energy, matvec

#: [e_j]_x, the generators of rotations about the axes: GEN[j, a, b]
GEN = np.array([[[0, 0, 0], [0, 0, -1], [0, 1, 0]],
                 [[0, 0, 1], [0, 0, 0], [-1, 0, 0]],
                 [[0, -1, 0], [1, 0, 0], [0, 0, 0]]], dtype=float)


@njit(cache=True, fastmath=_SUMS)
def _add_product(w, R, M, out):
    """out += w R M for 3 x 3 R, M."""
    for i in range(3):
        for j in range(3):
            out[i, j] += w * (R[i, 0] * M[0, j] + R[i, 1] * M[1, j] + R[i, 2] * M[2, j])


@njit(cache=True, fastmath=_SUMS)
def targets(inertia, states_c, states_R, states_q, alphas, J, A, B, mass, q0, r, b0, T0, T, t):
    """Add to the load's moments T0 (D, 3, 3), T (Q, 3, 3), t (D, 3) the inertia's pull
    towards x_hat = sum_k alphas[k] x(state k) (states_c (K, D, 3), states_R (K, D, 3, 3),
    states_q (K, Q)): T0 += w R_k (J + sum_a q_a A_a), T_b += w R_k (A_b^T + sum_a q_a B_ab),
    t += w mass c_k, w = inertia alpha_k."""
    M = np.empty((3, 3))
    for k in range(alphas.size):
        w = inertia * alphas[k]
        for d in range(mass.size):
            for i in range(3):
                for j in range(3):
                    s = J[d, i, j]
                    for a in range(r[d]):
                        s += states_q[k, q0[d] + a] * A[q0[d] + a, i, j]
                    M[i, j] = s
            _add_product(w, states_R[k, d], M, T0[d])
            for b in range(r[d]):
                for i in range(3):
                    for j in range(3):
                        s = A[q0[d] + b, j, i]
                        for a in range(r[d]):
                            s += states_q[k, q0[d] + a] * B[b0[d] + a * r[d] + b, i, j]
                        M[i, j] = s
                _add_product(w, states_R[k, d], M, T[q0[d] + b])
            for i in range(3):
                t[d, i] += w * mass[d] * states_c[k, d, i]


@njit(cache=True, fastmath=_SUMS)
def polynomials(q, q0, r, c0, c1, C2, S3, W4, offsets, z0, g, H):
    """The domains' elastic energies summed, J; with g (size > 0) their gradients added at
    z0[d] + 6, and their Hessians to H. The polynomials' coefficients
    packed: c0 (D,), c1 (Q,), and C2, S3 (r^3) and W4 (T r) of domain d flat from
    offsets[d] = (C2's, S3's, W4's)."""
    total = 0.0
    for d in range(r.size):
        rd = r[d]
        if rd == 0:
            total += c0[d]
            continue
        qd = q[q0[d]:q0[d] + rd].copy()
        c1d = c1[q0[d]:q0[d] + rd]
        C2d = C2[offsets[d, 0]:offsets[d, 0] + rd * rd].reshape(rd, rd)
        S3d = S3[offsets[d, 1]:offsets[d, 1] + rd * rd * rd].reshape(rd * rd, rd)
        triples = rd * (rd + 1) * (rd + 2) // 6
        W4d = W4[offsets[d, 2]:offsets[d, 2] + triples * rd].reshape(triples, rd)
        Aq = matvec(W4d, qd)
        total += energy(c0[d], c1d, C2d, S3d, Aq, qd)
        if g.size:
            gd, Hd = derivatives(c1d, C2d, S3d, Aq, qd, 0.0)
            o = z0[d] + 6
            for i in range(rd):
                g[o + i] += gd[i]
            for i in range(rd):
                for j in range(rd):
                    H[o + i, o + j] += Hd[i, j]
    return total


@njit(cache=True, fastmath=_SUMS)
def _pulled(R, T0, T, q, q0, rd):
    """T0 + sum_b q_b T_b (3, 3)."""
    M = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            s = T0[i, j]
            for b in range(rd):
                s += q[q0 + b] * T[q0 + b, i, j]
            M[i, j] = s
    return M


@njit(cache=True, fastmath=_SUMS)
def domain_energy(inertia, c, R, q, a, mass, T0, T, t, q0, r):
    """sum over domains of inertia/2 (2 a.q + |q|^2 + mass |c|^2) - tr(R^T (T0 + q . T))
    - t . c, J."""
    total = 0.0
    for d in range(mass.size):
        s = mass[d] * (c[d] @ c[d])
        for b in range(r[d]):
            qb = q[q0[d] + b]
            s += 2.0 * a[q0[d] + b] * qb + qb * qb
        total += 0.5 * inertia * s - np.sum(R[d] * _pulled(R[d], T0[d], T, q, q0[d], r[d]))
        total -= t[d] @ c[d]
    return total


@njit(cache=True, fastmath=_SUMS)
def domain_derivatives(inertia, c, R, q, a, mass, T0, T, t, q0, r, z0, g, H):
    """Set each domain's block of g and H to its inertia and load terms' gradient and Hessian
    in (c, theta, q) at theta = 0 (R turned by exp([theta]) R)."""
    GR = np.empty((3, 3, 3))
    for d in range(mass.size):
        o, rd = z0[d], r[d]
        M = _pulled(R[d], T0[d], T, q, q0[d], rd)
        for j in range(3):
            GR[j] = GEN[j] @ R[d]
        for i in range(3):
            g[o + i] = inertia * mass[d] * c[d, i] - t[d, i]
            g[o + 3 + i] = -np.sum(GR[i] * M)
        for b in range(rd):
            g[o + 6 + b] = inertia * (a[q0[d] + b] + q[q0[d] + b]) - np.sum(R[d] * T[q0[d] + b])
        for i in range(3):
            H[o + i, o + i] = inertia * mass[d]
            for k in range(3):
                G2 = 0.5 * (GEN[i] @ GR[k] + GEN[k] @ GR[i])
                H[o + 3 + i, o + 3 + k] = -np.sum(G2 * M)
        for b in range(rd):
            Tb = T[q0[d] + b]
            H[o + 6 + b, o + 6 + b] = inertia
            for j in range(3):
                v = -np.sum(GR[j] * Tb)
                H[o + 3 + j, o + 6 + b] = v
                H[o + 6 + b, o + 3 + j] = v


@njit(cache=True, fastmath=_SUMS)
def node_positions(c, R, q, base, dom, Y, U, x0, q0, r, out):
    """Positions (k, 3) of nodes in domains dom (k,): R (y + U q) + c in their domain (rest
    offsets Y (k, 3), basis rows U (k, 3, rmax)), base (3, 4) [R_g | c_g] moving x0 where
    held (dom -1): R_g x0 + c_g."""
    y = np.empty(3)
    for i in range(dom.size):
        d = dom[i]
        if d < 0:
            for a in range(3):
                out[i, a] = (base[a, 0] * x0[i, 0] + base[a, 1] * x0[i, 1]
                             + base[a, 2] * x0[i, 2] + base[a, 3])
            continue
        for a in range(3):
            s = Y[i, a]
            for b in range(r[d]):
                s += U[i, a, b] * q[q0[d] + b]
            y[a] = s
        for a in range(3):
            out[i, a] = R[d, a, 0] * y[0] + R[d, a, 1] * y[1] + R[d, a, 2] * y[2] + c[d, a]


@njit(cache=True, fastmath=_SUMS)
def node_jacobians(x, c, R, dom, U, r, Jn):
    """Jn[i] (3, 6 + r) = dx_i / d(c, theta, q) of each free joint node in its domain:
    [I | -[w]_x | R U_i], w = x_i - c."""
    for i in range(dom.size):
        d = dom[i]
        if d < 0:
            continue
        w0, w1, w2 = x[i, 0] - c[d, 0], x[i, 1] - c[d, 1], x[i, 2] - c[d, 2]
        for a in range(3):
            Jn[i, a, a] = 1.0
        Jn[i, 0, 4], Jn[i, 0, 5] = w2, -w1
        Jn[i, 1, 3], Jn[i, 1, 5] = -w2, w0
        Jn[i, 2, 3], Jn[i, 2, 4] = w1, -w0
        for a in range(3):
            for b in range(r[d]):
                Jn[i, a, 6 + b] = (R[d, a, 0] * U[i, 0, b] + R[d, a, 1] * U[i, 1, b]
                                   + R[d, a, 2] * U[i, 2, b])


@njit(cache=True, fastmath=_SUMS)
def element_forces(tets, grad, Jn, dom, z0, r, out):
    """Add each element's generalized force to out (m, Z): sum over its nodes i = tets[e, a]
    of Jn[i]^T grad[e, a] in node i's domain's unknowns (held nodes, dom -1: none); grad
    (m, k, 3), N, the element's own gradient on each of its nodes; Jn (node_jacobians)."""
    for e in range(tets.shape[0]):
        for a in range(tets.shape[1]):
            i = tets[e, a]
            d = dom[i]
            if d < 0:
                continue
            for v in range(6 + r[d]):
                out[e, z0[d] + v] += (Jn[i, 0, v] * grad[e, a, 0] + Jn[i, 1, v] * grad[e, a, 1]
                                      + Jn[i, 2, v] * grad[e, a, 2])


@njit(cache=True, fastmath=_SUMS)
def joint_derivatives(x, grad, blocks, pairs, pair_ptr, c, R, dom, U, r, z0, g, H):
    """Add the joints' gradient and Hessian, chained through each node's frame: grad (k, 3) and
    the Hessian's 3 x 3 blocks (p, 3, 3) in the positions of the node pairs (p, 2) that share
    an element (both orders, and (i, i)), sorted, node i's from pair_ptr[i] to
    pair_ptr[i + 1]."""
    k = dom.size
    nz = g.size
    Jn = np.zeros((k, 3, 6 + r.max()))
    node_jacobians(x, c, R, dom, U, r, Jn)
    K = np.zeros((3, nz))
    S = np.zeros((nz, nz))
    touched = np.zeros(r.size, np.bool_)
    for i in range(k):
        d = dom[i]
        if d < 0:
            continue
        o, rd = z0[d], r[d]
        gi = grad[i]
        w0, w1, w2 = x[i, 0] - c[d, 0], x[i, 1] - c[d, 1], x[i, 2] - c[d, 2]
        # first derivatives, and the second derivatives of x_i times the gradient
        for a in range(3):
            g[o + a] += gi[a]
        g[o + 3] += w1 * gi[2] - w2 * gi[1]
        g[o + 4] += w2 * gi[0] - w0 * gi[2]
        g[o + 5] += w0 * gi[1] - w1 * gi[0]
        w = (w0, w1, w2)
        gw = gi[0] * w0 + gi[1] * w1 + gi[2] * w2
        for a in range(3):
            for b in range(3):
                H[o + 3 + a, o + 3 + b] += 0.5 * (gi[a] * w[b] + gi[b] * w[a])
            H[o + 3 + a, o + 3 + a] -= gw
        for b in range(rd):
            v0, v1, v2 = Jn[i, 0, 6 + b], Jn[i, 1, 6 + b], Jn[i, 2, 6 + b]
            g[o + 6 + b] += v0 * gi[0] + v1 * gi[1] + v2 * gi[2]
            cr = (v1 * gi[2] - v2 * gi[1], v2 * gi[0] - v0 * gi[2], v0 * gi[1] - v1 * gi[0])
            for a in range(3):
                H[o + 3 + a, o + 6 + b] += cr[a]
                H[o + 6 + b, o + 3 + a] += cr[a]
        # Gauss-Newton part sum_j Jn_i^T hess_ij Jn_j, symmetric: K = sum_j hess_ij Jn_j over
        # node i's neighbours in its own domain and the later ones, then Jn_i^T K, within the
        # own domain its upper triangle only (mirrored below)
        touched[:] = False
        for p in range(pair_ptr[i], pair_ptr[i + 1]):
            j = pairs[p, 1]
            dj = dom[j]
            if dj < d:
                continue
            oj, nj = z0[dj], 6 + r[dj]
            if not touched[dj]:
                touched[dj] = True
                K[:, oj:oj + nj] = 0.0
            for a in range(3):
                for b in range(3):
                    h = blocks[p, a, b]
                    for v in range(nj):
                        K[a, oj + v] += h * Jn[j, b, v]
        for e in range(d, r.size):
            if not touched[e]:
                continue
            oe, ne = z0[e], 6 + r[e]
            for u in range(6 + rd):
                j0, j1, j2 = Jn[i, 0, u], Jn[i, 1, u], Jn[i, 2, u]
                if j0 == 0.0 and j1 == 0.0 and j2 == 0.0:
                    continue
                for v in range(u if e == d else 0, ne):
                    S[o + u, oe + v] += j0 * K[0, oe + v] + j1 * K[1, oe + v] + j2 * K[2, oe + v]
    for u in range(nz):
        H[u, u] += S[u, u]
        for v in range(u + 1, nz):
            H[u, v] += S[u, v]
            H[v, u] += S[u, v]


@njit(cache=True, fastmath=_SUMS)
def tree_chain(R, chain, arms, zc, zt, g, H, N):
    """The kinematic tree's chain rule (anisofem.reduced.framed), in place: g (r,) and H (r, r)
    in each domain's free centre, turn and coordinates become those in the tree's unknowns.
    N (3 D, r), zeroed by the caller, gets the moves of the centres (rows 3 d .. 3 d + 2 for
    domain d) per unit move of the tree's unknowns, less the identity; each entry (f, d) of
    chain (P, 2) with its rest arm arms (P, 3) adds I at f's own move (f != d) and
    -[R_f arm]_x at f's turn. Then, with C the centres' rows zc: the centres' second
    derivatives times g[C] join H's turn blocks, H += HN + HN^T + N^T H[C, C] N with
    HN = H[:, C] N, and g += N^T g[C]."""
    for p in range(chain.shape[0]):
        f, d = chain[p, 0], chain[p, 1]
        w = R[f] @ arms[p]
        if f != d:
            for a in range(3):
                N[3 * d + a, zc[f, a]] += 1.0
        N[3 * d + 0, zt[f, 1]] += w[2]
        N[3 * d + 0, zt[f, 2]] -= w[1]
        N[3 * d + 1, zt[f, 0]] -= w[2]
        N[3 * d + 1, zt[f, 2]] += w[0]
        N[3 * d + 2, zt[f, 0]] += w[1]
        N[3 * d + 2, zt[f, 1]] -= w[0]
        gc = g[zc[d]]
        gw = gc @ w
        for a in range(3):
            for b in range(3):
                H[zt[f, a], zt[f, b]] += 0.5 * (gc[a] * w[b] + gc[b] * w[a])
            H[zt[f, a], zt[f, a]] -= gw
    C = zc.ravel()
    nz, nc = g.size, C.size
    HN = np.zeros((nz, nz))
    CN = np.zeros((nc, nz))
    for i in range(nz):
        for a in range(nc):
            h = H[i, C[a]]
            if h != 0.0:
                for j in range(nz):
                    HN[i, j] += h * N[a, j]
    for a in range(nc):
        for b in range(nc):
            h = H[C[a], C[b]]
            if h != 0.0:
                for j in range(nz):
                    CN[a, j] += h * N[b, j]
    for i in range(nz):
        for j in range(nz):
            H[i, j] += HN[i, j] + HN[j, i]
    for a in range(nc):
        for i in range(nz):
            n = N[a, i]
            if n != 0.0:
                for j in range(nz):
                    H[i, j] += n * CN[a, j]
    gC = g[C].copy()
    for a in range(nc):
        for i in range(nz):
            g[i] += N[a, i] * gC[a]


@njit(cache=True)
def rodrigues(theta, out):
    """out (D, 3, 3) = exp([theta_d]_x) of rotation vectors theta (D, 3), by Rodrigues'
    formula (1 - cos a written 2 sin^2(a/2), which keeps its digits at small angles), with
    [t]_x^2 = t t^T - |t|^2 I."""
    for d in range(theta.shape[0]):
        t0, t1, t2 = theta[d, 0], theta[d, 1], theta[d, 2]
        square = t0 * t0 + t1 * t1 + t2 * t2
        angle = np.sqrt(square)
        first = np.sin(angle) / angle if angle > 0 else 1.0
        half = np.sin(0.5 * angle) / (0.5 * angle) if angle > 0 else 1.0
        second = 0.5 * half * half
        t = (t0, t1, t2)
        for i in range(3):
            for j in range(3):
                out[d, i, j] = second * t[i] * t[j]
            out[d, i, i] += 1.0 - second * square
        out[d, 0, 1] -= first * t2
        out[d, 1, 0] += first * t2
        out[d, 0, 2] += first * t1
        out[d, 2, 0] -= first * t1
        out[d, 1, 2] -= first * t0
        out[d, 2, 1] += first * t0


@njit(cache=True)
def nearest_rotations(R):
    """Each R[d] (D, 3, 3), a rotation up to round-off, replaced in place by its nearest
    rotation: the polar factor by X <- (X + X^-T) / 2, until no entry changes by 1e-16."""
    C = np.empty((3, 3))
    for d in range(R.shape[0]):
        X = R[d]
        for _ in range(20):
            # X^-T by cofactors: row i of the cofactor matrix over det
            for i in range(3):
                i1, i2 = (i + 1) % 3, (i + 2) % 3
                for j in range(3):
                    j1, j2 = (j + 1) % 3, (j + 2) % 3
                    C[i, j] = X[i1, j1] * X[i2, j2] - X[i1, j2] * X[i2, j1]
            det = X[0, 0] * C[0, 0] + X[0, 1] * C[0, 1] + X[0, 2] * C[0, 2]
            change = 0.0
            for i in range(3):
                for j in range(3):
                    v = 0.5 * (X[i, j] + C[i, j] / det)
                    change = max(change, abs(v - X[i, j]))
                    X[i, j] = v
            if change <= 1e-16:
                break


@njit(cache=True, fastmath=_SUMS)
def step_bound(dz, z0, r, radius, reach):
    """The largest node move of a step dz (r,) in the tree's unknowns plus its centres' moves,
    bounded per domain: |dc_d| + |dtheta_d| radius_d + |dq_d| reach_d, m."""
    worst = 0.0
    for d in range(z0.size):
        o = z0[d]
        c = np.sqrt(dz[o] ** 2 + dz[o + 1] ** 2 + dz[o + 2] ** 2)
        t = np.sqrt(dz[o + 3] ** 2 + dz[o + 4] ** 2 + dz[o + 5] ** 2)
        q = 0.0
        for b in range(r[d]):
            q += dz[o + 6 + b] ** 2
        worst = max(worst, c + t * radius[d] + np.sqrt(q) * reach[d])
    return worst


@njit(cache=True, fastmath=_SUMS)
def tree_centres(order, parent, arm_parent, arm_own, base, R, moves, c, to_moves):
    """The kinematic tree's centres (anisofem.reduced.framed): c_e = c_p + R_p a_e + R_e b_e
    + t_e (where the parent is the held nodes, p < 0, c_p and R_p are the base's (3, 4)
    [R_g | c_g]), parents first in order. to_moves False: c (D, 3) from the own moves t
    (D, 3); True: moves from the centres c."""
    for e in order:
        p = parent[e]
        for i in range(3):
            s = (R[e, i, 0] * arm_own[e, 0] + R[e, i, 1] * arm_own[e, 1]
                 + R[e, i, 2] * arm_own[e, 2])
            if p < 0:
                s += base[i, 3] + (base[i, 0] * arm_parent[e, 0] + base[i, 1] * arm_parent[e, 1]
                                   + base[i, 2] * arm_parent[e, 2])
            else:
                s += c[p, i] + (R[p, i, 0] * arm_parent[e, 0] + R[p, i, 1] * arm_parent[e, 1]
                                + R[p, i, 2] * arm_parent[e, 2])
            if to_moves:
                moves[e, i] = c[e, i] - s
            else:
                c[e, i] = s + moves[e, i]
