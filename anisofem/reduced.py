"""A scene's reduced model: positions x = x0 + U q in a basis U of r displacement directions
(the lowest vibration modes of the scene and their modal derivatives, Barbic and James 2005),
and the exact reduced potential, a quartic polynomial in q.

Why exact: Green's strain is quadratic in the displacement, so at each quadrature point
E(q) = E0 + sum_j q_j L_j + 1/2 sum_jk q_j q_k M_jk, with F0 the deformation gradient of x0, B_j
that of the basis vector U_j (F = F0 + sum_j q_j B_j), L_j = sym(F0^T B_j) and
M_jk = sym(B_j^T B_k). Saint Venant-Kirchhoff and the fiber term are quadratic forms of E:

    psi = 1/2 a(E, E),  a(X, Y) = lam tr X tr Y + 2 mu X : Y + 8 kappa (d^T X d)(d^T Y d),

so the elastic energy V(q) = sum_p w_p psi(E_p(q)) is

    V(q) = c0 + c1 . q + 1/2 q^T C2 q + 1/2 q^T T3 z + 1/8 z^T Q4 z,   z = (q_j q_k)_{j <= k},

with c1_j = sum w a(E0, L_j), C2_jk = sum w (a(L_j, L_k) + a(E0, M_jk)), T3_j,(kl) = sum w
c_kl a(L_j, M_kl), Q4_(jk),(lm) = sum w c_jk c_lm a(M_jk, M_lm), and c_jk = 2 for j < k, 1 for
j = k (the pair's multiplicity). The coefficients are summed once, per quadrature point of
every element (anisofem.kernels' ElementData: any element type), and the reduced force and
Hessian cost O(r^4) whatever the mesh. The Neo-Hookean base is not polynomial in q: it is
refused.

Dynamics: the basis is mass-orthonormal (U^T M U = I with the lumped mass), so backward Euler
minimizes 1/(2 dt^2) |q - q_hat|^2 + V(q) - f_r . q, q_hat = q_n + dt v_n, f_r = U^T f_ext.
"""
import math
import time
from dataclasses import dataclass

import numpy as np
import scipy.linalg
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from .densities import STVK
from .potential import Potential
from .scene import check_scene

#: Default number of vibration modes; the basis holds them and their m (m + 1) / 2 modal
#: derivatives, less dependent directions.
MODES = 6

#: Elements whose strains the coefficient sums form at once (memory: about
#: 6 * CHUNK * r^2 / 2 floats).
CHUNK = 256

#: A candidate direction is dropped from the basis when mass-orthogonalization leaves less
#: than this share of its norm (it depends on the others).
DEPENDENT = 1e-8

#: Voigt order of a symmetric 3x3 tensor: (00, 11, 22, 01, 02, 12); off-diagonal entries are
#: scaled by sqrt 2 so that X : Y is the dot product.
_VOIGT = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))
_ROOT2 = math.sqrt(2.0)


@dataclass
class NewtonReport:
    """How a reduced solve ended: converged, iterations, the final reduced gradient norm (N)."""
    converged: bool
    iterations: int
    residual: float


class ReducedModel:
    """The reduced model of a scene (StVK base, with or without fibers).

    Parameters
    ----------
    scene : the Scene (its mesh, material, fixed vertices and loads; statics start from its
        initial positions x0, which the basis moves).
    modes : vibration modes m of the rest Hessian with the lumped mass (default MODES); the
        basis adds their modal derivatives, so r <= m + m (m + 1) / 2.
    derivatives : False keeps the linear modes only (r = m; for comparison: they do not
        capture large rotations).

    Attributes: basis (3n, r) over all vertex components (0 on fixed ones), m per unit
    sqrt(kg) so that basis^T M basis = I; frequencies (m,) of the vibration modes, Hz;
    build_seconds.
    """

    def __init__(self, scene, modes=MODES, derivatives=True):
        check_scene(scene)
        if (scene.elements.model != STVK).any():
            raise ValueError("scene: the reduced model needs the StVK base material (its energy "
                             "is a polynomial in the reduced coordinates); this scene has "
                             "Neo-Hookean elements")
        scene.check_static()
        if not isinstance(modes, (int, np.integer)) or isinstance(modes, bool) or modes < 1:
            raise ValueError(f"modes: expected a positive integer, got {modes!r}")
        if modes >= scene.n_free:
            raise ValueError(f"modes: {modes} modes need more than the scene's {scene.n_free} "
                             f"unknowns")
        t0 = time.perf_counter()
        self.scene = scene
        self.x0 = scene.initial_positions()
        free = scene.free_dofs
        mass = np.repeat(scene.masses, 3)[free]
        layout = scene.layout("csr")
        potential = Potential(scene)
        K = _free_hessian(potential, self.x0, layout)
        lam, phi = spla.eigsh(K, k=modes, M=sp.diags(mass).tocsc(), sigma=0.0, which="LM")
        order = np.argsort(lam)
        lam, phi = lam[order], phi[:, order]
        self.frequencies = np.sqrt(np.maximum(lam, 0.0)) / (2.0 * math.pi)
        columns = [phi]
        if derivatives:
            columns.append(_modal_derivatives(potential, self.x0, layout, K, phi, free))
        U = _mass_orthonormal(np.hstack(columns), mass)
        self.basis = np.zeros((3 * scene.mesh.n_vertices, U.shape[1]))
        self.basis[free] = U
        self.pairs = np.triu_indices(self.r)
        self._coefficients()
        self.external = self.basis.T @ scene.external_force.ravel()
        self._stiffness = float(np.linalg.norm(self.C2, 2))
        self.build_seconds = time.perf_counter() - t0

    @property
    def r(self):
        """Number of reduced coordinates."""
        return self.basis.shape[1]

    def positions(self, q):
        """Full positions x0 + U q, (n, 3) in m, of reduced coordinates q (r,)."""
        return self.x0 + (self.basis @ q).reshape(-1, 3)

    def project(self, force):
        """The reduced force U^T f (r,) of nodal forces f (n, 3) in N."""
        return self.basis.T @ np.asarray(force, dtype=float).ravel()

    # -- the polynomial -------------------------------------------------------------------

    def _coefficients(self):
        """Sum c0, c1, C2, T3 and Q4 (module docstring) over every quadrature point."""
        el = self.scene.elements
        r = self.r
        U = self.basis.reshape(-1, 3, r)
        pi, pj = self.pairs
        multiplicity = np.where(pi == pj, 1.0, 2.0)
        c0, c1, C2 = 0.0, np.zeros(r), np.zeros((r, r))
        T3, Q4 = np.zeros((r, pi.size)), np.zeros((pi.size, pi.size))
        for lo in range(0, el.tets.shape[0], CHUNK):
            e0, L, M = self._strains(slice(lo, lo + CHUNK), U)
            c0 += 0.5 * float(np.dot(e0, e0))
            c1 += L.T @ e0
            C2 += L.T @ L
            C2[pi, pj] += M.T @ e0
            Mc = M * multiplicity
            T3 += L.T @ Mc
            Q4 += Mc.T @ Mc
        C2 = np.triu(C2) + np.triu(C2, 1).T  # the M part was summed on the upper triangle
        self.c0, self.c1, self.C2, self.T3, self.Q4 = c0, c1, C2, T3, Q4

    def _strains(self, elements, U):
        """The whitened strains of a block of elements' quadrature points: e0 (6p,), L (6p, r)
        and M (6p, pairs), each point's rows sqrt(w) R (its Voigt strain), R^T R the point's
        6x6 form a (so a(X, Y) is a dot product)."""
        el = self.scene.elements
        tets = el.tets[elements]
        G = el.grads[elements]                                  # (e, q, k, 3)
        w = el.weights[elements]                                # (e, q)
        F0 = np.einsum("eai,eqaj->eqij", self.x0[tets], G)
        B = np.einsum("eair,eqaj->eqrij", U[tets], G)           # (e, q, r, 3, 3)
        E0 = 0.5 * (np.einsum("eqki,eqkj->eqij", F0, F0) - np.eye(3))
        FB = np.einsum("eqki,eqrkj->eqrij", F0, B)
        L = 0.5 * (FB + np.swapaxes(FB, -1, -2))
        pi, pj = self.pairs
        BB = np.einsum("eqrki,eqskj->eqrsij", B, B)[:, :, pi, pj]
        M = 0.5 * (BB + np.swapaxes(BB, -1, -2))
        R = _whitening(el, elements, w)                         # (e, q, 6, 6)
        e0 = np.einsum("eqst,eqt->eqs", R, _voigt(E0)).reshape(-1)
        L = np.einsum("eqst,eqrt->eqsr", R, _voigt(L)).reshape(-1, self.r)
        M = np.einsum("eqst,eqpt->eqsp", R, _voigt(M)).reshape(-1, pi.size)
        return e0, L, M

    def energy(self, q):
        """The elastic energy V(q), J."""
        z = q[self.pairs[0]] * q[self.pairs[1]]
        return (self.c0 + self.c1 @ q + 0.5 * q @ self.C2 @ q + 0.5 * q @ (self.T3 @ z)
                + 0.125 * z @ (self.Q4 @ z))

    def force(self, q, hessian=False):
        """The elastic force dV/dq (r,) in N (the reduced gradient, U^T g(x0 + U q)), and with
        hessian=True also d2V/dq2 (r, r) in N/m."""
        pi, pj = self.pairs
        z = q[pi] * q[pj]
        Tq = self.T3.T @ q
        Qz = self.Q4 @ z
        half = _half_unpack(Tq + 0.5 * Qz, pi, pj, self.r)   # J^T y = 2 Y(y) q
        f = self.c1 + self.C2 @ q + 0.5 * (self.T3 @ z) + half @ q
        if not hessian:
            return f
        J = np.zeros((pi.size, self.r))
        rows = np.arange(pi.size)
        J[rows, pi] += q[pj]
        J[rows, pj] += q[pi]
        TJ = self.T3 @ J
        H = self.C2 + 0.5 * (TJ + TJ.T) + half + 0.25 * (J.T @ (self.Q4 @ J))
        return f, H

    # -- solving --------------------------------------------------------------------------

    def solve(self, force=None, q0=None, rtol=1e-8, max_iter=50):
        """The static equilibrium under the scene's loads plus nodal forces `force` (n, 3),
        N: returns (q, NewtonReport)."""
        q0 = np.zeros(self.r) if q0 is None else np.asarray(q0, dtype=float)
        load = self._load(force)
        scale = np.linalg.norm(load) + np.linalg.norm(self.force(q0))
        return self._newton(load, q0, None, None, scale, rtol, max_iter)

    def step(self, q, v, dt, force=None, rtol=1e-8, max_iter=50):
        """One backward-Euler step of dt s from reduced state (q, v) under the scene's loads
        plus nodal forces `force` (n, 3), N: returns (q_next, v_next, NewtonReport)."""
        if not dt > 0:
            raise ValueError(f"dt: the time step must be > 0 s, got {dt}")
        q_hat = q + dt * v
        load = self._load(force)
        scale = np.linalg.norm(load) + np.linalg.norm(self.force(q)) + np.linalg.norm(v) / dt
        q_next, report = self._newton(load, q_hat, q_hat, dt, scale, rtol, max_iter)
        return q_next, (q_next - q) / dt, report

    def _load(self, force):
        return self.external if force is None else self.external + self.project(force)

    def _newton(self, load, q, q_hat, dt, scale, rtol, max_iter):
        """Minimize V(q) - load . q (+ |q - q_hat|^2 / (2 dt^2)) from q by Newton with the
        Hessian's negative eigenvalues clamped and a backtracking Armijo line search, to a
        gradient norm of rtol * scale (N, the problem's force size)."""
        inertia = 0.0 if dt is None else 1.0 / dt ** 2

        def objective(q):
            value = self.energy(q) - load @ q
            return value if dt is None else value + 0.5 * inertia * np.dot(q - q_hat, q - q_hat)

        def gradient(q):
            f, H = self.force(q, hessian=True)
            g = f - load
            if dt is not None:
                g = g + inertia * (q - q_hat)
                H = H + inertia * np.eye(self.r)
            return g, H

        value = objective(q)
        for it in range(max_iter + 1):
            g, H = gradient(q)
            residual = float(np.linalg.norm(g))
            # float64 resolves the force to about eps times the stiffness times the state
            roundoff = 1e3 * np.finfo(float).eps * (self._stiffness * np.linalg.norm(q) + scale)
            if residual <= max(rtol * scale, roundoff):
                return q, NewtonReport(True, it, residual)
            if it == max_iter:
                break
            p = -_positive_solve(H, g)
            slope = float(g @ p)
            t = 1.0
            while t > 1e-12:
                trial = q + t * p
                trial_value = objective(trial)
                if trial_value <= value + 1e-4 * t * slope:
                    break
                t *= 0.5
            else:
                return q, NewtonReport(False, it, residual)
            q, value = trial, trial_value
        return q, NewtonReport(False, max_iter, residual)


def _positive_solve(H, g):
    """H^-1 g by Cholesky where H is positive definite, else with H's eigenvalues clamped to
    a small positive floor (the projected Newton step)."""
    try:
        return scipy.linalg.cho_solve(scipy.linalg.cho_factor(H), g)
    except np.linalg.LinAlgError:
        w, V = np.linalg.eigh(H)
        w = np.maximum(w, 1e-8 * np.abs(w).max())
        return V @ ((V.T @ g) / w)


def _half_unpack(y, pi, pj, r):
    """The symmetric (r, r) Y with Y_jj = y_jj and Y_jk = Y_kj = y_jk / 2 (pairs j <= k), so
    that sum_pairs y_jk q_j q_k = q^T Y q."""
    Y = np.zeros((r, r))
    value = np.where(pi == pj, y, 0.5 * y)
    Y[pi, pj] = value
    Y[pj, pi] = value
    return Y


def _voigt(X):
    """(..., 6) Voigt vectors of symmetric (..., 3, 3) tensors (off-diagonals times sqrt 2)."""
    out = np.empty(X.shape[:-2] + (6,))
    for s, (i, j) in enumerate(_VOIGT):
        out[..., s] = X[..., i, j] if i == j else _ROOT2 * X[..., i, j]
    return out


def _whitening(el, elements, w):
    """(e, q, 6, 6) sqrt(w) R with R^T R = D the Voigt matrix of the form a: lam 1 1^T
    + 2 mu I + 8 kappa delta delta^T, delta the Voigt vector of d d^T (d^T X d = delta . x)."""
    mu, lam, kappa, d = (el.mu[elements], el.lam[elements], el.kappa[elements],
                         el.fiber[elements])
    one = np.array([1.0, 1.0, 1.0, 0.0, 0.0, 0.0])
    delta = _voigt(np.einsum("ei,ej->eij", d, d))
    D = (lam[:, None, None] * one[:, None] * one + 2.0 * mu[:, None, None] * np.eye(6)
         + 8.0 * kappa[:, None, None] * delta[:, :, None] * delta[:, None, :])
    R = np.swapaxes(np.linalg.cholesky(D), -1, -2)  # D = R^T R
    return np.sqrt(w)[:, :, None, None] * R[:, None]


def _free_hessian(potential, x, layout):
    """The true Hessian of the free unknowns at x, scipy CSR (N/m)."""
    _, _, data = potential.hessian_data(x, layout, want_grad=False)
    return layout.matrix(data).tocsc()


def _modal_derivatives(potential, x0, layout, K, phi, free):
    """Psi_ij = -K^-1 (dH/dphi_i) phi_j for i <= j (free unknowns, columns). The Hessian of
    StVK and fiber energies is quadratic in x, so its central difference along phi_i is its
    directional derivative exactly (up to round-off)."""
    solve = spla.splu(K).solve
    n = x0.shape[0]
    size = np.sqrt(np.mean(np.sum((x0 - x0.mean(0)) ** 2, axis=1)))
    out = []
    slopes = []
    for i in range(phi.shape[1]):
        u = np.zeros(3 * n)
        u[free] = phi[:, i]
        h = 1e-3 * size / np.abs(u).max()
        plus = _free_hessian(potential, x0 + h * u.reshape(n, 3), layout)
        minus = _free_hessian(potential, x0 - h * u.reshape(n, 3), layout)
        slopes.append((plus - minus) / (2.0 * h))
    for i in range(phi.shape[1]):
        for j in range(i, phi.shape[1]):
            out.append(-solve(slopes[i] @ phi[:, j]))
    return np.column_stack(out)


def _mass_orthonormal(V, mass):
    """Columns of V made orthonormal in the lumped-mass inner product by modified Gram-Schmidt
    (twice), dropping those that depend on the earlier ones (DEPENDENT)."""
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
