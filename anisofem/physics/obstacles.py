"""Rigid obstacles a body can touch: a plane, a sphere, a box and a capsule, each convex and
given by its distance function; and a surface of triangles of any shape (Surface), whose
contact is taken pair by pair with ipctk (anisofem.physics.self_contact).

A sphere, a capsule and a box are a convex core (a point, a segment, a box) grown by a radius
(0 for the box): for a point x outside, with pi(x) its closest point of the core and
delta = |x - pi(x)|, the distance is d = delta - radius, its gradient the unit normal
n = (x - pi(x)) / delta and its Hessian (I - D pi - n n^T) / delta, D pi the core's projection
Jacobian (0 for a point, a a^T along a segment's axis a, the box's axes along which x lies
within its slab). A plane's distance is linear. Distances are m; inside, d <= 0.

first_touch bounds a straight move of points by the distance function's convexity: along
x + s dx, phi(s) = d - floor is convex, so Newton's iteration from s = 0 climbs to its first
root from below and never passes it: any iterate is a step that keeps every point at least
`floor` from the obstacle (a continuous collision test, conservative and exact in the limit).
"""
import copy

import numpy as np

from .._validate import as_float_array, as_scalar

#: Newton iterations of first_touch, and its stop once within this share of the floor.
TOUCH_ITERATIONS = 60
TOUCH_TOLERANCE = 1e-3


class Obstacle:
    """A convex rigid obstacle: name (for messages), friction (its own coefficient, or None:
    the Contact's)."""
    kind = "obstacle"

    def __init__(self, name, friction):
        self.name = str(name) if name is not None else self.kind
        self.friction = None if friction is None else as_scalar(friction, f"{self.kind} "
                                                                           "friction")
        if self.friction is not None and self.friction < 0:
            raise ValueError(f"{self.name}: friction must be >= 0, got {self.friction:g}")

    def __repr__(self):
        return f"{type(self).__name__}(name={self.name!r})"

    #: the attributes that say where it is (moved by `moved`); the first is its position
    placed = ()
    #: the attributes that give its shape, in its constructor's order (scene files, model files)
    parameters = ()
    #: (3,) m, how far it has moved since its step began: friction's anchor follows it
    shift = np.zeros(3)

    @property
    def position(self):
        """(3,) where it is: a plane's point, a sphere's or box's center, a capsule's end a."""
        return getattr(self, self.placed[0])

    def moved(self, delta):
        """A copy translated by delta (3,), m."""
        out = copy.copy(self)
        for key in self.placed:
            setattr(out, key, getattr(self, key) + np.asarray(delta, dtype=float))
        return out

    def distance(self, x):
        """(d (k,), normal (k, 3)) of points x (k, 3), m."""
        d, n, _ = self.geometry(x, curvature=False)
        return d, n

    def geometry(self, x, curvature=True):
        """(d (k,), normal (k, 3), Hessian of d (k, 3, 3) or None) at points x (k, 3)."""
        raise NotImplementedError

    def first_touch(self, x, dx, floor):
        """(k,) the largest s in [0, 1] for each point x (k, 3) moving by s dx (k, 3) that keeps
        its distance above floor (k,) > 0 on the whole way (x starts above it)."""
        s = np.zeros(len(x))
        live = np.arange(len(x))
        for _ in range(TOUCH_ITERATIONS):
            if not live.size:
                break
            d, n = self.distance(x[live] + s[live, None] * dx[live])
            phi = d - floor[live]
            slope = np.einsum("ij,ij->i", n, dx[live])
            clear = slope >= 0.0                     # convex: never closer from here on
            target = np.where(clear, 1.0, s[live] - phi / np.where(clear, -1.0, slope))
            s[live] = np.minimum(target, 1.0)
            touching = phi <= TOUCH_TOLERANCE * floor[live]
            live = live[~(clear | (target >= 1.0) | touching)]
        return s


class Plane(Obstacle):
    """The half-space on the side of `normal` of the plane through `point` (3,), m: the
    ground, a wall, a slope."""
    kind = "plane"
    placed = ("point",)
    parameters = ("point", "normal")

    def __init__(self, point=(0.0, 0.0, 0.0), normal=(0.0, 0.0, 1.0), *, name=None,
                 friction=None):
        super().__init__(name, friction)
        self.point = as_float_array(point, f"{self.name} point", shape=(3,))
        normal = as_float_array(normal, f"{self.name} normal", shape=(3,))
        size = float(np.linalg.norm(normal))
        if not size > 0:
            raise ValueError(f"{self.name}: normal must be nonzero")
        self.normal = normal / size

    def geometry(self, x, curvature=True):
        d = (x - self.point) @ self.normal
        n = np.broadcast_to(self.normal, x.shape)
        return d, n, (np.zeros((len(x), 3, 3)) if curvature else None)


class _Grown(Obstacle):
    """A convex core grown by a radius: subclasses give project(x) -> (closest points (k, 3),
    D pi (k, 3, 3) or None, inside the core (k,) bool)."""

    def __init__(self, radius, name, friction):
        super().__init__(name, friction)
        self.radius = as_scalar(radius, f"{self.name} radius")
        if self.radius < 0 or (self.radius == 0 and self.kind != "box"):
            raise ValueError(f"{self.name}: radius must be > 0, got {self.radius:g}")

    def geometry(self, x, curvature=True):
        c, jacobian, inside = self.project(x, curvature)
        r = x - c
        delta = np.sqrt(np.einsum("ij,ij->i", r, r))
        safe = np.where(delta > 0, delta, 1.0)
        n = r / safe[:, None]
        d = delta - self.radius
        if inside.any():
            d[inside], n[inside] = self.inside(x[inside])
        if not curvature:
            return d, n, None
        H = (np.eye(3) - jacobian - n[:, :, None] * n[:, None, :]) / safe[:, None, None]
        H[inside | (delta == 0)] = 0.0
        return d, n, H

    def inside(self, x):
        """(d <= 0, normal) of points inside the core (only the box has an inside)."""
        raise NotImplementedError


class Sphere(_Grown):
    """A ball of `radius` m about `center` (3,)."""
    kind = "sphere"
    placed = ("center",)
    parameters = ("center", "radius")

    def __init__(self, center, radius, *, name=None, friction=None):
        super().__init__(radius, name, friction)
        self.center = as_float_array(center, f"{self.name} center", shape=(3,))

    def project(self, x, curvature):
        k = len(x)
        return (np.broadcast_to(self.center, x.shape),
                np.zeros((k, 3, 3)) if curvature else None, np.zeros(k, bool))


class Capsule(_Grown):
    """The points within `radius` m of the segment from a (3,) to b (3,): a finger, a rod, a
    gripper's jaw."""
    kind = "capsule"
    placed = ("a", "b")
    parameters = ("a", "b", "radius")

    def __init__(self, a, b, radius, *, name=None, friction=None):
        super().__init__(radius, name, friction)
        self.a = as_float_array(a, f"{self.name} a", shape=(3,))
        self.b = as_float_array(b, f"{self.name} b", shape=(3,))
        self.axis = self.b - self.a
        self.length = float(np.linalg.norm(self.axis))
        if not self.length > 0:
            raise ValueError(f"{self.name}: a and b must differ")
        self.axis = self.axis / self.length

    def project(self, x, curvature):
        t = (x - self.a) @ self.axis
        within = (t > 0) & (t < self.length)
        c = self.a + np.clip(t, 0.0, self.length)[:, None] * self.axis
        jacobian = None
        if curvature:
            jacobian = np.zeros((len(x), 3, 3))
            jacobian[within] = np.outer(self.axis, self.axis)
        return c, jacobian, np.zeros(len(x), bool)


class Box(_Grown):
    """A box of half extents `half` (3,) m about `center` (3,), its axes the columns of
    `rotation` (3, 3; default the world's)."""
    kind = "box"
    placed = ("center",)
    parameters = ("center", "half", "rotation")

    def __init__(self, center, half, rotation=None, *, name=None, friction=None):
        super().__init__(0.0, name, friction)
        self.center = as_float_array(center, f"{self.name} center", shape=(3,))
        self.half = as_float_array(half, f"{self.name} half", shape=(3,))
        if not (self.half > 0).all():
            raise ValueError(f"{self.name}: half extents must be > 0, got {self.half}")
        R = np.eye(3) if rotation is None else as_float_array(rotation, f"{self.name} "
                                                                        "rotation", (3, 3))
        if not np.allclose(R.T @ R, np.eye(3), atol=1e-9) or np.linalg.det(R) < 0:
            raise ValueError(f"{self.name}: rotation must be a rotation matrix")
        self.rotation = R

    def project(self, x, curvature):
        local = (x - self.center) @ self.rotation
        within = np.abs(local) < self.half
        c = self.center + np.clip(local, -self.half, self.half) @ self.rotation.T
        jacobian = None
        if curvature:
            jacobian = np.einsum("ia,ka,ja->kij", self.rotation, within.astype(float),
                                 self.rotation)
        return c, jacobian, within.all(axis=1)

    def inside(self, x):
        local = (x - self.center) @ self.rotation
        depth = self.half - np.abs(local)
        axis = np.argmin(depth, axis=1)
        rows = np.arange(len(x))
        n = self.rotation[:, axis].T * np.sign(local[rows, axis])[:, None]
        return -depth[rows, axis], n


class Surface(Obstacle):
    """A rigid surface of triangles: vertices (v, 3) m, triangles (f, 3) indices into them,
    open or closed, of any shape (a bowl, a step, a scanned part; anisofem.read_surface reads
    one from a file). Its contact with the body is taken pair by pair as the surface's with
    itself is (anisofem.physics.self_contact, by ipctk: the body's vertices against its
    triangles, its vertices against the body's, edges against edges), so its edges and
    corners are exact; it needs ipctk, and the FEM's Newton method. It moves by translation
    (position: the mean of its vertices)."""
    kind = "surface"
    placed = ("vertices",)
    parameters = ("vertices", "triangles")

    def __init__(self, vertices, triangles, *, name=None, friction=None):
        super().__init__(name, friction)
        self.vertices = as_float_array(vertices, f"{self.name} vertices", shape=(None, 3))
        triangles = np.asarray(triangles)
        if triangles.ndim != 2 or triangles.shape[1] != 3 or not len(triangles) or \
                not np.issubdtype(triangles.dtype, np.integer):
            raise ValueError(f"{self.name}: triangles must be an (f, 3) integer array, f >= 1, "
                             f"got shape {triangles.shape} of {triangles.dtype}")
        if triangles.min() < 0 or triangles.max() >= len(self.vertices):
            raise ValueError(f"{self.name}: triangles index vertices 0 to "
                             f"{len(self.vertices) - 1}, got {triangles.min()} to "
                             f"{triangles.max()}")
        X = self.vertices
        area = np.linalg.norm(np.cross(X[triangles[:, 1]] - X[triangles[:, 0]],
                                       X[triangles[:, 2]] - X[triangles[:, 0]]), axis=1)
        if not (area > 0).all():
            raise ValueError(f"{self.name}: triangle {int(np.argmin(area))} has no area")
        # its own array: the collision mesh made of it is kept by the array's identity
        self.triangles = np.array(triangles, dtype=np.int32, order="C", copy=True)
        self.triangles.setflags(write=False)

    @property
    def position(self):
        """(3,) the mean of its vertices, m."""
        return self.vertices.mean(axis=0)


KINDS = {cls.kind: cls for cls in (Plane, Sphere, Box, Capsule, Surface)}
#: The obstacles given by a distance function, taken node by node (the others are Surfaces)
SHAPES = (Plane, Sphere, Box, Capsule)
