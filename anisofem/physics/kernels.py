"""The element loop: energies, gradients and Hessians of an element type (anisofem.physics.elements)
made of an energy density (anisofem.physics.densities), summed over quadrature points, and their
assembly.

Per element e with rest volume v and nodes x_a (a < k), at each quadrature point p with weight
w = v w_p and material shape gradients G_a = Dm^-T grad_xi N_a(xi_p) (1/m):

    F = sum_a x_a G_a^T,   Psi_e = sum_p w psi(F)                                        (J)
    g_a = sum_p w F S G_a                          (nodal gradient, N; S: 2nd Piola-Kirchhoff)
    H_ab = sum_p w (dP/dF contracted with G_a and G_b)                    (3x3 blocks, N/m)

The density (psi, S, and the contracted tangent, exact or PSD-projected at the point) is the
densities' business; this loop knows only k, the quadrature and the scatter. A linear tet is
one point with w = v, so its cost is that of a closed-form element kernel. The projection is
per point: a sum of PSD point Hessians with positive weights is PSD.

Assembly runs over colored blocks of consecutive elements (anisofem.physics.mesh.ASSEMBLY_BLOCK; no
two blocks of a color share a vertex), so the blocks of one color are scattered in parallel
without races, each thread reading and adding to one neighbourhood at a time, and results do
not depend on the thread count.
"""
import numpy as np
from numba import njit, prange

from .densities import fiber, point_hessian, point_stress
from .mesh import ASSEMBLY_BLOCK
from ..threads import parallel_threads

#: Below this many quadrature points (elements times points per element) the assembly runs on
#: one thread (parallel launches cost more).
PARALLEL_MIN_POINTS = 4000

#: Most nodes per element, and the shape of the densities' scratch array.
MAX_NODES = 10
WORK_SHAPE = (10, MAX_NODES, 3)


@njit(cache=True, inline="always")
def _deformation(t, n, G, x, F):
    """Fill F (3, 3), the deformation gradient at positions x of the element with nodes t and
    shape gradients G (n, 3) at a point."""
    for i in range(3):
        for j in range(3):
            acc = 0.0
            for a in range(n):
                acc += x[t[a], i] * G[a, j]
            F[i, j] = acc


@njit(cache=True, inline="always")
def _scatter_gradient(t, n, G, w, F, S, grad):
    """grad[node a] += w F S G_a for the n nodes t of an element (N)."""
    for i in range(3):
        P0 = F[i, 0] * S[0, 0] + F[i, 1] * S[1, 0] + F[i, 2] * S[2, 0]
        P1 = F[i, 0] * S[0, 1] + F[i, 1] * S[1, 1] + F[i, 2] * S[2, 1]
        P2 = F[i, 0] * S[0, 2] + F[i, 1] * S[1, 2] + F[i, 2] * S[2, 2]
        for a in range(n):
            grad[t[a], i] += w * (P0 * G[a, 0] + P1 * G[a, 1] + P2 * G[a, 2])


@njit(cache=True)
def _run_linear(lo, hi, x, tets, grads, weights, model, mu, lam, kappa, rest2, fdir, has_fiber,
                e_iso, e_fib, grad, want_grad, want_hess, project, hess_map, hess_data):
    """_elements for linear tets, compiled with their node and point counts as constants
    (measured: 1.2-1.4x faster than the loop over counts read at run time)."""
    _elements(4, 1, lo, hi, x, tets, grads, weights, model, mu, lam, kappa, rest2, fdir,
              has_fiber, e_iso, e_fib, grad, want_grad, want_hess, project, hess_map, hess_data)


@njit(cache=True)
def _run_general(lo, hi, x, tets, grads, weights, model, mu, lam, kappa, rest2, fdir, has_fiber,
                 e_iso, e_fib, grad, want_grad, want_hess, project, hess_map, hess_data):
    """_elements for any element type (node and point counts read at run time)."""
    _elements(tets.shape[1], weights.shape[1], lo, hi, x, tets, grads, weights, model, mu, lam,
              kappa, rest2, fdir, has_fiber, e_iso, e_fib, grad, want_grad, want_hess, project,
              hess_map, hess_data)


@njit(cache=True, inline="always")
def _elements(n, nq, lo, hi, x, tets, grads, weights, model, mu, lam, kappa, rest2, fdir,
              has_fiber, e_iso, e_fib, grad, want_grad, want_hess, project, hess_map, hess_data):
    """Energies (J), and if asked gradient and Hessian contributions, of elements lo to hi - 1,
    n nodes and nq quadrature points each; hess_map[e] ((3n)^2,) gives the position in
    hess_data of each He entry (-1: dropped)."""
    F = np.empty((3, 3))
    S = np.empty((3, 3))
    Fd = np.empty(3)
    He = np.empty((3 * n, 3 * n))
    work = np.empty(WORK_SHAPE)
    for e in range(lo, hi):
        k_e = kappa[e] if has_fiber else 0.0
        d = fdir[e]
        iso = 0.0
        fib = 0.0
        if want_hess:
            He[:] = 0.0
        for p in range(nq):
            w = weights[e, p]
            G = grads[e, p]
            _deformation(tets[e], n, G, x, F)
            iso += w * point_stress(model[e], F, mu[e], lam[e], S)
            if k_e != 0.0:
                fib += w * fiber.stress(F, d, k_e, rest2[e], S, Fd)
            if want_grad:
                _scatter_gradient(tets[e], n, G, w, F, S, grad)
            if want_hess:
                point_hessian(model[e], G, n, w, mu[e], lam[e], k_e, rest2[e], d, F, S, Fd,
                              project, work, He)
        e_iso[e] = iso
        e_fib[e] = fib
        if want_hess:
            _scatter_hessian(n, He, hess_map[e], hess_data)


@njit(cache=True, inline="always")
def _scatter_hessian(n, He, row, hess_data):
    """Mirror He's blocks a <= b to a > b and add every entry at its position in hess_data."""
    for a in range(n):
        for b in range(a + 1, n):
            for i in range(3):
                for k in range(3):
                    He[3 * b + k, 3 * a + i] = He[3 * a + i, 3 * b + k]
    size = 3 * n
    for r in range(size):
        for c in range(size):
            pos = row[size * r + c]
            if pos >= 0:
                hess_data[pos] += He[r, c]


@njit(cache=True, parallel=True)
def _run_colors(starts, color_ptr, linear, x, tets, grads, weights, model, mu, lam, kappa, rest2,
                fdir, has_fiber, e_iso, e_fib, grad, want_grad, want_hess, project, hess_map,
                hess_data):
    """The assembly blocks of each color in parallel (each block's elements in order), colors
    one after another: every sum over elements runs in the same order whatever the threads.
    linear: the elements are linear tets (_run_linear)."""
    m = tets.shape[0]
    for c in range(color_ptr.shape[0] - 1):
        for k in prange(color_ptr[c + 1] - color_ptr[c]):
            lo = starts[color_ptr[c] + k]
            hi = min(lo + ASSEMBLY_BLOCK, m)
            if linear:
                _run_linear(lo, hi, x, tets, grads, weights, model, mu, lam, kappa, rest2, fdir,
                            has_fiber, e_iso, e_fib, grad, want_grad, want_hess, project,
                            hess_map, hess_data)
            else:
                _run_general(lo, hi, x, tets, grads, weights, model, mu, lam, kappa, rest2, fdir,
                             has_fiber, e_iso, e_fib, grad, want_grad, want_hess, project,
                             hess_map, hess_data)



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

    x: (n, 3) float64 positions (m). elements: an ElementData (see anisofem.physics.scene).
    hess_map: (m, (3k)^2) int positions of each element-matrix entry in hess_data (-1:
    dropped; k nodes per element), hess_data: float64 array to which the Hessian entries are
    added (caller zeroes it).
    Returns (e_iso (m,), e_fiber (m,), grad (n, 3) or None), energies in J, gradient in N.
    """
    m = elements.tets.shape[0]
    e_iso = np.empty(m)
    e_fib = np.empty(m)
    grad = np.zeros_like(x) if want_grad else EMPTY_GRAD
    if not want_hess:
        hess_map, hess_data = _EMPTY_MAP, _EMPTY_DATA
    args = (x, elements.tets, elements.grads, elements.weights, elements.model, elements.mu,
            elements.lam, elements.kappa, elements.rest2, elements.fiber, elements.has_fiber, e_iso,
            e_fib, grad,
            want_grad, want_hess, project, hess_map, hess_data)
    linear = elements.tets.shape[1] == 4 and elements.weights.shape[1] == 1
    if m * elements.weights.shape[1] < PARALLEL_MIN_POINTS:
        (_run_linear if linear else _run_general)(0, m, *args)
    else:
        parallel_threads()
        _run_colors(elements.block_starts, elements.color_ptr, linear, *args)
    return e_iso, e_fib, (grad if want_grad else None)


EMPTY_GRAD = np.empty((0, 3))
_EMPTY_MAP = np.empty((0, 144), dtype=np.int32)
_EMPTY_DATA = np.empty(0)
