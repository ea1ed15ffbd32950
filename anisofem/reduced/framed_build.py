"""How a framed model's domains are built (anisofem.reduced.framed): each domain's local basis
from the full FEM's equilibria pulled back into their best-fitting frames and the rest vibration
modes, rigid motion removed; its basis moments and the polynomial of its inner elements; and the
map of the joint elements' matrices onto 3 x 3 node blocks."""
from dataclasses import dataclass

import numpy as np
import scipy.sparse.linalg as spla

from ..physics.potential import Potential
from . import basis as _basis
from .framed_kernels import GEN
from .polynomial import polynomial
from .snapshots import principal_directions


@dataclass
class Domain:
    """One domain: nodes (k,); centre (3,), its rest centre of mass, m; y (k, 3) the nodes'
    rest positions about it, m; U
    (k, 3, r) its local basis; mass, kg; the moments of its basis (a (r,) = sum m U_b . y,
    J (3, 3) = sum m y y^T, A (r, 3, 3) = sum m U_a y^T, B (r, r, 3, 3) = sum m U_a U_b^T);
    polynomial, the energy of its inner elements; radius, the largest |y|, m; reach, the
    largest row norm of U; z and q, its slices of the Newton unknowns and of FramedState.q."""
    nodes: np.ndarray
    centre: np.ndarray
    y: np.ndarray
    U: np.ndarray
    mass: float
    a: np.ndarray
    J: np.ndarray
    A: np.ndarray
    B: np.ndarray
    polynomial: object
    radius: float
    reach: float
    z: slice
    q: slice

    @property
    def r(self):
        return self.U.shape[2]


def cross_matrices(w):
    """(m, 3, 3) [w]_x of each row of w (m, 3)."""
    return np.einsum("mj,jab->mab", w, GEN)


def block_map(tets, pairs, free):
    """(m, (3k)^2) where each element-matrix entry (3 a + i, 3 b + j) of elements tets (m, k)
    lands among 3 x 3 blocks, one per row of pairs (p, 2) (sorted node pairs): 9 p + 3 i + j,
    or -1 where a node is not free."""
    m, k = tets.shape
    a = np.repeat(np.arange(k), 3)[:, None].repeat(3 * k, axis=1)
    b = a.T
    i = np.tile(np.arange(3), k)[:, None].repeat(3 * k, axis=1)
    j = i.T
    first, second = tets[:, a], tets[:, b]                     # (m, 3k, 3k)
    keys = pairs[:, 0] * (pairs.max() + 1) + pairs[:, 1]
    p = np.searchsorted(keys, first * (pairs.max() + 1) + second)
    position = 9 * p + 3 * i + j
    position[~(free[first] & free[second])] = -1
    return position.reshape(m, -1).astype(np.int32 if 9 * len(pairs) < 2 ** 31 else np.int64)


def rest_modes(scene, x0, count):
    """The `count` lowest vibration modes at rest as node fields (count, n, 3), m."""
    n = scene.mesh.n_vertices
    if count == 0:
        return np.zeros((0, n, 3))
    free = scene.free_dofs
    mass = np.repeat(scene.masses, 3)[free]
    K = _basis.free_hessian(Potential(scene), x0, scene.layout("csr"))
    _, phi = _basis.vibration_modes(K, spla.splu(K), mass, count)
    out = np.zeros((count, 3 * n))
    out[:, free] = phi.T
    return out.reshape(count, n, 3)


def best_frame(x, y, m):
    """The rotation R (3, 3) and centre c (3,) that best carry rest offsets y (k, 3) (about
    their centre of mass) onto positions x (k, 3), weighted by masses m (k,)."""
    c = m @ x / m.sum()
    u, _, vt = np.linalg.svd((m[:, None] * y).T @ (x - c))
    flip = np.diag([1.0, 1.0, np.sign(np.linalg.det(vt.T @ u.T))])
    return vt.T @ flip @ u.T, c


def build_domain(scene, x0, nodes, states, modes, count, inner, z, q):
    """The Domain of `nodes`: its local basis from the states (s, n, 3) pulled back into their
    best frames and the mode fields (k, n, 3), rigid motion removed; its moments; the
    polynomial of its inner elements."""
    m = scene.masses[nodes]
    mass = float(m.sum())
    centre = m @ x0[nodes] / mass
    y = x0[nodes] - centre
    local = []
    for x in states:
        R, c = best_frame(x[nodes], y, m)
        local.append(((x[nodes] - c) @ R - y).ravel())
    local.extend(field[nodes].ravel() for field in modes)
    S = np.array(local).T
    weights = np.repeat(m, 3)
    norms = np.sqrt(weights @ S ** 2)
    S = S[:, norms > 1e-12 * max(norms.max(), 1e-300)]
    rigid = _basis.mass_orthonormal(rigid_motions(y), weights)
    U = principal_directions(S, weights, min(count, 3 * nodes.size - 6), against=rigid)
    U = U.reshape(nodes.size, 3, -1)
    r = U.shape[2]
    full = np.zeros((3 * scene.mesh.n_vertices, r))
    full[(3 * nodes[:, None] + np.arange(3)).ravel()] = U.reshape(-1, r)
    return Domain(
        nodes=nodes, centre=centre, y=y, U=U, mass=mass, a=np.einsum("k,kir,ki->r", m, U, y),
        J=(m[:, None] * y).T @ y, A=np.einsum("k,kia,kj->aij", m, U, y),
        B=np.einsum("k,kia,kjb->abij", m, U, U),
        polynomial=polynomial(scene.elements.subset(inner), x0, full),
        radius=float(np.linalg.norm(y, axis=1).max()),
        reach=float(np.linalg.norm(U.reshape(-1, 3, r), axis=(1, 2)).max()),
        z=slice(z, z + 6 + r), q=slice(q, q + r))


def rigid_motions(y):
    """(3k, 6) the translations and small rotations about the origin of offsets y (k, 3)."""
    V = np.zeros((y.shape[0], 3, 6))
    V[:, :, :3] = np.eye(3)
    V[:, :, 3:] = -cross_matrices(y)
    return V.reshape(-1, 6)
