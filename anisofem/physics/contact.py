"""Contact with rigid obstacles by Incremental Potential Contact (Li et al. 2020): a barrier
that grows without bound as a surface node nears an obstacle, and a smoothed Coulomb friction
potential, both added to the incremental potential, with every Newton step clipped so that no
node reaches an obstacle along its way (anisofem.physics.obstacles.first_touch).

Barrier, per surface node i and obstacle o at distance d < dhat:
    B = kappa sum A_i b(d),   b(d) = -(d - dhat)^2 ln(d / dhat),
A_i the node's share of the rest surface area (m^2), so kappa (N/m^3) sets a contact pressure
-kappa b'(d) that does not depend on the mesh; default kappa = E / dhat, E the stiffest
element's Young's modulus (a pressure of E at d = 0.43 dhat, 3 E eps^2 at d = (1 - eps) dhat).
The gradient is kappa A b'(d) n and the Hessian kappa A (b''(d) n n^T + b'(d) D^2 d), D^2 d
the obstacle's curvature (b' < 0: negative semi-definite there; the PSD-projected Hessian
clamps each node's 3 x 3 block).

Friction, in a backward-Euler step only, lagged at the step's start x_n (IPC's lagged
friction, one lag per step): each node in contact there gets its normal force
lambda = -kappa A b'(d) and tangent projector T = I - n n^T, and the step adds
    D = sum mu lambda f0(|u|),   u = T (x - x_n),
f0 Coulomb's |u| smoothed below eps_u = smoothing velocity times dt (f0(y) = -y^3 / (3 eps^2)
+ y^2 / eps + eps / 3): a node sliding slower than the smoothing velocity sticks elastically,
faster it feels mu lambda against its motion. Statics has no friction (it has no motion to
resist).
"""
import copy
import math
import weakref
from dataclasses import dataclass, replace

import numpy as np

from .._validate import as_scalar
from .obstacles import SHAPES, Obstacle
from .self_contact import SelfContact, surface_share

#: The default contact distance dhat over the body's size (its rest bounding box diagonal).
DISTANCE_SHARE = 1e-3
#: The default smoothing velocity of friction, m/s, over the body's size per second.
SMOOTHING_SHARE = 1e-3
#: A step keeps each node at least this share of its distance now from every obstacle.
KEEP = 0.1


@dataclass(frozen=True)
class Contact:
    """Contact of the body with rigid obstacles: obstacles (a sequence of anisofem Plane,
    Sphere, Box, Capsule, Surface; may be empty with self_contact); distance dhat, m, at which
    the barrier starts (default 1e-3 of the body's size); friction mu >= 0 (an obstacle's own
    coefficient wins); stiffness kappa, N/m^3 (default E / dhat); smoothing, m/s, the velocity
    below which friction sticks (default 1e-3 of the body's size per second); self_contact:
    the surface's contact with itself and between the bodies of one mesh too (by ipctk,
    anisofem.physics.self_contact)."""
    obstacles: tuple = ()
    distance: float = None
    friction: float = 0.0
    stiffness: float = None
    smoothing: float = None
    self_contact: bool = False

    def __post_init__(self):
        obstacles = ((self.obstacles,) if isinstance(self.obstacles, Obstacle)
                     else tuple(self.obstacles))
        if not isinstance(self.self_contact, bool):
            raise TypeError(f"contact: self_contact: expected True or False, got "
                            f"{self.self_contact!r}")
        if not obstacles and not self.self_contact:
            raise ValueError("contact: obstacles: give at least one, or self_contact=True")
        for o in obstacles:
            if not isinstance(o, Obstacle):
                raise TypeError(f"contact: obstacles: expected anisofem obstacles (Plane, "
                                f"Sphere, Box, Capsule, Surface), got {type(o).__name__}")
        object.__setattr__(self, "obstacles", obstacles)
        for key in ("distance", "stiffness", "smoothing"):
            value = getattr(self, key)
            if value is not None:
                value = as_scalar(value, f"contact {key}")
                if not value > 0:
                    raise ValueError(f"contact: {key} must be > 0, got {value:g}")
                object.__setattr__(self, key, value)
        friction = as_scalar(self.friction, "contact friction")
        if friction < 0:
            raise ValueError(f"contact: friction must be >= 0, got {friction:g}")
        object.__setattr__(self, "friction", friction)

    @property
    def pairs(self):
        """Whether part of it is taken pair by pair (ipctk): self-contact, or a Surface
        obstacle. Its pairs may couple nodes no element joins."""
        return self.self_contact or any(not isinstance(o, SHAPES) for o in self.obstacles)


class ContactTerm:
    """A scene's contact in one problem: the barrier (and, with dt, the friction lagged at
    x_lag (n, 3)) over the mesh's surface nodes."""

    def __init__(self, scene, x_lag=None, dt=None):
        contact, mesh = scene.contact, scene.mesh
        self.contact = contact
        self.obstacles = tuple(o for o in contact.obstacles if isinstance(o, SHAPES))
        surfaces = tuple(o for o in contact.obstacles if not isinstance(o, SHAPES))
        self.nodes, self.area = surface_nodes(mesh)
        self.size = body_size(mesh)
        self.dhat = contact.distance or DISTANCE_SHARE * self.size
        self.kappa = contact.stiffness or stiffest_modulus(scene) / self.dhat
        self.friction, self.itself = (), None
        lagged = dt is not None and x_lag is not None
        if lagged:
            self.friction = self.friction_at(x_lag[self.nodes], dt)
        if contact.pairs:
            self.itself = SelfContact(mesh, self.dhat, self.kappa, x_lag=x_lag,
                                      mu=contact.friction if lagged else 0.0,
                                      eps=self.smoothing(dt) if lagged else None,
                                      surfaces=surfaces, itself=contact.self_contact)
        self._positions = {}

    def lagged(self, x, dt):
        """A copy of this term whose friction is that of a step of dt s lagged at the surface
        nodes' positions x (k, 3)."""
        moved = copy.copy(self)
        moved.friction = self.friction_at(x, dt)
        return moved

    def smoothing(self, dt):
        """eps_u, m: the tangential displacement over a step of dt s below which friction
        sticks."""
        return (self.contact.smoothing or SMOOTHING_SHARE * self.size) * dt

    def friction_at(self, x, dt):
        """The friction of a step of dt s lagged at the surface nodes' positions x (k, 3): per
        obstacle with friction, (mu lambda (c,), rows (c,), T (c, 3, 3), x_lag (c, 3), eps) of
        the nodes within dhat of it there."""
        out, eps = [], self.smoothing(dt)
        for o in self.obstacles:
            mu = self.contact.friction if o.friction is None else o.friction
            if mu <= 0:
                continue
            d, n = o.distance(x)
            rows = np.flatnonzero((d > 0) & (d < self.dhat))
            if not rows.size:
                continue
            force = -self.kappa * self.area[rows] * barrier_slope(d[rows], self.dhat)
            T = np.eye(3) - n[rows, :, None] * n[rows, None, :]
            out.append((mu * force, rows, T, x[rows] + o.shift, eps))
        return tuple(out)

    def energy(self, x, grad=None):
        """The barrier's and friction's energy at positions x (n, 3), J (inf where a node
        reached an obstacle); adds their gradient to grad (n, 3) when given."""
        total, g = self.surface_energy(x[self.nodes])
        if grad is not None:
            np.add.at(grad, self.nodes, g)
        if self.itself is not None and math.isfinite(total):
            total += self.itself.energy(x, grad)
        return total

    def surface_energy(self, xs):
        """(energy J, gradient (k, 3) N) of the obstacles' barrier and friction at the
        surface nodes' positions xs (k, 3); inf (and a zero gradient) where a node reached an
        obstacle."""
        total, g = 0.0, np.zeros_like(xs)
        for o in self.obstacles:
            d, n = o.distance(xs)
            if (d <= 0).any():
                return math.inf, np.zeros_like(xs)
            near = d < self.dhat
            if near.any():
                a, dn = self.area[near], d[near]
                total += self.kappa * float(a @ barrier(dn, self.dhat))
                g[near] += (self.kappa * a * barrier_slope(dn, self.dhat))[:, None] * n[near]
        for weight, rows, T, start, eps in self.friction:
            u = np.einsum("kij,kj->ki", T, xs[rows] - start)
            y = np.sqrt(np.einsum("ij,ij->i", u, u))
            total += float(weight @ smoothed(y, eps))
            g[rows] += (weight * slope_over(y, eps))[:, None] * u
        return total, g

    def node_hessians(self, x, project=False):
        """(k, 3, 3) each surface node's Hessian block of the barrier and friction at x (n, 3);
        project: each block clamped to positive semi-definite."""
        return self.surface_hessians(x[self.nodes], project=project)

    def in_reach(self, xs):
        """(k,) bool: the surface nodes at xs (k, 3) within dhat of an obstacle, or with
        friction (the others' Hessian blocks are 0)."""
        near = np.zeros(len(xs), bool)
        for o in self.obstacles:
            near |= o.distance(xs)[0] < self.dhat
        for _, rows, _, _, _ in self.friction:
            near[rows] = True
        return near

    def surface_hessians(self, xs, rows=None, project=False):
        """node_hessians at the surface nodes' positions xs (k, 3), or at those of the nodes
        `rows` (c,) only (indices among the surface nodes), xs then (c, 3)."""
        rows = np.arange(len(xs)) if rows is None else rows
        H = np.zeros((len(xs), 3, 3))
        for o in self.obstacles:
            d, n, curvature = o.geometry(xs)
            near = (d > 0) & (d < self.dhat)
            if near.any():
                a, dn, nn = self.area[rows][near], d[near], n[near]
                H[near] += self.kappa * a[:, None, None] * (
                    barrier_curvature(dn, self.dhat)[:, None, None] * nn[:, :, None]
                    * nn[:, None, :] + barrier_slope(dn, self.dhat)[:, None, None]
                    * curvature[near])
        local = np.full(len(self.nodes), -1)
        local[rows] = np.arange(len(rows))
        for weight, lagged, T, start, eps in self.friction:
            at = local[lagged]
            kept = at >= 0
            at, weight, T, start = at[kept], weight[kept], T[kept], start[kept]
            u = np.einsum("kij,kj->ki", T, xs[at] - start)
            y = np.sqrt(np.einsum("ij,ij->i", u, u))
            unit = u / np.maximum(y, 1e-300)[:, None]     # (f0'' - f0' / y) along u
            along = np.where(y < eps, -y / (eps * eps), -1.0 / np.maximum(y, 1e-300))
            H[at] += weight[:, None, None] * (slope_over(y, eps)[:, None, None] * T
                                              + along[:, None, None] * unit[:, :, None]
                                              * unit[:, None, :])
        if project:
            lam, V = np.linalg.eigh(H)
            H = np.einsum("kij,kj,klj->kil", V, np.maximum(lam, 0.0), V)
        return H

    def add_hessian(self, x, layout, data, project=False):
        """Add the nodes' blocks into data, the entries of `layout`."""
        if id(layout) not in self._positions:
            where = layout.positions(self.nodes[:, None])
            self._positions[id(layout)] = (layout, where >= 0, where[where >= 0])
        _, keep, where = self._positions[id(layout)]
        H = self.node_hessians(x, project)
        np.add.at(data, where, H.reshape(len(H), -1)[keep])

    def max_step(self, x, dx):
        """The largest share in (0, 1] of the move dx (n, 3) from x (n, 3) along which no
        surface node comes closer to an obstacle than KEEP of its distance now."""
        share = self.surface_max_step(x[self.nodes], dx[self.nodes])
        if self.itself is not None:
            share = min(share, self.itself.max_step(x, dx))
        return share

    def surface_max_step(self, xs, ds):
        """max_step's obstacle part for surface nodes at xs (k, 3) moving by ds (k, 3)."""
        move = np.sqrt(np.einsum("ij,ij->i", ds, ds))
        share = 1.0
        for o in self.obstacles:
            d, _ = o.distance(xs)
            near = move > (1.0 - KEEP) * d   # the others cannot come within KEEP d
            share = min(share, float(o.first_touch(xs[near], ds[near], KEEP * d[near]).min(
                initial=1.0)))
        return share

    def coupled_hessian(self, x, dofs, project=False):
        """The self-contact's Hessian at x (n, 3) over the flat degrees of freedom `dofs`, a
        scipy CSC matrix (its pairs couple nodes no element joins), or None without
        self-contact."""
        if self.itself is None:
            return None
        H = self.itself.hessian(x, project).tocsr()[dofs]
        return H.tocsc()[:, dofs]

    def clear(self, x):
        """Whether every surface node at x (n, 3) is off every obstacle, and the surface off
        itself and the surfaces (nowhere touching or crossing them)."""
        return bool((self.distances(x) > 0).all()) and (
            self.itself is None or self.itself.clear(x))

    def distances(self, x):
        """(k, obstacles) every surface node's distance to every obstacle at x (n, 3), m."""
        xs = x[self.nodes]
        return np.column_stack([o.distance(xs)[0] for o in self.obstacles]
                               or [np.full(len(xs), np.inf)])


def advance(target, placed, mesh, x, origin):
    """(the Contact `target` with each obstacle moved from where the Contact `placed` (the same
    obstacles) has it toward where target has it, as far as the body of `mesh` at x (n, 3)
    lets it, held, whether every one got there): the body kept at KEEP of its gap (the share
    of the way first_touch allows its surface nodes, or ipctk's collision test a surface's),
    so a moving obstacle pushes the body and never jumps into it. Each obstacle's shift is its
    move since `origin` (where its step began), which friction's anchor follows."""
    obstacles, arrived = [], True
    xs = x[surface_nodes(mesh)[0]]
    for aim, now, before in zip(target.obstacles, placed.obstacles, origin.obstacles):
        delta = aim.position - now.position
        if not np.any(delta):
            share = 1.0
        elif not isinstance(now, SHAPES):
            share = surface_share(mesh, now, x, delta)
        else:
            d, _ = now.distance(xs)
            share = float(now.first_touch(xs, np.broadcast_to(-delta, xs.shape),
                                          KEEP * d).min(initial=1.0))
        there = now.moved(share * delta) if share < 1.0 else copy.copy(aim)
        there.shift = there.position - before.position
        obstacles.append(there)
        arrived &= share >= 1.0
    return replace(target, obstacles=tuple(obstacles)), arrived


def barrier(d, dhat):
    """b(d) = -(d - dhat)^2 ln(d / dhat) for 0 < d < dhat, m^2."""
    return -(d - dhat) ** 2 * np.log(d / dhat)


def barrier_slope(d, dhat):
    """b'(d), m."""
    return -2.0 * (d - dhat) * np.log(d / dhat) - (d - dhat) ** 2 / d


def barrier_curvature(d, dhat):
    """b''(d)."""
    return -2.0 * np.log(d / dhat) - 4.0 * (d - dhat) / d + (d - dhat) ** 2 / (d * d)


def smoothed(y, eps):
    """f0(y): |u| smoothed below eps, m."""
    return np.where(y < eps, -y ** 3 / (3 * eps * eps) + y * y / eps + eps / 3.0, y)


def slope_over(y, eps):
    """f0'(y) / y, 1/m (2 / eps at y = 0)."""
    return np.where(y < eps, -y / (eps * eps) + 2.0 / eps, 1.0 / np.maximum(y, 1e-300))


def surface_nodes(mesh):
    """(nodes (k,), area (k,) m^2), read-only: the nodes of the mesh's boundary faces
    (corners; midside nodes too on quadratic tets) and each one's share of the rest boundary
    area, each face's split evenly over its 3 (linear) or 6 (quadratic) nodes: every node of
    the surface feels the barrier. Found once per mesh (every step's contact reads them)."""
    if mesh not in _SURFACES:
        _SURFACES[mesh] = _surface(mesh)
    return _SURFACES[mesh]


#: surface_nodes of each mesh alive
_SURFACES = weakref.WeakKeyDictionary()


def _surface(mesh):
    faces = mesh.boundary_faces
    X = mesh.vertices
    area = 0.5 * np.linalg.norm(np.cross(X[faces[:, 1]] - X[faces[:, 0]],
                                         X[faces[:, 2]] - X[faces[:, 0]]), axis=1)
    if mesh.order == 2:
        faces = np.column_stack([faces] + [mesh.edge_nodes(faces[:, [a, b]])
                                           for a, b in ((0, 1), (1, 2), (2, 0))])
    share = np.zeros(mesh.n_vertices)
    for c in range(faces.shape[1]):
        np.add.at(share, faces[:, c], area / faces.shape[1])
    nodes = np.unique(faces)
    area = share[nodes]
    for a in (nodes, area):
        a.setflags(write=False)
    return nodes, area


def body_size(mesh):
    """The diagonal of the mesh's rest bounding box, m."""
    return float(np.linalg.norm(np.ptp(mesh.vertices, axis=0)))


def stiffest_modulus(scene):
    """The largest Young's modulus among the scene's elements (of the base material), Pa."""
    return float(np.max(scene.material.per_element(scene.mesh.n_tets)["young"]))
