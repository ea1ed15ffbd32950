"""The loads a reduced model must handle, declared with its scene, and the load cases drawn
from a declaration: the static equilibria its basis is fitted to, and unseen cases that
validate it.

    loads = Loads(drags=(Drag(tip, magnitude=0.8),), cone=20.0)

A Drag is a force of up to `magnitude` N on a set of vertices, spread over them in proportion
to their mass (a hand or a hook grabbing a region, a controller's actuator), in any direction
or in given ones. `cone` lets the scene's gravity turn by up to that many degrees (a body
carried around). `controls` gives the range of each of the scene's controls a model must
follow: {"inflate": (0.0, 20e3)}. A Carry moves the held vertices rigidly (the framed model's
base): a turn, a move, and the shortest time either takes. Without a declaration
(default_loads) a model handles the scene's own loads, a drag of half the body's weight at
each free end, and the range each control on a load curve takes.
"""
import math
from dataclasses import dataclass, field

import numpy as np
from scipy.sparse.csgraph import connected_components

from .domains import edge_graph, held_distance

#: Directions a drag declared in any direction is built from: the 6 axes and the 8 diagonals.
ANY_DIRECTION = tuple(tuple(np.array(d, float) / np.linalg.norm(d)) for d in
                      [(1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0), (0, 0, 1), (0, 0, -1)]
                      + [(a, b, c) for a in (1, -1) for b in (1, -1) for c in (1, -1)])

#: Shares of a drag's magnitude the build solves for, in order, each from the last equilibrium.
SHARES = (0.25, 0.5, 1.0)

#: Gravity directions the build takes on a cone: this many around its rim, at the full angle
#: and at half of it.
CONE_DIRECTIONS = 4

#: A free end: the vertices at least this share of the farthest distance from the held ones,
#: split into connected pieces (the tip of a cantilever, each arm's end of a T).
END_SHARE = 0.9

#: With more than one declared control, the build also solves for all of them at once at
#: this many points per control, drawn uniformly in their ranges from COMBINED_SEED (the
#: validation draws from seed 0).
COMBINED = 2
COMBINED_SEED = 1

#: The unseen cases draw a drag's magnitude between this share of the declared one and all of it.
SMALLEST_UNSEEN = 0.3

#: Standard gravity, m/s^2: the default drag's weight in a scene without gravity.
STANDARD_GRAVITY = 9.81

#: The default drag's magnitude, over the body's weight: a sudden drag of the whole weight at
#: the free end of the 0.2 m trade cantilever folds it back on itself, and the full FEM turns
#: dozens of its elements inside out.
DRAG_SHARE = 0.5


@dataclass(frozen=True)
class Drag:
    """A force of up to `magnitude` N on `vertices` (indices), spread in proportion to their
    masses, along any direction (directions None) or along one of `directions` (unit 3-vectors,
    normalized here)."""
    vertices: tuple
    magnitude: float
    directions: tuple = None

    def __post_init__(self):
        vertices = np.asarray(self.vertices)
        if vertices.ndim != 1 or vertices.size == 0 or not np.issubdtype(vertices.dtype,
                                                                            np.integer):
            raise ValueError(f"vertices: expected a non-empty list of vertex indices, got "
                             f"{self.vertices!r}")
        object.__setattr__(self, "vertices", tuple(int(i) for i in vertices))
        if not _real(self.magnitude) or not self.magnitude > 0:
            raise ValueError(f"magnitude: expected a finite force > 0 N, got "
                             f"{self.magnitude!r}")
        object.__setattr__(self, "magnitude", float(self.magnitude))
        if self.directions is not None:
            object.__setattr__(self, "directions", _unit_rows(self.directions))

    def force(self, scene, direction):
        """The nodal force (n, 3), N, of this drag at its full magnitude along `direction`."""
        idx = np.asarray(self.vertices)
        m = scene.masses[idx]
        f = np.zeros((scene.mesh.n_vertices, 3))
        f[idx] = np.outer(m / m.sum(), self.magnitude * np.asarray(direction, float))
        return f

    @property
    def candidate_directions(self):
        """The directions the build solves along: the declared ones, or ANY_DIRECTION."""
        return ANY_DIRECTION if self.directions is None else self.directions


@dataclass(frozen=True)
class Carry:
    """The held vertices carried by a rigid motion (a hand, a character): turned by up to
    `turn` degrees about any axis through their centroid and moved up to `move` m, each motion
    taking at least `seconds` s (FramedModel.step's base; the linear model holds its held
    vertices in place)."""
    turn: float = 0.0
    move: float = 0.0
    seconds: float = 0.5

    def __post_init__(self):
        if not _real(self.turn) or not 0.0 <= self.turn <= 180.0:
            raise ValueError(f"turn: expected an angle from 0 to 180 degrees, got {self.turn!r}")
        if not _real(self.move) or not self.move >= 0:
            raise ValueError(f"move: expected a finite distance >= 0 m, got {self.move!r}")
        if not _real(self.seconds) or not self.seconds > 0:
            raise ValueError(f"seconds: expected a finite time > 0 s, got {self.seconds!r}")
        for name in ("turn", "move", "seconds"):
            object.__setattr__(self, name, float(getattr(self, name)))

    def inertia(self, scene):
        """The nodal forces (k, n, 3), N, of the carry's largest accelerations (a move and a
        turn along half a cosine over `seconds`): its move's, uniform, along each of
        ANY_DIRECTION, and its turn's about each axis both ways, growing with the distance
        from the held vertices' centroid."""
        peak = math.pi ** 2 / (2 * self.seconds ** 2)
        m = scene.masses[:, None]
        forces = [self.move * peak * m * np.asarray(d) for d in ANY_DIRECTION] if self.move else []
        if self.turn:
            h = scene.mesh.vertices[scene.fixed_mask.any(axis=1)].mean(axis=0)
            arm = scene.mesh.vertices - h
            for axis in np.vstack([np.eye(3), -np.eye(3)]):
                forces.append(math.radians(self.turn) * peak * m * np.cross(axis, arm))
        return np.array(forces).reshape(-1, scene.mesh.n_vertices, 3)

    def base(self, scene, axis, angle, shift, t):
        """The base (3, 4) [R_g | c_g] at time t (s) of the carry turning by `angle` rad about
        `axis` (a unit 3-vector) through the held vertices' centroid and moving by `shift`
        (3,), m, along half a cosine over `seconds`, then holding."""
        s = 0.5 - 0.5 * math.cos(math.pi * min(t / self.seconds, 1.0))
        K = np.cross(np.eye(3), np.asarray(axis, float))        # [axis]_x
        a = s * angle
        R = np.eye(3) + math.sin(a) * K + (1 - math.cos(a)) * (K @ K)
        h = scene.mesh.vertices[scene.fixed_mask.any(axis=1)].mean(axis=0)
        return np.hstack([R, (h - R @ h + s * np.asarray(shift, float))[:, None]])


@dataclass(frozen=True)
class Loads:
    """What a reduced model must handle beyond the scene's own dead loads: drags (Drag, any
    number), a gravity cone (degrees, 0 to 180: the scene's gravity may turn by up to this
    angle), a carry (Carry: the held vertices moved rigidly; the framed model only) and the
    ranges of the scene's controls (a mapping name -> (low, high), held as sorted pairs)."""
    drags: tuple = field(default_factory=tuple)
    cone: float = 0.0
    carry: Carry = None
    controls: tuple = ()

    def __post_init__(self):
        drags = tuple(self.drags)
        for i, d in enumerate(drags):
            if not isinstance(d, Drag):
                raise TypeError(f"drags: item {i} is a {type(d).__name__}, expected a Drag")
        object.__setattr__(self, "drags", drags)
        if not _real(self.cone) or not 0.0 <= self.cone <= 180.0:
            raise ValueError(f"cone: expected an angle from 0 to 180 degrees, got {self.cone!r}")
        object.__setattr__(self, "cone", float(self.cone))
        if self.carry is not None and not isinstance(self.carry, Carry):
            raise TypeError(f"carry: expected a Carry, got {type(self.carry).__name__}")
        ranges = dict(self.controls)
        for name, span in ranges.items():
            low, high = _span(name, span)
            ranges[name] = (low, high)
        object.__setattr__(self, "controls", tuple(sorted(ranges.items())))

    def check(self, scene):
        """ValueError unless every drag names vertices of the scene's mesh of which at least one
        is free, and a cone has gravity to turn."""
        n = scene.mesh.n_vertices
        held = scene.fixed_mask.all(axis=1)
        for i, d in enumerate(self.drags):
            idx = np.asarray(d.vertices)
            outside = idx[(idx < 0) | (idx >= n)]
            if outside.size:
                raise ValueError(f"drags[{i}].vertices: {outside.size} indices outside the "
                                 f"mesh's {n} vertices (first {int(outside[0])})")
            if held[idx].all() or not scene.masses[idx].sum() > 0:
                raise ValueError(f"drags[{i}].vertices: every one of its {idx.size} vertices is "
                                 f"held fixed or in no tet; a drag needs a free vertex to act "
                                 f"on")
        if self.cone > 0 and not np.any(scene.gravity):
            raise ValueError(f"cone: {self.cone} degrees of gravity direction, but the scene "
                             f"has no gravity")
        if self.carry is not None and not scene.fixed_mask.any():
            raise ValueError("carry: the scene holds no vertex to carry")
        activations = {a.name for a in scene.activations}
        cables = {c.name for c in scene.cables}
        for name, (low, high) in self.controls:
            if name not in scene.controls:
                raise ValueError(f"controls: no control {name!r}; the scene has: "
                                 f"{', '.join(scene.controls) or 'none'}")
            if name in cables and low < 0:
                raise ValueError(f"controls: {name!r} is a cable, its range must lie at >= 0 "
                                 f"N, got ({low:g}, {high:g})")
            if name in activations and not 0.0 <= low < high < 1.0:
                raise ValueError(f"controls: {name!r} is an activation, its range must lie in "
                                 f"[0, 1), got ({low:g}, {high:g})")


def _real(value):
    """Whether value is a finite real number (not a bool)."""
    return (isinstance(value, (int, float, np.integer, np.floating))
            and not isinstance(value, bool) and math.isfinite(value))


def _span(name, span):
    """(low, high) of a control's declared range; ValueError naming it otherwise."""
    try:
        low, high = (float(v) for v in span)
    except (TypeError, ValueError):
        raise ValueError(f"controls: {name!r}: expected a range (low, high), got "
                         f"{span!r}") from None
    if not (math.isfinite(low) and math.isfinite(high) and low < high):
        raise ValueError(f"controls: {name!r}: expected finite low < high, got {span!r}")
    return low, high


def _unit_rows(directions):
    """Directions (3,) or (k, 3) as a tuple of unit 3-tuples; ValueError unless each is a
    finite non-zero 3-vector."""
    try:
        d = np.atleast_2d(np.asarray(directions, dtype=float))
    except (TypeError, ValueError):
        d = None
    ok = d is not None and d.ndim == 2 and d.shape[1] == 3 and d.shape[0] > 0
    norms = np.linalg.norm(d, axis=1) if ok else None
    if not ok or not np.isfinite(d).all() or not (norms > 0).all():
        raise ValueError(f"directions: expected non-zero finite 3-vectors, got {directions!r}")
    return tuple(tuple(float(c) for c in row) for row in d / norms[:, None])


def free_ends(scene):
    """The free ends of a scene's body: lists of vertex indices, the vertices at least
    END_SHARE of the farthest distance from the held vertices through the mesh (along its
    edges: the far end of each arm, not a point across a gap), split into connected pieces."""
    graph = edge_graph(scene.mesh)
    distance = held_distance(scene, graph)
    far = np.flatnonzero(distance >= END_SHARE * distance.max())
    count, label = connected_components(graph[far][:, far], directed=False)
    return [far[label == c] for c in range(count)]


def default_loads(scene):
    """The scene's own loads plus, at each free end (free_ends), a drag in any direction of up
    to DRAG_SHARE of the body's weight (its mass times |gravity|, or standard gravity in a
    scene without), and the range each control on a load curve takes (curve_ranges)."""
    g = float(np.linalg.norm(scene.gravity)) or STANDARD_GRAVITY
    weight = DRAG_SHARE * float(scene.masses.sum()) * g
    return Loads(drags=tuple(Drag(tuple(end), weight) for end in free_ends(scene)),
                 controls=curve_ranges(scene))


def curve_ranges(scene):
    """{name: (low, high)}: the values each of the scene's controls on a load curve takes,
    its written value times the curve's smallest and largest factor (none where they are
    one)."""
    written = dict(zip(scene.controls, scene.control_values))
    ranges = {}
    for part in scene.timed:
        if part.control is not None:
            ends = written[part.control] * np.array([part.curve.values.min(),
                                                     part.curve.values.max()])
            low, high = float(ends.min()), float(ends.max())
            if low < high:
                ranges[part.control] = (low, high)
    return ranges


def gravity_change(scene, direction):
    """The nodal force (n, 3), N, that turns the scene's gravity to `direction` (a unit
    3-vector) at the same magnitude."""
    g = scene.gravity
    return scene.gravity_force(np.linalg.norm(g) * np.asarray(direction, float) - g)


def _cone_direction(g, angle, azimuth):
    """The unit vector at `angle` radians from g (3,), at `azimuth` around it."""
    axis = g / np.linalg.norm(g)
    e1 = np.cross(axis, [1.0, 0.0, 0.0] if abs(axis[0]) < 0.9 else [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(axis, e1)
    return (math.cos(angle) * axis
            + math.sin(angle) * (math.cos(azimuth) * e1 + math.sin(azimuth) * e2))


def build_cases(scene, loads):
    """The static load cases a basis is fitted to, as chains of (extra nodal force (n, 3) N
    over the scene's own, controls {name: value} over the scene's own): each drag along each
    candidate direction at SHARES of its magnitude (a chain, solved in order); gravity turned
    to CONE_DIRECTIONS points on the cone's rim and on the cone at half its angle (one-case
    chains); a carry widens the cone to its turn and adds its inertia (Carry.inertia) at
    SHARES; each declared control from its written value toward each end of its range, each
    pair of them together toward each pair of ends, and with more than one, all of them
    toward COMBINED points per control drawn in their ranges (seed COMBINED_SEED), at
    SHARES."""
    none = {}
    chains = [[(s * d.force(scene, direction), none) for s in SHARES]
              for d in loads.drags for direction in d.candidate_directions]
    cone = loads.cone
    if loads.carry is not None:
        # a carried body feels gravity turn by the carry's turn, and the carry's inertia as a
        # body force of up to its largest acceleration, any direction
        if np.any(scene.gravity):
            cone = max(cone, loads.carry.turn)
        chains += [[(s * f, none) for s in SHARES] for f in loads.carry.inertia(scene)]
    if cone > 0:
        for angle in (cone, cone / 2):
            for k in range(CONE_DIRECTIONS):
                direction = _cone_direction(scene.gravity, math.radians(angle),
                                            2 * math.pi * k / CONE_DIRECTIONS)
                chains.append([(gravity_change(scene, direction), none)])
    written = dict(zip(scene.controls, scene.control_values))
    zero = np.zeros((scene.mesh.n_vertices, 3))
    away = {name: [end for end in span if end != written[name]]
            for name, span in loads.controls}
    names = list(away)
    ends = [{name: end} for name in names for end in away[name]]
    ends += [{a: x, b: y} for i, a in enumerate(names) for b in names[i + 1:]
             for x in away[a] for y in away[b]]
    if len(names) > 1:   # all of them at once: COMBINED draws per control from the ranges
        rng = np.random.default_rng(COMBINED_SEED)
        ends += [{name: float(rng.uniform(*span)) for name, span in loads.controls}
                 for _ in range(COMBINED * len(names))]
    for end in ends:
        chains.append([(zero, {name: written[name] + s * (value - written[name])
                               for name, value in end.items()}) for s in SHARES])
    return chains


def unseen_cases(scene, loads, count, seed=0):
    """`count` load cases drawn from the declaration (reproducibly, from `seed`), almost surely
    none of the build's: a random drag along a random direction (uniform on the sphere, or one
    of its declared directions) at SMALLEST_UNSEEN to 1 of its magnitude, with gravity turned
    to a random direction within the cone, and with a carry, the held vertices carried along
    a random axis and direction at SMALLEST_UNSEEN to 1 of its turn and move, and each
    declared control at a uniform draw from its range. Returns [(drag index or None, force
    (n, 3), N, base (t -> (3, 4)) or None, controls {name: value})]."""
    rng = np.random.default_rng(seed)
    cases = []
    for _ in range(count):
        f = np.zeros((scene.mesh.n_vertices, 3))
        which = None
        if loads.drags:
            which = int(rng.integers(len(loads.drags)))
            d = loads.drags[which]
            if d.directions is None:
                direction = rng.normal(size=3)
                direction /= np.linalg.norm(direction)
            else:
                direction = d.directions[int(rng.integers(len(d.directions)))]
            f += rng.uniform(SMALLEST_UNSEEN, 1.0) * d.force(scene, direction)
        if loads.cone > 0:
            angle = math.radians(loads.cone) * math.sqrt(rng.uniform())
            f += gravity_change(scene, _cone_direction(scene.gravity, angle,
                                                       rng.uniform(0, 2 * math.pi)))
        base = _drawn_carry(scene, loads.carry, rng)
        controls = {name: float(rng.uniform(low, high)) for name, (low, high) in loads.controls}
        cases.append((which, f, base, controls))
    return cases


def _drawn_carry(scene, carry, rng):
    """A random carry of the declared one (None without): t -> base (3, 4)."""
    if carry is None:
        return None
    axis, way = rng.normal(size=3), rng.normal(size=3)
    angle = math.radians(carry.turn) * rng.uniform(SMALLEST_UNSEEN, 1.0)
    shift = carry.move * rng.uniform(SMALLEST_UNSEEN, 1.0) * way / np.linalg.norm(way)
    axis = axis / np.linalg.norm(axis)
    return lambda t: carry.base(scene, axis, angle, shift, t)
