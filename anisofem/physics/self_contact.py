"""Contact of the body's surface with itself (and between the bodies of one mesh) by the IPC
Toolkit (ipctk, an optional extra: `pip install ipctk`): its barrier over the point-triangle
and edge-edge pairs nearer than dhat, its lagged smoothed friction, and its continuous
collision test. Written with ipctk rather than by hand because the pairs' distances, their
derivatives in every closest-feature case and a robust CCD of moving triangles are exactly what
it is built and tested for.

Its barrier acts on squared distances (b(d^2, dhat^2), area weighted); its stiffness is the
Contact's kappa times SCALE / dhat^2, so that between two parallel faces at dhat / 2 the
pressure equals the obstacles' barrier's there (anisofem.physics.contact). The surface is the
mesh's boundary triangles (a quadratic face split into its four corner-midside triangles).
"""
import weakref

import numpy as np
import scipy.sparse as sp

#: ipctk's stiffness per unit of the Contact's kappa, times dhat^2. Between two parallel faces
#: at distance d its area-weighted pairs press with C kappa_i 2 d |B'(d^2)| per area, B(s) =
#: -(s - dhat^2)^2 ln(s / dhat^2) and C -> 8/3 on fine faces (measured: 2.16, 2.40, 2.53 on
#: 4, 8, 16 cells a side); the obstacles' barrier presses with kappa |b'(d)|. At d = dhat / 2
#: they are equal where kappa_i = SCALE kappa / dhat^2.
SCALE = 3.0 * (0.5 + np.log(2.0)) / (8.0 * (1.5 * np.log(4.0) + 2.25))

#: ipctk's collision meshes of each mesh alive: {(itself, the surfaces' triangles' ids):
#: (the surfaces' triangles, kept so their ids stay theirs; the CollisionMesh; its owners)}
_COLLISION_MESHES = weakref.WeakKeyDictionary()


def ipctk_module():
    """The ipctk module, or ImportError saying how to install it."""
    try:
        import ipctk
    except ImportError:
        raise ImportError("contact: self_contact needs the IPC Toolkit: pip install ipctk "
                          "(or pip install anisofem[contact])") from None
    return ipctk


def surface_triangles(mesh):
    """(f, 3) the boundary triangles of the mesh: its boundary faces, or for quadratic tets
    each face's four triangles of corners and midside nodes."""
    faces = mesh.boundary_faces
    if mesh.order == 1:
        return np.ascontiguousarray(faces, dtype=np.int32)
    a, b, c = faces.T
    ab, bc, ca = (mesh.edge_nodes(np.column_stack(pair)) for pair in ((a, b), (b, c), (c, a)))
    return np.ascontiguousarray(np.concatenate([
        np.column_stack([a, ab, ca]), np.column_stack([ab, b, bc]),
        np.column_stack([ca, bc, c]), np.column_stack([ab, bc, ca])]), dtype=np.int32)


class SelfContact:
    """Contact pair by pair in one problem: the body's surface with itself (itself=True) and
    with the rigid `surfaces` (anisofem.Surface obstacles, where they are now); dhat (m),
    kappa (N/m^3, the Contact's), and with friction (mu > 0 for the body, or a surface's own)
    and eps (m, smoothing velocity times dt) the friction lagged at x_lag (n, 3), the
    surfaces then where they were at the step's start (less their shift)."""

    def __init__(self, mesh, dhat, kappa, x_lag=None, mu=0.0, eps=None, surfaces=(),
                 itself=True):
        ipctk = self.ipctk = ipctk_module()
        self.surfaces = tuple(surfaces)
        self.mesh, owner = collision_mesh(mesh, self.surfaces, itself)
        self.dhat = dhat
        self.barrier = ipctk.BarrierPotential(dhat, kappa * SCALE / dhat ** 2)
        self.n = mesh.n_vertices
        self.friction = None
        body_mu = mu if eps is not None else 0.0
        mus = [body_mu] + [body_mu if o.friction is None else o.friction
                           for o in self.surfaces]
        if x_lag is not None and eps is not None and max(mus) > 0:
            lag = self.mesh.vertices(np.asfortranarray(np.vstack(
                [x_lag] + [o.vertices - o.shift for o in self.surfaces])))
            pairs = self.collisions(lag)
            if len(pairs):
                tangential = ipctk.TangentialCollisions()
                if self.surfaces:   # a pair with a surface takes its coefficient
                    each = np.where(owner > 0, np.array(mus)[owner], -1.0)[:, None]
                    tangential.build(self.mesh, lag, pairs, self.barrier, each, each,
                                     lambda a, b: body_mu if max(a, b) < 0 else max(a, b))
                else:
                    tangential.build(self.mesh, lag, pairs, self.barrier, body_mu)
                self.friction = (tangential, ipctk.FrictionPotential(eps), lag)

    def vertices(self, x):
        """The collision mesh's vertices with the body at positions x (n, 3)."""
        if self.surfaces:
            x = np.vstack([x] + [o.vertices for o in self.surfaces])
        return self.mesh.vertices(np.asfortranarray(x))

    def collisions(self, V):
        """The pairs nearer than dhat at collision-mesh vertices V."""
        pairs = self.ipctk.NormalCollisions()
        pairs.use_area_weighting = True
        pairs.build(self.mesh, V, self.dhat)
        return pairs

    def energy(self, x, grad=None):
        """The barrier's and friction's energy at x (n, 3), J (inf where two parts of the
        surface meet); adds the gradient to grad (n, 3) when given."""
        V = self.vertices(x)
        pairs = self.collisions(V)
        if len(pairs) and pairs.compute_minimum_distance(self.mesh, V) <= 0.0:
            return np.inf
        total = self.barrier(pairs, self.mesh, V) if len(pairs) else 0.0
        g = (self.barrier.gradient(pairs, self.mesh, V) if len(pairs)
             else np.zeros(V.size))
        if self.friction is not None:
            tangential, potential, lag = self.friction
            total += potential(tangential, self.mesh, V - lag)
            g = g + potential.gradient(tangential, self.mesh, V - lag)
        if grad is not None:
            grad += self.mesh.to_full_dof(g).reshape(-1, 3)[:self.n]
        return float(total)

    def hessian(self, x, project=False):
        """(3n, 3n) scipy sparse, the barrier's and friction's Hessian at x (n, 3); project:
        each pair's clamped to positive semi-definite."""
        V = self.vertices(x)
        how = (self.ipctk.PSDProjectionMethod.CLAMP if project
               else self.ipctk.PSDProjectionMethod.NONE)
        pairs = self.collisions(V)
        H = sp.csc_matrix((V.size, V.size))
        if len(pairs):
            H = self.barrier.hessian(pairs, self.mesh, V, how)
        if self.friction is not None:
            tangential, potential, lag = self.friction
            H = H + potential.hessian(tangential, self.mesh, V - lag, how)
        H = self.mesh.to_full_dof(sp.csc_matrix(H))
        return H if not self.surfaces else H.tocsr()[:3 * self.n].tocsc()[:, :3 * self.n]

    def max_step(self, x, dx):
        """The largest share in (0, 1] of the move dx (n, 3) from x along which no two parts of
        the surface come nearer than a tenth of their nearest distance now."""
        return free_share(self.mesh, self.vertices(x), self.vertices(x + dx), self.dhat)

    def clear(self, x):
        """Whether the body's surface at x (n, 3) nowhere touches or crosses itself or the
        surfaces (a crossing can leave every pair's distance positive: ipctk's intersection
        test)."""
        return self.nearest(x) > 0 and not self.ipctk.has_intersections(self.mesh,
                                                                       self.vertices(x))

    def nearest(self, x):
        """The smallest distance between two parts of the surface within dhat at x, m (inf
        where none is that near)."""
        V = self.vertices(x)
        pairs = self.collisions(V)
        return (float(np.sqrt(pairs.compute_minimum_distance(self.mesh, V))) if len(pairs)
                else np.inf)


def free_share(cm, V0, V1, reach):
    """The largest share in (0, 1] of the move of the collision mesh cm's vertices from V0 to
    V1 along which no two parts within `reach` m of each other at V0 come nearer than a tenth
    of their nearest distance there (ipctk's additive CCD, Li et al. 2021: its tight-inclusion
    default took 11 s for one step of the beam over a surface block, whose faces are much
    larger than the beam's)."""
    ipctk = ipctk_module()
    pairs = ipctk.NormalCollisions()
    pairs.build(cm, V0, reach)
    floor = 0.0
    if len(pairs):   # ipctk's distances are squared
        floor = 0.1 * float(np.sqrt(pairs.compute_minimum_distance(cm, V0)))
    return float(ipctk.compute_collision_free_stepsize(cm, V0, V1, min_distance=floor,
                                                       narrow_phase_ccd=ipctk.AdditiveCCD()))


def surface_share(mesh, surface, x, delta):
    """The largest share in (0, 1] of a move delta (3,) m of the Surface `surface`, the body
    of `mesh` held at x (n, 3), along which it comes no nearer to the body than a tenth of
    their nearest distance now (only what is nearer than the move can be met)."""
    cm, _ = collision_mesh(mesh, (surface,), itself=False)
    V0, V1 = (cm.vertices(np.asfortranarray(np.vstack([x, surface.vertices + d])))
              for d in (0.0, delta))
    return free_share(cm, V0, V1, float(np.linalg.norm(delta)))


def collision_mesh(mesh, surfaces=(), itself=True):
    """(ipctk's CollisionMesh of the mesh's boundary triangles and the surfaces' (their
    vertices after the mesh's, in order), whose pairs are the body's with itself (itself) and
    with each surface, never a surface's with itself or another; (v,) int the owner of each of
    its vertices, 0 the body, k the k-th surface). Built once per mesh and set of surfaces
    (every step reads it)."""
    ipctk = ipctk_module()
    key = (itself,) + tuple(id(o.triangles) for o in surfaces)
    built = _COLLISION_MESHES.setdefault(mesh, {})
    if key not in built:
        faces = [surface_triangles(mesh)]
        start = mesh.n_vertices
        for o in surfaces:
            faces.append(o.triangles + start)
            start += len(o.vertices)
        faces = np.ascontiguousarray(np.concatenate(faces), dtype=np.int32)
        rest = np.vstack([mesh.vertices] + [o.vertices for o in surfaces])
        cm = ipctk.CollisionMesh.build_from_full_mesh(np.asfortranarray(rest),
                                                      ipctk.edges(faces), faces)
        full = cm.vertices(np.asfortranarray(np.repeat(np.arange(len(rest), dtype=float)[:, None],
                                                       3, axis=1)))[:, 0]   # its full ids
        ends = np.cumsum([mesh.n_vertices] + [len(o.vertices) for o in surfaces])
        owner = np.searchsorted(ends, full, side="right")
        if surfaces:   # ipctk keeps the full mesh's order: the body's vertices come first
            fixed = owner > 0
            if fixed[:int((~fixed).sum())].any():
                raise RuntimeError("ipctk reordered the collision mesh's vertices; its filter "
                                   "of the surfaces' pairs needs the body's first")
            cm.can_collide = (ipctk.make_static_obstacle_filter(int((~fixed).sum())) if itself
                              else ipctk.make_vertex_patches_filter(fixed.astype(np.int32)))
        built[key] = ([o.triangles for o in surfaces], cm, owner)
    return built[key][1:]


def check_rest(contact, x):
    """ValueError where the body's surface at x (n, 3) intersects (or touches) itself."""
    if contact.ipctk.has_intersections(contact.mesh, contact.vertices(x)):
        raise ValueError("contact: self_contact: the body's surface intersects or touches "
                         "itself at rest; self-contact needs parts apart")


def check_surface(mesh, surface, x):
    """ValueError naming the surface obstacle where the body at x (n, 3) crosses or touches
    it, with the body's surface node nearest its vertices."""
    pairs = SelfContact(mesh, 1e-3 * float(np.ptp(x, axis=0).max()), 1.0,
                        surfaces=(surface,), itself=False)
    V = pairs.vertices(x)
    if pairs.ipctk.has_intersections(pairs.mesh, V) or pairs.nearest(x) <= 0:
        from scipy.spatial import cKDTree
        nodes = np.unique(surface_triangles(mesh))
        _, at = cKDTree(x[nodes]).query(surface.vertices)
        near = x[nodes[at[np.argmin(np.linalg.norm(x[nodes[at]] - surface.vertices,
                                                   axis=1))]]]
        raise ValueError(f"contact: the body starts inside obstacle {surface.name!r} "
                         f"(surface): its triangles cross the body's surface, near "
                         f"({', '.join(f'{v:.4g}' for v in near)})")
