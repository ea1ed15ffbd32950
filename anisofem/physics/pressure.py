"""Pressure on the walls of a cavity: a conservative load, part of the potential.

A uniform pressure p on a surface S pushes each of its points into the material, with force
-p n dA (n the body's outward normal). Where S closes a cavity, that force is the gradient of

    Pi(x) = -p (V(x) - V(X)),

V the volume the cavity encloses, so the load enters the (incremental) potential with an exact
gradient and Hessian, and every method that minimizes the potential takes it. V is a surface
integral (the divergence theorem with a field F of divergence 1),

    V(x) = -sum over S's triangles of  int F(x(xi)) . (dx/dxi_1 x dx/dxi_2) dxi,

the triangles ordered outward from the body (into the cavity) and x(xi) interpolated by the
face's shape functions: 3 nodes on linear tets, 6 on quadratic ones. The integrand is a cubic
polynomial of the nodal positions of degree 1 (linear) or 4 (quadratic) in xi, so a one-point
or a six-point rule integrates it exactly.

A surface need not be closed: its rim (edges of one face only) may lie on vertices that are
held, or that slide in planes normal to an axis (symmetry planes, rollers). The surface that
closes the cavity there does not count when F . n vanishes on it: F = s (x - o) with s zero
along the axes whose rim planes take two offsets (the two ends of a tube) and o on the single
plane of the others. Fully held rim vertices close it with a fixed cap, whose share is
constant.
"""
import math

import numpy as np

from .._validate import as_index_array, as_scalar

#: Triangle rules on the reference triangle (0,0), (1,0), (0,1) (area 1/2): points (q, 2) and
#: weights (q,), by mesh order. Linear faces: the centroid (the integrand has degree 1).
#: Quadratic faces: the six-point rule exact to degree 4 (Dunavant 1985), all weights positive.
_A, _B = 0.445948490915965, 0.091576213509771
_WA, _WB = 0.223381589678011 / 2, 0.109951743655322 / 2
RULES = {1: (np.array([[1 / 3, 1 / 3]]), np.array([0.5])),
         2: (np.array([[_A, _A], [1 - 2 * _A, _A], [_A, 1 - 2 * _A],
                       [_B, _B], [1 - 2 * _B, _B], [_B, 1 - 2 * _B]]),
             np.array([_WA] * 3 + [_WB] * 3))}

#: A rim plane's offset is the same as another's within this share of the mesh's size.
PLANE_TOLERANCE = 1e-9


class Pressure:
    """A uniform pressure on a surface of the mesh, pushing into the material.

    Parameters
    ----------
    faces : (k, 3) vertex triples (corner vertices; any order), boundary faces of the mesh
        (TetMesh.faces_where selects them). Together they close a cavity, or their rim lies on
        held vertices or vertices sliding in planes normal to an axis (see the module).
    magnitude : p, Pa: positive inflates the cavity.
    name : None (a load), or a name that makes the pressure one of the scene's controls
        (anisofem.physics.controls): a controller sets it every step.
    """

    def __init__(self, faces, magnitude, name=None):
        self.faces = as_index_array(faces, "pressure faces", shape=(None, 3))
        if self.faces.shape[0] == 0:
            raise ValueError("pressure faces: no face given")
        self.magnitude = as_scalar(magnitude, "pressure magnitude")
        if name is not None and (not isinstance(name, str) or not name):
            raise ValueError(f"pressure name: expected a non-empty string, got {name!r}")
        self.name = name

    def __repr__(self):
        named = f"{self.name!r}, " if self.name else ""
        return f"Pressure({named}{self.faces.shape[0]} faces, {self.magnitude:g} Pa)"


class CavityLoad:
    """A Pressure bound to a mesh and its held vertices: the potential term -p (V - V0).

    Attributes: nodes (k, s) each face's nodes (3 corners, then the midside nodes of its edges
    (0,1), (1,2), (2,0) on quadratic tets), ordered outward from the body; owner (k,) the tet
    each face bounds and local (k, s) the face's nodes among that tet's; scale (3,) and origin
    (3,) the field F = scale (x - origin); magnitude p, Pa; name (a control's, or None);
    rest_volume V(X), m^3.
    """

    def __init__(self, mesh, pressure, fixed_mask):
        corners, self.owner = mesh.find_boundary_faces(pressure.faces, "pressure faces")
        if len(np.unique(np.sort(corners, axis=1), axis=0)) < len(corners):
            raise ValueError("pressure faces: a face is given twice")
        self.nodes = corners if mesh.order == 1 else np.concatenate(
            [corners, mesh.edge_nodes(corners[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2))
             .reshape(-1, 3)], axis=1)
        cells = mesh.cells[self.owner]
        self.local = np.argmax(cells[:, None, :] == self.nodes[:, :, None], axis=2)
        self.scale, self.origin = _closing_field(mesh, corners, fixed_mask)
        self.magnitude, self.name = pressure.magnitude, pressure.name
        points, self.weights = RULES[mesh.order]
        self.shapes, self.slopes = _triangle_shapes(mesh.order, points)
        self._positions = {}   # per Hessian layout: where each face block lands (add_hessian)
        self.rest_volume = self.volume(mesh.vertices)

    def scaled(self, share):
        """The same load at `share` of its pressure."""
        return self.at(share * self.magnitude)

    def at(self, magnitude):
        """The same cavity at pressure `magnitude`, Pa."""
        out = object.__new__(CavityLoad)
        out.__dict__.update(self.__dict__)
        out.magnitude = magnitude
        return out

    def _slots(self, x):
        """The face points a = s (x - o) and tangents b, c (k, q, 3) at the rule's points."""
        X = x[self.nodes]
        a = self.scale * (np.einsum("qa,kai->kqi", self.shapes, X) - self.origin)
        b = np.einsum("qa,kai->kqi", self.slopes[:, :, 0], X)
        c = np.einsum("qa,kai->kqi", self.slopes[:, :, 1], X)
        return a, b, c

    def reduced_slots(self, x0, basis):
        """The face points and tangents along a reduced basis: (w (K,), a0, b0, c0 (K, 3), A,
        B, C (K, 3, r)), K = faces times rule points, so that at x0 + basis q the slots of
        _slots are a0 + A q, b0 + B q, c0 + C q and V = -sum_K w a . (b x c)."""
        a0, b0, c0 = self._slots(x0)
        r = basis.shape[1]
        U = basis.reshape(-1, 3, r)[self.nodes]                 # (k, s, 3, r)
        A = self.scale[:, None] * np.einsum("qa,kair->kqir", self.shapes, U)
        B = np.einsum("qa,kair->kqir", self.slopes[:, :, 0], U)
        C = np.einsum("qa,kair->kqir", self.slopes[:, :, 1], U)
        k = a0.shape[0] * a0.shape[1]
        return (np.tile(self.weights, a0.shape[0]), a0.reshape(k, 3), b0.reshape(k, 3), c0.reshape(k, 3),
                A.reshape(k, 3, r), B.reshape(k, 3, r), C.reshape(k, 3, r))

    def volume(self, x):
        """The cavity's volume V(x), m^3 (up to the constant share of a held cap), positions x
        (n, 3)."""
        a, b, c = self._slots(x)
        return -float(np.einsum("q,kqi,kqi->", self.weights, a, np.cross(b, c)))

    def energy(self, x, grad=None):
        """-p (V(x) - V(X)), J; with grad (n, 3), the term's gradient -p dV/dx (N) is added
        into it, from the same evaluation."""
        a, b, c = self._slots(x)
        bc = np.cross(b, c)
        value = self.magnitude * (float(np.einsum("q,kqi,kqi->", self.weights, a, bc))
                                  + self.rest_volume)
        if grad is not None:
            # d(a . b x c): s (b x c) through a, (c x a) through b, (a x b) through c
            w, N, dN = self.weights, self.shapes, self.slopes
            g = (np.einsum("q,qn,kqi->kni", w, N, self.scale * bc)
                 + np.einsum("q,qn,kqi->kni", w, dN[:, :, 0], np.cross(c, a))
                 + np.einsum("q,qn,kqi->kni", w, dN[:, :, 1], np.cross(a, b)))
            np.add.at(grad, self.nodes.ravel(), (self.magnitude * g).reshape(-1, 3))
        return value

    def face_hessians(self, x):
        """(k, 3s, 3s) each face's block of the term's Hessian, -p d2V/dx2, N/m, over its nodes
        (3 a + i)."""
        a, b, c = self._slots(x)
        w, N, dN = self.weights, self.shapes, self.slopes
        S = np.diag(self.scale)
        ab = -np.einsum("ij,kqjl->kqil", S, _skew(c))   # d2/da db of a . (b x c)
        ac = np.einsum("ij,kqjl->kqil", S, _skew(b))    # d2/da dc
        bc = -_skew(a)                                  # d2/db dc
        d1, d2 = dN[:, :, 0], dN[:, :, 1]
        H = (np.einsum("q,qm,qn,kqij->kminj", w, N, d1, ab)
             + np.einsum("q,qm,qn,kqij->kminj", w, N, d2, ac)
             + np.einsum("q,qm,qn,kqij->kminj", w, d1, d2, bc))
        H = H + H.transpose(0, 3, 4, 1, 2)
        s = self.nodes.shape[1]
        return self.magnitude * H.reshape(-1, 3 * s, 3 * s)

    def add_hessian(self, x, layout, data):
        """Add the term's Hessian into data, the entries of `layout` (an anisofem.physics.assembly
        layout over the mesh's tets: each face's block lands through its owner tet's)."""
        if id(layout) not in self._positions:
            width = math.isqrt(layout.map.shape[1])  # 3 times the nodes of a tet
            dofs = (3 * self.local[:, :, None] + np.arange(3)).reshape(len(self.local), -1)
            where = layout.map[self.owner[:, None, None],
                               dofs[:, :, None] * width + dofs[:, None, :]]
            self._positions[id(layout)] = (layout, where >= 0, where[where >= 0])
        _, keep, where = self._positions[id(layout)]
        np.add.at(data, where, self.face_hessians(x)[keep])


def _skew(v):
    """(..., 3, 3) the matrices [v]_x with [v]_x u = v x u, of v (..., 3)."""
    out = np.zeros(v.shape + (3,))
    out[..., 0, 1], out[..., 0, 2] = -v[..., 2], v[..., 1]
    out[..., 1, 0], out[..., 1, 2] = v[..., 2], -v[..., 0]
    out[..., 2, 0], out[..., 2, 1] = -v[..., 1], v[..., 0]
    return out


def _triangle_shapes(order, points):
    """Shape values (q, s) and derivatives (q, s, 2) of the 3- or 6-node triangle at reference
    points (q, 2): corners, then the midsides of edges (0,1), (1,2), (2,0)."""
    xi, eta = points[:, 0], points[:, 1]
    L = np.stack([1 - xi - eta, xi, eta], axis=1)
    dL = np.array([[-1.0, -1.0], [1.0, 0.0], [0.0, 1.0]])
    if order == 1:
        return L, np.broadcast_to(dL, (len(points), 3, 2)).copy()
    i, j = np.array([0, 1, 2]), np.array([1, 2, 0])
    N = np.concatenate([L * (2 * L - 1), 4 * L[:, i] * L[:, j]], axis=1)
    dN = np.concatenate([(4 * L - 1)[:, :, None] * dL[None],
                         4 * (L[:, i, None] * dL[None, j] + L[:, j, None] * dL[None, i])],
                        axis=1)
    return N, dN


def _closing_field(mesh, faces, fixed_mask):
    """(scale (3,), origin (3,)) of the field F = scale (x - origin) whose flux through the
    surface that closes `faces` (k, 3, outward) does not change as the body moves; ValueError
    where the rim has a free vertex or no axis is left (see the module)."""
    pairs = faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    key = np.sort(pairs, axis=1)
    unique, counts = np.unique(key, axis=0, return_counts=True)
    if (counts > 2).any():
        bad = unique[counts > 2][0].tolist()
        raise ValueError(f"pressure faces: the edge {bad} joins more than two faces of the "
                         f"surface")
    rim = np.unique(unique[counts == 1])
    X = mesh.vertices
    origin = X[faces].reshape(-1, 3).mean(axis=0)
    if rim.size == 0:
        return np.full(3, 1.0 / 3.0), origin
    held = fixed_mask[rim]
    free = rim[~held.any(axis=1)]
    if free.size:
        raise ValueError(f"pressure faces: the surface is not closed, and its rim vertex "
                         f"{int(free[0])} is free (a pressure surface must close a cavity, or "
                         f"end on held vertices or on vertices sliding in a plane)")
    sliding = ~held.all(axis=1)
    scale = np.ones(3)
    for k in range(3):
        offsets = X[rim[sliding & held[:, k]], k]
        if offsets.size == 0:
            continue
        if np.ptp(offsets) > PLANE_TOLERANCE * mesh.size:
            scale[k] = 0.0
        else:
            origin[k] = offsets.mean()
    if not scale.any():
        raise ValueError("pressure faces: the rim slides in planes at two offsets along every "
                         "axis; no closing surface is fixed")
    return scale / scale.sum(), origin
