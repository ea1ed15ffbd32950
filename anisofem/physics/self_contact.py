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

#: ipctk's CollisionMesh of each mesh alive
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
    """The surface's contact with itself in one problem: dhat (m), kappa (N/m^3, the
    Contact's), and with friction mu > 0 and eps (m, smoothing velocity times dt) the friction
    lagged at x_lag (n, 3)."""

    def __init__(self, mesh, dhat, kappa, x_lag=None, mu=0.0, eps=None):
        ipctk = self.ipctk = ipctk_module()
        if mesh not in _COLLISION_MESHES:
            faces = surface_triangles(mesh)
            _COLLISION_MESHES[mesh] = ipctk.CollisionMesh.build_from_full_mesh(
                np.asfortranarray(mesh.vertices), ipctk.edges(faces), faces)
        self.mesh = _COLLISION_MESHES[mesh]     # built once per mesh: every step reads it
        self.dhat = dhat
        self.barrier = ipctk.BarrierPotential(dhat, kappa * SCALE / dhat ** 2)
        self.n = mesh.n_vertices
        self.friction = None
        if mu > 0 and x_lag is not None:
            lag = self.vertices(x_lag)
            pairs = self.collisions(lag)
            if len(pairs):
                tangential = ipctk.TangentialCollisions()
                tangential.build(self.mesh, lag, pairs, self.barrier, mu)
                self.friction = (tangential, ipctk.FrictionPotential(eps), lag)

    def vertices(self, x):
        """The collision mesh's vertices at positions x (n, 3)."""
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
            grad += self.mesh.to_full_dof(g).reshape(self.n, 3)
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
        return self.mesh.to_full_dof(sp.csc_matrix(H))

    def max_step(self, x, dx):
        """The largest share in (0, 1] of the move dx (n, 3) from x along which no two parts of
        the surface come nearer than a tenth of their nearest distance now."""
        V0, V1 = self.vertices(x), self.vertices(x + dx)
        pairs = self.collisions(V0)
        floor = 0.0
        if len(pairs):   # ipctk's distances are squared
            floor = 0.1 * np.sqrt(pairs.compute_minimum_distance(self.mesh, V0))
        return float(self.ipctk.compute_collision_free_stepsize(self.mesh, V0, V1,
                                                                min_distance=floor))

    def nearest(self, x):
        """The smallest distance between two parts of the surface within dhat at x, m (inf
        where none is that near)."""
        V = self.vertices(x)
        pairs = self.collisions(V)
        return (float(np.sqrt(pairs.compute_minimum_distance(self.mesh, V))) if len(pairs)
                else np.inf)


def check_rest(contact, x):
    """ValueError where the surface at x (n, 3) intersects (or touches) itself."""
    if contact.ipctk.has_intersections(contact.mesh, contact.vertices(x)):
        raise ValueError("contact: self_contact: the body's surface intersects or touches "
                         "itself at rest; self-contact needs parts apart")
