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
import math
import weakref

import numpy as np
import scipy.sparse as sp
from numba import njit

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
    surfaces then where they were at the step's start (less their shift). near: a NearPairs
    whose pairs every collision test takes (a reduced model's; None: ipctk's broad phase)."""

    def __init__(self, mesh, dhat, kappa, x_lag=None, mu=0.0, eps=None, surfaces=(),
                 itself=True, near=None):
        ipctk = self.ipctk = ipctk_module()
        self.surfaces = tuple(surfaces)
        self.mesh, owner, _ = collision_mesh(mesh, self.surfaces, itself)
        self.dhat = dhat
        self.near = near
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
        if self.near is not None:
            pairs.build(self.near.candidates(V), self.mesh, V, self.dhat)
        else:
            pairs.build(self.mesh, V, self.dhat)
        return pairs

    def energy(self, x, grad=None):
        """The barrier's and friction's energy at x (n, 3), J (inf where two parts of the
        surface meet); adds the gradient to grad (n, 3) when given."""
        total, g = self.surface_energy(self.vertices(x))
        if grad is not None and np.isfinite(total):
            grad += self.mesh.to_full_dof(g).reshape(-1, 3)[:self.n]
        return total

    def surface_energy(self, V, pairs=None):
        """(energy J, gradient (3v,) N over the collision mesh's unknowns) at its vertices V
        (v, 3) (pairs: their collisions there, found if None); inf (and no gradient) where
        two parts of the surface meet."""
        pairs = self.collisions(V) if pairs is None else pairs
        if len(pairs) and pairs.compute_minimum_distance(self.mesh, V) <= 0.0:
            return np.inf, None
        total = self.barrier(pairs, self.mesh, V) if len(pairs) else 0.0
        g = (self.barrier.gradient(pairs, self.mesh, V) if len(pairs)
             else np.zeros(V.size))
        if self.friction is not None:
            tangential, potential, lag = self.friction
            total += potential(tangential, self.mesh, V - lag)
            g = g + potential.gradient(tangential, self.mesh, V - lag)
        return float(total), g

    def hessian_parts(self, V, pairs, how=None):
        """The Hessian's parts at the collision mesh's vertices V (v, 3), pairs their
        collisions there: [the barrier's, the friction's] (scipy CSC (3v, 3v), N/m; how:
        ipctk's PSD projection, default none)."""
        how = self.ipctk.PSDProjectionMethod.NONE if how is None else how
        parts = [self.barrier.hessian(pairs, self.mesh, V, how)] if len(pairs) else []
        if self.friction is not None:
            tangential, potential, lag = self.friction
            parts.append(potential.hessian(tangential, self.mesh, V - lag, how))
        return parts

    def hessian(self, x, project=False):
        """(3n, 3n) scipy sparse, the barrier's and friction's Hessian at x (n, 3); project:
        each pair's clamped to positive semi-definite."""
        H = self.mesh.to_full_dof(self.surface_hessian(self.vertices(x), project))
        return H if not self.surfaces else H.tocsr()[:3 * self.n].tocsc()[:, :3 * self.n]

    def surface_hessian(self, V, project=False, pairs=None):
        """(3v, 3v) scipy CSC, the Hessian over the collision mesh's unknowns at V (v, 3)
        (pairs: their collisions there, found if None)."""
        how = (self.ipctk.PSDProjectionMethod.CLAMP if project
               else self.ipctk.PSDProjectionMethod.NONE)
        pairs = self.collisions(V) if pairs is None else pairs
        return sp.csc_matrix(sum(self.hessian_parts(V, pairs, how),
                                 sp.csc_matrix((V.size, V.size))))

    def max_step(self, x, dx):
        """The largest share in (0, 1] of the move dx (n, 3) from x along which no two parts of
        the surface come nearer than a tenth of their nearest distance now (with NearPairs: as
        far as the pairs found for it hold)."""
        return self.surface_max_step(self.vertices(x), self.vertices(x + dx))

    def surface_max_step(self, V0, V1):
        """max_step for the collision mesh's vertices moving from V0 to V1 (v, 3)."""
        if self.near is None:
            return free_share(self.mesh, V0, V1, self.dhat)
        candidates, reach = self.near.along(V0, V1)
        if reach < 1.0:
            V1 = V0 + reach * (V1 - V0)
        return reach * free_share(self.mesh, V0, V1, self.dhat, candidates,
                                  self.near.dhat + self.near.margin)

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


def free_share(cm, V0, V1, reach, candidates=None, apart=None):
    """The largest share in (0, 1] of the move of the collision mesh cm's vertices from V0 to
    V1 along which no two parts within `reach` m of each other at V0 come nearer than a tenth
    of their nearest distance there (ipctk's additive CCD, Li et al. 2021: its tight-inclusion
    default took 11 s for one step of the beam over a surface block, whose faces are much
    larger than the beam's). candidates: ipctk's Candidates holding every pair that can meet
    along the move (NearPairs), the others at least `apart` m apart at V0 (>= reach), or None
    to find them. A move that changes no distance by more than 0.9 of the nearest (twice the
    largest vertex move less the common one) is free without a CCD."""
    ipctk = ipctk_module()
    pairs = ipctk.NormalCollisions()
    if candidates is None:
        pairs.build(cm, V0, reach)
    else:
        pairs.build(candidates, cm, V0, apart)
    nearest = float(np.sqrt(pairs.compute_minimum_distance(cm, V0))) if len(pairs) else np.inf
    if candidates is not None and 2.0 * _shape_change(V1 - V0) <= 0.9 * min(nearest, apart):
        return 1.0
    floor = 0.1 * nearest if nearest < reach else 0.0   # ipctk's distances are squared
    ccd = ipctk.AdditiveCCD()
    if candidates is None:
        return float(ipctk.compute_collision_free_stepsize(cm, V0, V1, min_distance=floor,
                                                           narrow_phase_ccd=ccd))
    return float(candidates.compute_collision_free_stepsize(cm, V0, V1, min_distance=floor,
                                                            narrow_phase_ccd=ccd))


class NearPairs:
    """The pairs of the collision mesh cm that can come within dhat while its vertices stay
    near where they were found: the point-triangle and edge-edge pairs within dhat + margin
    (m) at V_c, which hold every pair that can come within dhat for as long as each vertex's
    move since V_c, less their common translation, stays under margin / 2 (then no distance
    changed by more than margin). Found again where a move leaves that. For a solve whose
    surface's shape changes little between its evaluations (a reduced model's): ipctk's broad
    phase keeps the surface's neighbouring features (thousands of pairs, as costly to test as
    the few that matter); these are the few."""

    def __init__(self, cm, dhat, margin):
        self.cm, self.dhat, self.margin = cm, dhat, margin
        self.adjacency = _adjacency(cm)
        self.at, self.found, self.builds = None, None, 0

    def holds(self, V):
        """Whether the pairs found hold every pair that can come within dhat at V (v, 3)."""
        return self.at is not None and _shape_change(V - self.at) <= 0.5 * self.margin

    def candidates(self, V):
        """ipctk's Candidates holding every pair that can come within dhat at V."""
        if not self.holds(V):
            self._find(V)
        return self.found

    def along(self, V0, V1):
        """(ipctk's Candidates, share): the pairs that can come within dhat anywhere along the
        first `share` in (0, 1] of the straight move from V0 to V1 (v, 3). Found again at V0
        where the move leaves them; share < 1 where the move changes the surface's shape by
        more than margin / 2 (each vertex's move less the common one grows linearly along
        it)."""
        if self.holds(V0) and self.holds(V1):
            return self.found, 1.0
        self._find(V0)
        far = _shape_change(V1 - V0)
        return self.found, 1.0 if far <= 0.5 * self.margin else 0.5 * self.margin / far

    def _find(self, V):
        self.found = near_candidates(self.cm, V, self.dhat + self.margin, self.adjacency)
        self.at, self.builds = V.copy(), self.builds + 1


@njit(cache=True)
def _shape_change(move):
    """The largest of the vertices' moves (v, 3), m, less their common translation (the
    middle of their range)."""
    lo, hi = move[0].copy(), move[0].copy()
    for i in range(move.shape[0]):
        for k in range(3):
            lo[k] = min(lo[k], move[i, k])
            hi[k] = max(hi[k], move[i, k])
    mid = 0.5 * (lo + hi)
    far = 0.0
    for i in range(move.shape[0]):
        d = 0.0
        for k in range(3):
            d += (move[i, k] - mid[k]) ** 2
        far = max(far, d)
    return math.sqrt(far)


def near_candidates(cm, V, reach, adjacency):
    """ipctk's Candidates of the point-triangle and edge-edge pairs of cm (not sharing a
    vertex) within `reach` m at V: ipctk's broad and narrow phases find the pairs of closest
    features within reach (vertex-vertex, edge-vertex, edge-edge, face-vertex), and each gives
    back every triangle-point and edge-edge pair whose closest features it can be."""
    ipctk = ipctk_module()
    wide = ipctk.Candidates()
    wide.build(cm, np.asfortranarray(V), 0.5 * reach)   # boxes apart by more: pairs too
    near = ipctk.NormalCollisions()
    near.build(wide, cm, np.asfortranarray(V), reach)
    faces_of, edges_of, edge_faces = adjacency
    fv, ee = set(), set()
    for c in near.fv_collisions:
        fv.add((c.face_id, c.vertex_id))
    for c in near.ee_collisions:
        ee.add((c.edge0_id, c.edge1_id))
    for c in near.ev_collisions:
        fv.update((f, c.vertex_id) for f in edge_faces[c.edge_id])
        ee.update((c.edge_id, e) for e in edges_of[c.vertex_id])
    for c in near.vv_collisions:
        a, b = c.vertex0_id, c.vertex1_id
        fv.update((f, b) for f in faces_of[a])
        fv.update((f, a) for f in faces_of[b])
        ee.update((e, e1) for e in edges_of[a] for e1 in edges_of[b])
    F, E = cm.faces, cm.edges
    found = ipctk.Candidates()
    found.fv_candidates = [ipctk.FaceVertexCandidate(int(f), int(v)) for f, v in fv
                           if v not in F[f]]
    found.ee_candidates = [ipctk.EdgeEdgeCandidate(int(a), int(b)) for a, b in
                           {tuple(sorted(p)) for p in ee} if not set(E[a]) & set(E[b])]
    return found


def _adjacency(cm):
    """(the faces of each vertex, the edges of each vertex, the faces of each edge) of the
    collision mesh cm, lists of lists."""
    faces_of = [[] for _ in range(cm.num_vertices)]
    edges_of = [[] for _ in range(cm.num_vertices)]
    edge_faces = [[] for _ in range(cm.num_edges)]
    for f, (a, b, c) in enumerate(cm.faces):
        for v in (a, b, c):
            faces_of[v].append(f)
    for e, (a, b) in enumerate(cm.edges):
        edges_of[a].append(e)
        edges_of[b].append(e)
    for f, row in enumerate(cm.faces_to_edges):
        for e in row:
            edge_faces[e].append(f)
    return faces_of, edges_of, edge_faces


def surface_share(mesh, surface, x, delta):
    """The largest share in (0, 1] of a move delta (3,) m of the Surface `surface`, the body
    of `mesh` held at x (n, 3), along which it comes no nearer to the body than a tenth of
    their nearest distance now (only what is nearer than the move can be met)."""
    cm = collision_mesh(mesh, (surface,), itself=False)[0]
    V0, V1 = (cm.vertices(np.asfortranarray(np.vstack([x, surface.vertices + d])))
              for d in (0.0, delta))
    return free_share(cm, V0, V1, float(np.linalg.norm(delta)))


def collision_mesh(mesh, surfaces=(), itself=True):
    """(ipctk's CollisionMesh of the mesh's boundary triangles and the surfaces' (their
    vertices after the mesh's, in order), whose pairs are the body's with itself (itself) and
    with each surface, never a surface's with itself or another; (v,) int the owner of each of
    its vertices, 0 the body, k the k-th surface; (v,) int the index of each among the mesh's
    vertices then the surfaces'). Built once per mesh and set of surfaces (every step reads
    it)."""
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
        ids = np.repeat(np.arange(len(rest), dtype=float)[:, None], 3, axis=1)
        # its full ids (ipctk maps them by a sparse product: 7.9999999 for 8)
        full = np.rint(cm.vertices(np.asfortranarray(ids))[:, 0]).astype(int)
        ends = np.cumsum([mesh.n_vertices] + [len(o.vertices) for o in surfaces])
        owner = np.searchsorted(ends, full, side="right")
        if surfaces:   # ipctk keeps the full mesh's order: the body's vertices come first
            fixed = owner > 0
            if fixed[:int((~fixed).sum())].any():
                raise RuntimeError("ipctk reordered the collision mesh's vertices; its filter "
                                   "of the surfaces' pairs needs the body's first")
            cm.can_collide = (ipctk.make_static_obstacle_filter(int((~fixed).sum())) if itself
                              else ipctk.make_vertex_patches_filter(fixed.astype(np.int32)))
        built[key] = ([o.triangles for o in surfaces], cm, owner, full)
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
