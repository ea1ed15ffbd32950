"""Cables (tendons): a polyline of material points routed through the body, pulled with a
tension T >= 0, a control.

The points move with the body: each is a vertex, or a rest point inside a tet, carried by
the tet's shape functions (anisofem.physics.points). The cable slides without friction
through them (the guides of a tendon-driven finger), so a tension T does the work -T dL when
the cable's length L changes, and the cable enters the potential as

    Pi(x) = T L(x) = T sum_j |p_{j+1}(x) - p_j(x)|,

with the exact gradient T sum_j t_j . d(p_{j+1} - p_j)/dx (t_j the unit segment) and the
Hessian T sum_j D_j^T (I - t_j t_j^T) / l_j D_j, positive semi-definite. A cable anchored at a
held point and at the tip pulls the tip toward the anchor along the cable; a straight cable at
an offset e from a beam's neutral axis bends it by an end moment T e.
"""
import numpy as np

from .controls import control_number
from .points import node_weights


class Cable:
    """A cable through `points`, pulled with `tension` N, a control named `name`.

    points : a sequence of at least two material points, each a vertex index, or a rest point
        (x, y, z), m, inside the body.
    tension : T >= 0, N (default 0: slack).
    """

    def __init__(self, points, tension=0.0, name="cable"):
        if not isinstance(name, str) or not name:
            raise ValueError(f"cable name: expected a non-empty string, got {name!r}")
        self.name = name
        self.points = list(points)
        if len(self.points) < 2:
            raise ValueError(f"cable {name!r}: points: a cable runs through at least two "
                             f"points, got {len(self.points)}")
        self.tension = tension_value(tension, name)

    def __repr__(self):
        return f"Cable({self.name!r}, {len(self.points)} points, {self.tension:g} N)"


def tension_value(value, name):
    """value as a tension >= 0, N; ValueError naming the cable otherwise."""
    t = control_number(value, name)
    if t < 0:
        raise ValueError(f"control {name!r}: a cable's tension must be >= 0 N (a cable pulls, "
                         f"it cannot push), got {t:g}")
    return t


class CableLoad:
    """A Cable bound to a mesh: nodes (p, k) and weights (p, k) of each point (a vertex: its
    own index and weight 1, padded), groups (p - 1, 2k) the nodes of each segment, tension
    T N, name; rest_length, m."""

    def __init__(self, mesh, cable):
        k = mesh.cells.shape[1]
        nodes, weights = np.zeros((len(cable.points), k), np.int64), np.zeros(
            (len(cable.points), k))
        for i, p in enumerate(cable.points):
            if _is_vertex(p):
                if not 0 <= int(p) < mesh.n_vertices:
                    raise ValueError(f"cable {cable.name!r}: point {i} is vertex {p}, not one "
                                     f"of the mesh's {mesh.n_vertices}")
                nodes[i], weights[i, 0] = int(p), 1.0
                continue
            rest = _point(p, cable.name, i)
            try:
                found = node_weights(mesh, rest[None])
            except ValueError:
                raise ValueError(f"cable {cable.name!r}: point {i} at {rest.tolist()} m lies "
                                 f"outside the mesh (in no tet)") from None
            nodes[i], weights[i] = found[0][0], found[1][0]
        self.nodes, self.weights = nodes, weights
        self.groups = np.concatenate([nodes[:-1], nodes[1:]], axis=1)
        self.name, self.tension = cable.name, cable.tension
        self.rest_length = self.length(mesh.vertices)
        if not self.rest_length > 0:
            raise ValueError(f"cable {cable.name!r}: its points all lie at one place")
        self._positions = {}

    def at(self, tension):
        """The same cable at `tension`, N."""
        out = object.__new__(CableLoad)
        out.__dict__.update(self.__dict__)
        out.tension = tension_value(tension, self.name)
        return out

    def points_at(self, x):
        """(p, 3) the cable's points at positions x (n, 3)."""
        return np.einsum("pk,pki->pi", self.weights, x[self.nodes])

    def length(self, x):
        """The cable's length L(x), m."""
        return float(np.linalg.norm(np.diff(self.points_at(x), axis=0), axis=1).sum())

    def _segments(self, x):
        """(unit segments t (s, 3), lengths l (s,)); a segment of zero length has t = 0."""
        d = np.diff(self.points_at(x), axis=0)
        l = np.linalg.norm(d, axis=1)
        return d / np.where(l > 0, l, 1.0)[:, None], l

    def energy(self, x, grad=None):
        """T L(x), J; with grad (n, 3), the term's gradient (N) is added into it."""
        t, l = self._segments(x)
        if grad is not None and self.tension:
            force = self.tension * t                               # on p_{j+1}; minus on p_j
            w = self.weights
            np.add.at(grad, self.nodes[1:].ravel(), (w[1:, :, None] * force[:, None]).reshape(
                -1, 3))
            np.add.at(grad, self.nodes[:-1].ravel(), -(w[:-1, :, None] * force[:, None])
                      .reshape(-1, 3))
        return self.tension * float(l.sum())

    def segment_hessians(self, x):
        """(s, 6k, 6k) each segment's block of T D^T (I - t t^T) / l D over its groups' nodes
        (3 a + i), N/m; zero for a segment of zero length."""
        t, l = self._segments(x)
        P = (np.eye(3) - t[:, :, None] * t[:, None, :]) / np.where(l > 0, l, np.inf)[:, None,
                                                                                         None]
        c = np.concatenate([-self.weights[:-1], self.weights[1:]], axis=1)   # (s, 2k)
        H = self.tension * np.einsum("sa,sb,sij->saibj", c, c, P)
        s, w = c.shape
        return H.reshape(s, 3 * w, 3 * w)

    def add_hessian(self, x, layout, data):
        """Add the term's Hessian into data, the entries of `layout` (which holds the cable's
        groups among its couplings)."""
        if not self.tension:
            return
        if id(layout) not in self._positions:
            where = layout.positions(self.groups)
            self._positions[id(layout)] = (layout, where >= 0, where[where >= 0])
        _, keep, where = self._positions[id(layout)]
        H = self.segment_hessians(x)
        np.add.at(data, where, H.reshape(H.shape[0], -1)[keep])


def _is_vertex(point):
    return isinstance(point, (int, np.integer)) and not isinstance(point, bool)


def _point(point, name, i):
    """A routing point as a (3,) float array; ValueError naming it otherwise."""
    try:
        p = np.array(point, dtype=float)
    except (TypeError, ValueError):
        p = None
    if p is None or p.shape != (3,) or not np.isfinite(p).all():
        raise ValueError(f"cable {name!r}: point {i}: expected a vertex index or a finite rest "
                         f"point (x, y, z), got {point!r}")
    return p

