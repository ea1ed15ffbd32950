"""Contact with rigid obstacles (anisofem.physics.obstacles, .contact): the obstacles' distance
derivatives and continuous collision test, the barrier's and friction's derivatives against
central differences, drop tests that never pass an obstacle, Coulomb's slope, and bad input."""
import itertools
import os

import numpy as np
import pytest

import anisofem as af
from anisofem.physics.contact import ContactTerm, body_size
from anisofem.physics.curves import Timed
from anisofem.physics.potential import Potential
from anisofem.studies import drops

OBSTACLES = {
    "plane": af.Plane((0.0, 0.0, -0.1), (0.3, -0.2, 1.0)),
    "sphere": af.Sphere((0.1, 0.0, -0.2), 0.15),
    "capsule": af.Capsule((-0.2, 0.0, -0.2), (0.3, 0.1, -0.25), 0.1),
    "box": af.Box((0.0, 0.0, -0.3), (0.2, 0.15, 0.1),
                  rotation=[[0.8, -0.6, 0.0], [0.6, 0.8, 0.0], [0.0, 0.0, 1.0]]),
}


def outside_points(obstacle, rng, k=200):
    """k points outside obstacle, at distances from 1 mm to 0.2 m, away from its kinks."""
    points = []
    while len(points) < k:
        x = rng.uniform(-0.6, 0.6, size=(4 * k, 3))
        d, _ = obstacle.distance(x)
        keep = x[(d > 1e-3) & (d < 0.2)]
        points.extend(keep[:k - len(points)])
    return np.array(points)


@pytest.mark.parametrize("kind", sorted(OBSTACLES))
def test_distance_derivatives_match_central_differences(kind):
    """The normal is the distance's gradient and the curvature its Hessian, to 1e-6 relative,
    at 200 points outside each obstacle (a box's edges and corners, a capsule's caps)."""
    o = OBSTACLES[kind]
    x = outside_points(o, np.random.default_rng(1))
    d, n, H = o.geometry(x)
    h = 1e-6
    for axis in range(3):
        e = np.zeros(3)
        e[axis] = h
        dp, np_ = o.distance(x + e)
        dm, nm = o.distance(x - e)
        assert np.allclose((dp - dm) / (2 * h), n[:, axis], atol=1e-6)
        assert np.allclose((np_ - nm) / (2 * h), H[:, :, axis], atol=1e-4 * np.abs(H).max())
    assert np.allclose(np.linalg.norm(n, axis=1), 1.0)


@pytest.mark.parametrize("kind", sorted(OBSTACLES))
def test_first_touch_never_passes_the_floor_and_stops_near_it(kind):
    """Points flung at an obstacle: the share first_touch returns keeps every point at or above
    its floor all along the way (checked at 2,000 stations), and where the move would cross
    it, it stops within 1% of the floor."""
    o = OBSTACLES[kind]
    rng = np.random.default_rng(2)
    x = outside_points(o, rng, 100)
    d0, n0 = o.distance(x)
    dx = -n0 * rng.uniform(0.5, 3.0, size=(100, 1)) * d0[:, None] + rng.normal(
        scale=0.05, size=(100, 3))
    floor = 0.1 * d0
    s = o.first_touch(x, dx, floor)
    stations = np.linspace(0.0, 1.0, 2001)
    for i in range(100):
        d_way, _ = o.distance(x[i] + np.outer(stations * s[i], dx[i]))
        assert d_way.min() >= floor[i] * (1 - 1e-9)
        if s[i] < 1.0:
            d_end, _ = o.distance((x[i] + s[i] * dx[i])[None])
            assert d_end[0] <= floor[i] * 1.01
    assert (s < 1.0).sum() > 30


def near_ground(cells=(4, 1, 1), order=1, lift=3e-5, material=None, **contact):
    """A 0.04 x 0.01 x 0.01 m bar lying `lift` m above the ground z = 0 (within its barrier's
    reach), under gravity."""
    mesh = af.box_beam(size=(0.04, 0.01, 0.01), cells=cells)
    mesh = af.TetMesh(mesh.vertices - mesh.vertices.min(axis=0) + [0, 0, lift], mesh.tets)
    if order == 2:
        mesh = mesh.raised()
    material = material or af.Material(1e5, 0.45, 1000.0, np.array([1.0, 0, 0]), 1e5)
    return af.Scene(mesh, material, gravity=(0, 0, -9.81),
                    contact=af.Contact([af.Plane(name="ground")], **contact))


def central_differences(pot, x, direction, h):
    """(dG along direction, the gradient's change along it) by central differences."""
    ep, gp = pot.energy_gradient(x + h * direction)
    em, gm = pot.energy_gradient(x - h * direction)
    return (ep - em) / (2 * h), (gp - gm) / (2 * h)


def assert_derivatives(pot, x, g, H, directions, floor=0.0):
    """The gradient g (n, 3) and Hessian H (3n, 3n) at x within 1e-6 of central differences
    of pot along each unit direction (n, 3) (the Hessian's, plus `floor`)."""
    for p in directions:
        p = p / np.linalg.norm(p)
        slope, change = central_differences(pot, x, p, 1e-9)
        assert abs(slope - float((g * p).sum())) <= 1e-6 * np.abs(g).sum()
        Hp = (H @ p.ravel()).reshape(-1, 3)
        assert np.abs(change - Hp).max() <= 1e-6 * np.abs(Hp).max() + floor


@pytest.mark.parametrize("order", [1, 2])
@pytest.mark.parametrize("stiffness", [None, 1e14])
def test_barrier_and_friction_derivatives_match_central_differences(order, stiffness):
    """A step's potential with the barrier and friction (nodes sliding past and inside the
    smoothing, friction 0.5): its gradient along random directions and its Hessian times them
    within 1e-6 of central differences, at the default stiffness and at 10^14 N/m^3."""
    scene = near_ground(order=order, friction=0.5, stiffness=stiffness)
    rng = np.random.default_rng(3)
    x0 = scene.initial_positions()
    dt = 0.01
    x_start = x0 + rng.normal(scale=2e-6, size=x0.shape) * [1, 1, 0]
    pot = Potential(scene, x_start + dt * np.array([0.01, 0.0, 0.0]), dt, x_start=x_start)
    term = pot.contact
    assert term.friction, "some nodes within reach of the ground at the step's start"
    eps = term.friction[0][4]
    x = x_start + rng.normal(scale=1e-6, size=x0.shape)
    x[:, 2] = x0[:, 2] + rng.uniform(-1e-5, 1e-5, size=len(x))   # within the barrier
    x[::3, 0] += 5 * eps    # some nodes sliding past the smoothing, the others inside it
    layout = scene.full_layout
    _, g, data = pot.hessian_data(x, layout)
    H = layout.matrix(data)
    assert_derivatives(pot, x, g, H, rng.normal(size=(3,) + x.shape), 1e-9 * np.abs(H).max())


def test_projected_contact_blocks_are_positive_semi_definite():
    """Against a sphere the barrier's block has a negative curvature part; the projected
    Hessian clamps it: every node's block PSD."""
    mesh = af.box_beam(size=(0.04, 0.01, 0.01), cells=(4, 1, 1))
    ball = af.Sphere((0.02, 0.005, -0.006 - 2e-5), 0.001)   # under a bottom node
    scene = af.Scene(mesh, af.Material(1e5, 0.45, 1000.0), contact=af.Contact([ball]))
    term = ContactTerm(scene)
    x = scene.initial_positions()
    exact = term.node_hessians(x)
    projected = term.node_hessians(x, project=True)
    assert np.linalg.eigvalsh(exact).min() < 0
    assert np.linalg.eigvalsh(projected).min() >= -1e-9 * np.abs(projected).max()


def body(kind):
    """A Neo-Hookean body 2 cm above the ground: the 0.2 m beam, the T, a tentacle-like rod."""
    mesh = drops.body(kind)
    X = mesh.vertices - [0, 0, mesh.vertices[:, 2].min() - 0.02]
    return af.TetMesh(X, mesh.tets), drops.MATERIAL


@pytest.mark.parametrize("kind", ["beam", "tee", "rod"])
def test_drops_never_pass_the_ground_or_a_box(kind):
    """Each body dropped onto the ground with a box on it at 1, 10 and 100 g, dt 0.005 to 0.05
    s: every step converged, no surface node ever at or below an obstacle (nor at any Newton
    iterate: the solve's every iterate is clipped; for the ground, a plane, that is no
    intersection at all), no element inverted; it comes to rest within the barrier's reach of
    the ground. (The box's edges can cut into a face between its nodes: ipctk's intersection
    test finds the beam draped over it at 10 g crossing its top edge; docs/contact.md.)"""
    mesh, material = body(kind)
    X = mesh.vertices
    middle = X.mean(axis=0)
    box = af.Box((middle[0], middle[1], 0.005), (0.02, 0.05, 0.005), name="block")
    ground = af.Plane(name="ground")
    for g, dt in itertools.product((1, 10, 100), (0.005, 0.02, 0.05)):
        scene = af.Scene(mesh, material, gravity=(0, 0, -9.81 * g),
                         contact=af.Contact([ground, box]))
        term = ContactTerm(scene)
        roll = af.simulate(scene, drops.fall_steps(9.81 * g, dt), dt=dt, warn=False)
        assert roll.completed and roll.converged, (kind, g, dt)
        for s in roll.steps:
            assert term.distances(s.x).min() > 0, (kind, g, dt)
            assert s.newton.inversion.inverted == 0
        assert term.distances(roll.steps[-1].x).min() < term.dhat


def test_a_cube_on_a_slope_follows_coulomb():
    """A stiff cube on a plane tilted by atan(0.5) (the tilt turned on over 0.3 s): with
    friction 0.5 it stays (its slide over 1 s below the smoothing velocity times 1 s); with
    0.49 and 0.3 it slides with acceleration g (sin t - mu cos t) within 5%."""
    theta, g, dt = np.arctan(0.5), 9.81, 0.01
    mesh = af.box_beam(size=(0.02, 0.02, 0.02), cells=(2, 2, 2))
    mesh = af.TetMesh(mesh.vertices - mesh.vertices.min(axis=0) + [0, 0, 3e-5], mesh.tets)
    material = af.Material(1e7, 0.4, 1000.0, model="neohookean")
    push = np.zeros((mesh.n_vertices, 3))
    for mu in (0.5, 0.49, 0.3):
        def scene_of(force):
            return af.Scene(mesh, material, gravity=(0, 0, -g * np.cos(theta)),
                            nodal_force=force, contact=af.Contact([af.Plane()], friction=mu))
        settled = af.simulate(scene_of(None), 30, dt=dt, warn=False).steps[-1]
        m = scene_of(None).masses
        push[:, 0] = m * g * np.sin(theta)
        tilted = scene_of(push).following([Timed(af.LoadCurve([0, 0.3, 10], [0, 1, 1]),
                                                 force=push)])
        roll = af.simulate(tilted, 100, dt=dt, x0=settled.x, v0=settled.v, warn=False)
        assert roll.converged
        slide = np.array([m @ (s.x[:, 0] - settled.x[:, 0]) for s in roll.steps]) / m.sum()
        t = dt * np.arange(1, len(slide) + 1)
        if mu == 0.5:
            assert abs(slide[-1]) < 1e-3 * body_size(mesh) * 1.0, slide[-1]
        else:
            late = t > 0.4
            a = 2 * np.polyfit(t[late], slide[late], 2)[0]
            assert a == pytest.approx(g * (np.sin(theta) - mu * np.cos(theta)), rel=0.05)


def test_bad_contact_input_is_refused_in_one_line():
    mesh = af.box_beam(size=(0.04, 0.01, 0.01), cells=(4, 1, 1))
    material = af.Material(1e5, 0.45, 1000.0)
    with pytest.raises(ValueError, match=r"contact: the body starts inside obstacle 'floor' "
                       r"\(plane\): \d+ surface nodes, the deepest 5 mm in at"):
        af.Scene(mesh, material, contact=af.Contact([af.Plane(name="floor")]))
    for kwargs, message in (({"distance": 0.0}, "contact: distance must be > 0"),
                            ({"distance": -1e-3}, "contact: distance must be > 0"),
                            ({"friction": -0.1}, "contact: friction must be >= 0"),
                            ({"stiffness": 0.0}, "contact: stiffness must be > 0")):
        with pytest.raises(ValueError, match=message):
            af.Contact([af.Plane()], **kwargs)
    with pytest.raises(ValueError, match="contact: obstacles: give at least one"):
        af.Contact([])
    with pytest.raises(TypeError, match="expected anisofem obstacles"):
        af.Contact(["ground"])
    with pytest.raises(ValueError, match="ball: radius must be > 0"):
        af.Sphere((0, 0, 0), -1.0, name="ball")
    with pytest.raises(ValueError, match="wall: friction must be >= 0"):
        af.Plane(name="wall", friction=-1)
    with pytest.raises(ValueError, match="block: rotation must be a rotation matrix"):
        af.Box((0, 0, 0), (1, 1, 1), rotation=2 * np.eye(3), name="block")
    scene = near_ground()
    with pytest.raises(ValueError, match="method: 'reuse' keeps factors"):
        af.simulate(scene, 2, method="reuse")


def test_no_newton_iterate_or_trial_point_reaches_the_ground(monkeypatch):
    """The 0.2 m beam dropped at 100 g with dt = 0.05 s: every point any line search tries (a
    superset of the Newton iterates) keeps every surface node above the ground."""
    mesh, material = body("beam")
    scene = af.Scene(mesh, material, gravity=(0, 0, -981.0),
                     contact=af.Contact([af.Plane(name="ground")]))
    closest = []
    energy = ContactTerm.energy

    def watched(self, x, grad=None):
        closest.append(float(self.distances(x).min()))
        return energy(self, x, grad)

    monkeypatch.setattr(ContactTerm, "energy", watched)
    roll = af.simulate(scene, 10, dt=0.05, warn=False)
    assert roll.converged
    assert len(closest) > 50 and min(closest) > 0
    assert min(closest) < ContactTerm(scene).dhat     # it did reach the barrier


SCENE = """mesh = "beam.msh"
gravity = [0, 0, -9.81]

[material]
law = "neohookean"
young = 1e5
poisson = 0.45

[contact]
friction = 0.4
{extra}
[contact.obstacles.ground]
plane = {{point = [0, 0, -0.03], normal = [0, 0, 1]}}

[contact.obstacles.ball]
{ball}
friction = 0.1
"""
BALL = "sphere = {center = [0.05, 0, -0.05], radius = 0.03}"


@pytest.fixture(scope="module")
def beam_file(tmp_path_factory):
    folder = tmp_path_factory.mktemp("contact")
    af.write_mesh(str(folder / "beam.msh"), af.box_beam(size=(0.1, 0.02, 0.02),
                                                        cells=(10, 2, 2)))
    return folder


def test_a_scene_file_declares_obstacles(beam_file):
    """[contact] with a ground plane and a ball of its own friction: the beam falls onto the
    ball and drapes over it, above both."""
    (beam_file / "drop.toml").write_text(SCENE.format(extra="", ball=BALL))
    scene = af.load_scene(str(beam_file / "drop.toml"))
    ground, ball = scene.contact.obstacles
    assert (ground.name, ball.name, ball.friction, scene.contact.friction) == (
        "ground", "ball", 0.1, 0.4)
    roll = af.simulate(scene, 20, dt=0.02, warn=False)
    assert roll.converged
    term = ContactTerm(scene)
    lowest = min(float(term.distances(s.x).min()) for s in roll.steps)
    assert 0 < lowest < term.dhat
    assert roll.steps[-1].x[:, 2].min() < -0.02   # its ends hang below the ball's top


@pytest.mark.parametrize("extra, ball, message", [
    ("distance = 0", BALL, r"contact: distance must be > 0"),
    ("frictoin = 0.1", BALL, r"contact.frictoin: unknown key; did you mean 'friction'\?"),
    ("", "sphere = {center = [0.05, 0, -0.05]}",
     r"contact.obstacles.ball.sphere: expected \{center, radius\}"),
    ("", "sphere = {center = [0.05, 0, -0.05], radius = -1}",
     r"contact.obstacles.ball.sphere: ball: radius must be > 0"),
    ("", "cube = {center = [0, 0, 0]}", r"contact.obstacles.ball.cube: unknown key"),
    ("", "sphere = {center = [0.05, 0, 0], radius = 0.02}",
     r"contact: the body starts inside obstacle 'ball' \(sphere\)"),
    ("", BALL + "\nmove = [0, 0, 0.01]",
     r"contact.obstacles.ball: give move \(how far, m\) and curve \(when\) together"),
    ("self_contact = 1", BALL, r"contact.self_contact: expected true or false, got 1"),
])
def test_a_scene_file_with_bad_contact_fails_in_one_line(beam_file, extra, ball, message):
    from anisofem.io.scenefile import SceneFileError
    (beam_file / "bad.toml").write_text(SCENE.format(extra=extra, ball=ball))
    with pytest.raises(SceneFileError, match=message):
        af.load_scene(str(beam_file / "bad.toml"))


def test_a_scene_file_takes_self_contact_without_obstacles(beam_file):
    """[contact] with self_contact = true and no obstacles is the surface's contact with
    itself; without either it is refused."""
    pytest.importorskip("ipctk")
    (beam_file / "itself.toml").write_text(
        'mesh = "beam.msh"\n[contact]\nself_contact = true\nfriction = 0.2\n')
    contact = af.load_scene(str(beam_file / "itself.toml")).contact
    assert (contact.self_contact, contact.obstacles, contact.friction) == (True, (), 0.2)
    (beam_file / "none.toml").write_text('mesh = "beam.msh"\n[contact]\nfriction = 0.2\n')
    from anisofem.io.scenefile import SceneFileError
    with pytest.raises(SceneFileError, match=r"contact.obstacles: expected "
                                             r"\[contact.obstacles.NAME\] tables, at least one "
                                             r"\(or self_contact = true\)"):
        af.load_scene(str(beam_file / "none.toml"))


def two_blocks(gap=2e-3, shift=(0.003, 0.002), material=None, **contact):
    """A 2 cm cube held at the origin and a second one `gap` m above it, shifted by `shift`, in
    one mesh, with self-contact."""
    cube = af.box_beam(size=(0.02, 0.02, 0.02), cells=(2, 2, 2))
    X = cube.vertices - cube.vertices.min(axis=0)
    upper = X + [shift[0], shift[1], 0.02 + gap]
    mesh = af.TetMesh(np.vstack([X, upper]), np.vstack([cube.tets, cube.tets + len(X)]))
    material = material or af.Material(1e5, 0.4, 1000.0, model="neohookean")
    held = np.zeros((mesh.n_vertices, 3), bool)
    held[:len(X)] = True
    return mesh, material, held, len(X)


def test_a_block_dropped_on_a_block_never_passes_into_it():
    """Self-contact (ipctk): a cube dropped onto a held cube of the same mesh at 1, 10 and 100
    g: every step converged, no intersection by ipctk's own test at any step, no inverted
    element, and it rests within the barrier's reach."""
    pytest.importorskip("ipctk")
    mesh, material, held, lower = two_blocks()
    for g in (1, 10, 100):
        scene = af.Scene(mesh, material, gravity=(0, 0, -9.81 * g), fixed=held,
                         contact=af.Contact(self_contact=True, friction=0.5))
        itself = ContactTerm(scene).itself
        roll = af.simulate(scene, 30, dt=0.01, warn=False)
        assert roll.completed and roll.converged, g
        for s in roll.steps:
            assert not itself.ipctk.has_intersections(itself.mesh, itself.vertices(s.x))
            assert itself.nearest(s.x) > 0
            assert s.newton.inversion.inverted == 0
        assert itself.nearest(roll.steps[-1].x) < itself.dhat
        assert roll.steps[-1].x[lower:, 2].min() > 0.02


@pytest.mark.parametrize("lower, upper, g, dt", [("tee", "beam", 1, 0.05),
                                                  ("rod", "tee", 10, 0.02),
                                                  ("beam", "rod", 100, 0.005)])
def test_bodies_dropped_onto_each_other_never_intersect(monkeypatch, lower, upper, g, dt):
    """One body lying on the ground, another dropped across it from 2 cm (friction 0.3;
    scripts/stacked_drops.py runs every pair at every gravity and step): every step
    converged, no point any solve evaluated intersects by ipctk's own test, nothing
    inverted, and the upper body comes to lie on the lower within the barrier's reach."""
    pytest.importorskip("ipctk")
    from anisofem.physics import self_contact
    mesh, n = drops.stacked(lower, upper)
    scene = af.Scene(mesh, drops.MATERIAL, gravity=(0, 0, -9.81 * g), contact=af.Contact(
        [af.Plane(name="ground")], friction=0.3, self_contact=True))
    seen, energy = [], self_contact.SelfContact.energy

    def watched(contact, x, grad=None):
        seen.append(bool(contact.ipctk.has_intersections(contact.mesh, contact.vertices(x))))
        return energy(contact, x, grad)
    monkeypatch.setattr(self_contact.SelfContact, "energy", watched)
    roll = af.simulate(scene, drops.fall_steps(9.81 * g, dt), dt=dt, warn=False)
    assert roll.completed and roll.converged
    assert len(seen) > len(roll.steps) and not any(seen)
    assert all(s.newton.inversion.inverted == 0 for s in roll.steps)
    itself = ContactTerm(scene).itself
    assert 0 < itself.nearest(roll.steps[-1].x) < itself.dhat
    assert roll.steps[-1].x[n:, 2].max() > mesh.vertices[:n, 2].max() + 0.01   # lies on it


@pytest.mark.parametrize("friction", [0.0, 0.5])
def test_self_contact_derivatives_match_central_differences(friction):
    """A step's potential with the two blocks within the barrier's reach (and friction lagged
    at the step's start): gradient and Hessian within 1e-6 of central differences."""
    pytest.importorskip("ipctk")
    mesh, material, held, lower = two_blocks(gap=3e-5)
    scene = af.Scene(mesh, material, gravity=(0, 0, -9.81), fixed=held,
                     contact=af.Contact(self_contact=True, friction=friction))
    rng = np.random.default_rng(4)
    x_start = scene.initial_positions()
    x_start[lower:, :2] += 1e-6
    pot = Potential(scene, x_start, 0.01, x_start=x_start)
    x = x_start.copy()
    x[lower:] += rng.normal(scale=3e-6, size=(mesh.n_vertices - lower, 3))
    x[lower:, 0] += 1e-5
    layout = scene.full_layout
    _, g, data = pot.hessian_data(x, layout)
    H = layout.matrix(data) + pot.coupled_hessian(x, layout)
    assert pot.contact.itself.nearest(x) < pot.contact.dhat
    upper = np.zeros((3,) + x.shape)      # moving the upper block only
    upper[:, lower:] = rng.normal(size=(3, mesh.n_vertices - lower, 3))
    assert_derivatives(pot, x, g, H, upper)
    public = af.hessian(scene, x, x_hat=x_start, dt=0.01)   # ipctk sums pairs on threads
    assert np.abs((public - H).toarray()).max() <= 1e-12 * np.abs(H).max()


def test_a_block_slides_on_a_slab_by_coulomb():
    """Self-contact friction: a 2 cm cube on a held slab of the same mesh, under gravity tilted
    by atan(0.5) (turned on over 0.1 s) with friction 0.3, slides with g (sin t - mu cos t)
    within 5%."""
    pytest.importorskip("ipctk")
    theta, g, dt, mu = np.arctan(0.5), 9.81, 0.01, 0.3
    slab = af.box_beam(size=(0.3, 0.04, 0.01), cells=(15, 2, 1))
    cube = af.box_beam(size=(0.02, 0.02, 0.02), cells=(2, 2, 2))
    S = slab.vertices - slab.vertices.min(axis=0)
    C = cube.vertices - cube.vertices.min(axis=0) + [0.013, 0.011, 0.01 + 5e-5]
    mesh = af.TetMesh(np.vstack([S, C]), np.vstack([slab.tets, cube.tets + len(S)]))
    lower = len(S)
    held = np.zeros((mesh.n_vertices, 3), bool)
    held[:lower] = True
    material = af.Material(1e7, 0.4, 1000.0, model="neohookean")
    m = af.Scene(mesh, material, fixed=held).masses
    push = np.zeros((mesh.n_vertices, 3))
    push[lower:, 0] = m[lower:] * g * np.sin(theta)
    scene = af.Scene(mesh, material, gravity=(0, 0, -g * np.cos(theta)), fixed=held,
                     nodal_force=push, contact=af.Contact(self_contact=True, friction=mu))
    tilted = scene.following([Timed(af.LoadCurve([0, 0.1, 10], [0, 1, 1]), force=push)])
    roll = af.simulate(tilted, 40, dt=dt, warn=False)
    assert roll.converged
    w = m[lower:]
    slide = np.array([w @ s.x[lower:, 0] for s in roll.steps]) / w.sum()
    t = dt * np.arange(1, len(slide) + 1)
    late = t > 0.15
    a = 2 * np.polyfit(t[late], slide[late], 2)[0]
    assert a == pytest.approx(g * (np.sin(theta) - mu * np.cos(theta)), rel=0.05)
    assert roll.steps[-1].x[lower:, 2].min() > 0.01     # on the slab all along


def test_self_contact_refuses_what_it_cannot_take():
    pytest.importorskip("ipctk")
    mesh, material, held, _ = two_blocks(gap=-2e-3)
    for gap, shift in ((-2e-3, (0.003, 0.002)), (0.0, (0.0, 0.0))):   # overlapping, touching
        mesh, material, held, _ = two_blocks(gap=gap, shift=shift)
        with pytest.raises(ValueError, match="contact: self_contact: the body's surface "
                                             "intersects or touches itself at rest"):
            af.Scene(mesh, material, fixed=held, contact=af.Contact(self_contact=True))
    mesh, material, held, _ = two_blocks()
    scene = af.Scene(mesh, material, fixed=held, gravity=(0, 0, -9.81),
                     contact=af.Contact(self_contact=True))
    with pytest.raises(ValueError, match="method: 'cg' cannot take self-contact"):
        af.simulate(scene, 1, method="cg")
    with pytest.raises(ValueError, match="linear_solver: 'banded' cannot hold the couplings of "
                                              "self-contact"):
        af.simulate(scene, 1, linear_solver="banded")
    with pytest.raises(TypeError, match="self_contact: expected True or False"):
        af.Contact(self_contact="yes")


@pytest.fixture(scope="module")
def sagging():
    """The 0.2 m StVK beam clamped at one end 1 cm above the ground, which its tip reaches
    under gravity (friction 0.3), and its reduced model (6 modes + 10 fitted)."""
    from anisofem.reduced import ReducedModel
    beam = af.box_beam(size=(0.2, 0.02, 0.02), cells=(20, 2, 2))
    mesh = af.TetMesh(beam.vertices - [0, 0, beam.vertices[:, 2].min() - 0.01], beam.tets)
    material = af.Material(1e5, 0.45, 1000.0, np.array([1.0, 0, 0]), 1e5)
    scene = af.Scene(mesh, material, gravity=(0, 0, -9.81), fixed=beam.vertices[:, 0] <= 1e-9,
                     contact=af.Contact([af.Plane(name="ground")], friction=0.3))
    return scene, ReducedModel(scene, modes=6, snapshots=10)


def fem_gap(scene, x):
    """The nearest any surface node is to an obstacle at x, m."""
    return float(ContactTerm(scene).distances(x).min())


def test_the_reduced_contact_is_the_fems_at_its_positions(sagging):
    """The reduced barrier and friction at q equal the FEM's at x0 + U q (1e-12), and their
    reduced gradient and Hessian (a plane: no curvature to clamp) match central differences
    of the reduced energy within 1e-6."""
    scene, model = sagging
    rng = np.random.default_rng(5)
    q_lag = model.solve()[0]
    [touching] = model.contact.touching(q_lag, 0.01)
    q = q_lag + rng.normal(scale=1e-8, size=model.r)
    x = model.positions(q)
    assert 0 < fem_gap(scene, x) < ContactTerm(scene).dhat
    fem = ContactTerm(scene, model.positions(q_lag), 0.01)
    assert touching.energy(q) == pytest.approx(fem.energy(x), rel=1e-12)
    assert fem.friction, "the tip touches the ground: friction is lagged there"
    g = touching.gradient(q)
    H, _ = touching.hessian(q)
    for _ in range(3):
        p = rng.normal(size=model.r)
        p /= np.linalg.norm(p)
        def richardson(f, h=1e-9):   # fourth-order central differences of f along p
            return (8 * (f(q + h * p) - f(q - h * p)) - (f(q + 2 * h * p) - f(q - 2 * h * p))
                    ) / (12 * h)
        slope = richardson(touching.energy)
        assert slope == pytest.approx(float(g @ p), rel=1e-6, abs=1e-9 * np.abs(g).sum())
        change = richardson(touching.gradient)
        assert np.abs(change - H @ p).max() <= 1e-6 * np.abs(H @ p).max()


def test_the_reduced_model_rests_on_the_ground_like_the_fem(sagging):
    """Statics: the reduced tip on the ground within 1e-3 of the FEM's height; a rollout of
    0.6 s: the tip within 3% of its largest motion, no surface node ever at the ground."""
    scene, model = sagging
    tip = af.metrics.end_vertices(scene.mesh, 0, "max")
    q, report = model.solve()
    assert report.converged
    full = af.solve(scene, warn=False).x
    assert model.positions(q)[tip, 2].mean() == pytest.approx(full[tip, 2].mean(), rel=1e-3)
    roll = af.simulate(scene, 60, dt=0.01, warn=False)
    q, w = np.zeros(model.r), np.zeros(model.r)
    gap, worst = np.inf, 0.0
    for s in roll.steps:
        q, w, report = model.step(q, w, 0.01)
        assert report.converged
        gap = min(gap, fem_gap(scene, model.positions(q)))
        worst = max(worst, abs(model.positions(q)[tip, 2].mean() - s.x[tip, 2].mean()))
    sag = max(abs(s.x[tip, 2].mean() - scene.mesh.vertices[tip, 2].mean()) for s in roll.steps)
    assert worst <= 0.03 * sag
    assert gap > 0


@pytest.fixture(scope="module")
def contact_file(tmp_path_factory):
    """The sagging beam with the ground and a ball under its tip, its reduced model written."""
    from anisofem.reduced import ReducedModel
    from export.writers.reduced import write
    beam = af.box_beam(size=(0.2, 0.02, 0.02), cells=(20, 2, 2))
    mesh = af.TetMesh(beam.vertices - [0, 0, beam.vertices[:, 2].min() - 0.01], beam.tets)
    material = af.Material(1e5, 0.45, 1000.0, np.array([1.0, 0, 0]), 1e5)
    ball = af.Sphere((0.15, 0.0, -0.002), 0.008, name="ball", friction=0.6)
    box = af.Box((0.05, 0.0, -0.01), (0.01, 0.03, 0.005), name="block",
                 rotation=[[0.8, -0.6, 0.0], [0.6, 0.8, 0.0], [0.0, 0.0, 1.0]])
    rod = af.Capsule((0.1, -0.05, -0.02), (0.1, 0.05, -0.02), 0.01, name="rod")
    scene = af.Scene(mesh, material, gravity=(0, 0, -9.81), fixed=beam.vertices[:, 0] <= 1e-9,
                     contact=af.Contact([af.Plane(name="ground"), ball, box, rod],
                                        friction=0.3))
    model = ReducedModel(scene, modes=6, snapshots=10)
    path = str(tmp_path_factory.mktemp("contact_file") / "beam")
    write(model, path, title="beam")
    return model, path


def test_the_runtimes_step_contact_like_the_library(contact_file):
    """The numpy runtime steps the written model with its four obstacles like the library
    (1e-10 m), and the C runtime like numpy (1e-9 m), also while the ball is moved into the
    body (both move it as far as the body lets it, to the same place)."""
    from export import native
    from export.runtime import ReducedSimulator
    model, path = contact_file
    sim = ReducedSimulator(path)
    assert sim.obstacles == ("ground", "ball", "block", "rod")
    force = model.scene.external_force
    q, w = np.zeros(model.r), np.zeros(model.r)
    qn, wn = sim.rest_state()
    for _ in range(40):
        q, w, report = model.step(q, w, 0.01)
        qn, wn = sim.step(qn, wn, force, 0.01)
        assert np.abs(model.positions(q) - sim.positions(qn)).max() <= 1e-10
    if native.compiler() is None:
        pytest.skip("no C compiler")
    c = native.CReducedSimulator(path)
    c.set_constant_force(force)
    assert c.obstacles == sim.obstacles
    sim = ReducedSimulator(path)
    qn, wn = sim.rest_state()
    qc, wc = c.rest_state()
    for k in range(60):
        if k in (20, 40):
            target = (0.15, 0.0, 0.004) if k == 20 else (0.15, 0.0, 0.03)
            sim.move_obstacle("ball", target)
            c.move_obstacle("ball", target)
        qn, wn = sim.step(qn, wn, force, 0.01)
        c.step(qc, wc, None, 0.01)
        assert np.abs(sim.positions(qn) - c.positions(qc)).max() <= 1e-9
    assert np.allclose(c.obstacle_position("ball"), sim.contact.obstacles[1]["center"],
                       atol=1e-12)
    assert 0.004 < c.obstacle_position("ball")[2] < 0.03    # it pushed the beam, not through
    x = c.positions(qc)
    term = ContactTerm(model.scene)
    assert term.distances(x)[:, 0].min() > 0
    with pytest.raises(RuntimeError, match="obstacle 'ball': its position must be 3 finite"):
        c.move_obstacle("ball", (0.0, np.nan, 0.0))
    with pytest.raises(ValueError, match="obstacle: no obstacle 'wall'"):
        c.move_obstacle("wall", (0.0, 0.0, 0.0))


def held_beam_under(tmp_path, young, obstacle):
    """The 0.1 m beam held at x = 0 (Young's modulus young, Pa) under gravity with one obstacle
    (friction 0.5), its reduced model written and loaded in the C runtime with gravity set:
    (scene, CReducedSimulator), or a skip without a C compiler."""
    from anisofem.reduced import ReducedModel
    from export import native
    from export.writers.reduced import write
    if native.compiler() is None:
        pytest.skip("no C compiler")
    beam = af.box_beam(size=(0.1, 0.02, 0.02), cells=(10, 2, 2))
    scene = af.Scene(beam, af.Material(young, 0.45, 1000.0), gravity=(0.0, 0.0, -9.81),
                     fixed=beam.vertices[:, 0] <= 1e-9,
                     contact=af.Contact([obstacle], friction=0.5))
    path = str(tmp_path / "beam")
    write(ReducedModel(scene, modes=6, snapshots=8, validate=False), path)
    c = native.CReducedSimulator(path)
    c.set_constant_force(c.masses[:, None] * scene.gravity)
    return scene, c


def test_a_free_obstacle_falls_onto_the_body_and_rests_on_it(tmp_path):
    """A 5 g box, free (af_obstacle_motion), dropped from 0.5 mm over the held beam's tip: every
    step its momentum changes by the impulse of gravity and of the beam's push on it
    (af_obstacle_wrench, summed from the nodes' barrier and friction) to 1e-9 N s, it never
    enters the beam, and after 4 s it rests there, the beam pushing it up by its weight
    (0.1%) and sagging under it."""
    from export import native
    g, dt, mass = np.array([0.0, 0.0, -9.81]), 0.01, 0.005
    scene, c = held_beam_under(tmp_path, 1e5,
                               af.Box((0.09, 0.0, 0.0205), (0.01, 0.015, 0.01), name="box"))
    q, w = c.rest_state()
    c.set_obstacle_motion("box", mass, (0.0, 0.0, 0.0), g)
    term = ContactTerm(scene)
    p, v = c.obstacle_position("box"), np.zeros(3)
    for _ in range(400):
        c.step(q, w, None, dt)
        p1 = c.obstacle_position("box")
        v1, push = (p1 - p) / dt, c.obstacle_wrench("box")
        assert np.abs(mass * (v1 - v) - dt * (push[:3] + mass * g)).max() < 1e-9
        moved = af.Box(p1, (0.01, 0.015, 0.01))
        assert moved.distance(c.positions(q)[term.nodes])[0].min() > 0
        p, v = p1, v1
    assert np.abs(v).max() < 1e-4
    assert push[2] == pytest.approx(mass * 9.81, rel=1e-3)
    c.set_obstacle_motion("box", 0.0, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    q0, w0 = c.rest_state()
    alone = native.CReducedSimulator(str(tmp_path / "beam"))
    alone.set_constant_force(alone.masses[:, None] * g)
    for _ in range(400):
        alone.step(q0, w0, None, dt)
    tip = scene.mesh.vertices[:, 0] >= 0.1 - 1e-9
    assert c.positions(q)[tip, 2].mean() < alone.positions(q0)[tip, 2].mean() - 1e-4
    with pytest.raises(RuntimeError, match="obstacle 'box': mass must be a finite number >= 0"):
        c.set_obstacle_motion("box", -1.0, (0.0, 0.0, 0.0), g)


def test_a_free_obstacle_that_turns_tips_over_the_tip(tmp_path):
    """A 2 cm cube of 5 g, free and turning (af_obstacle_motion with its inertia), dropped with
    its center over the end of a stiff held beam: it tips over the edge and falls off. Every
    step (Newton to a relative 1e-12) its momentum changes by gravity's impulse and the
    wrench's force (1e-9 N s; the weight's is 5e-4; 3e-12 to 4e-10 seen, as the basis's
    round-off goes) and its angular momentum by the wrench's moment (1e-11 N m s), the turns
    read from its orientation (af_obstacle_shape); no beam node is ever inside it."""
    from scipy.spatial.transform import Rotation
    g, dt, mass = np.array([0.0, 0.0, -9.81]), 0.01, 0.005
    inertia = mass * 0.02 ** 2 / 6
    scene, c = held_beam_under(tmp_path, 1e7,
                               af.Box((0.1, 0.0, 0.0205), (0.01, 0.01, 0.01), name="cube"))
    q, w = c.rest_state()
    c.set_obstacle_motion("cube", mass, np.zeros(6), np.r_[g, 0, 0, 0],
                          inertia=inertia * np.eye(3))
    nodes = ContactTerm(scene).nodes
    p, v, R, spin = c.obstacle_position("cube"), np.zeros(3), np.eye(3), np.zeros(3)
    most = 0.0
    for _ in range(60):
        c.step(q, w, None, dt, rtol=1e-12, max_iter=500)
        p1, push = c.obstacle_position("cube"), c.obstacle_wrench("cube")
        R1 = c.obstacle_shape("cube")[1][6:15].reshape(3, 3)
        v1, spin1 = (p1 - p) / dt, Rotation.from_matrix(R1 @ R.T).as_rotvec() / dt
        assert np.abs(mass * (v1 - v) - dt * (push[:3] + mass * g)).max() < 1e-9
        assert np.abs(inertia * (spin1 - spin) - dt * push[3:]).max() < 1e-11
        assert af.Box(p1, (0.01, 0.01, 0.01), R1).distance(c.positions(q)[nodes])[0].min() > 0
        p, v, R, spin = p1, v1, R1, spin1
        most = max(most, np.degrees(Rotation.from_matrix(R).magnitude()))
    assert most > 90.0, "it tipped over"
    assert p[2] < -0.2, "it fell off"


def test_under_the_sanitizers_a_file_with_obstacles_steps(contact_file, tmp_path):
    """The C runtime steps the file with its four obstacles, each moved every 10 steps, under
    AddressSanitizer and UndefinedBehaviorSanitizer."""
    import re
    import subprocess
    from export import native
    if native.compiler() is None:
        pytest.skip("no C compiler")
    from test_c_runtime import _sanitized
    _, path = contact_file
    done = subprocess.run([_sanitized(tmp_path), path], capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 0 and "runtime error" not in done.stderr, done.stderr
    assert re.match(r"ok 1 \d+ 50 \S+ obstacles 4 \S+$", done.stdout.strip()), done.stdout


def test_an_obstacle_moved_along_a_curve_pushes_the_body(beam_file):
    """A scene file's ball lifted 4 cm over 1 s along a curve under the hanging beam: every
    step the ball reaches where its curve puts it (its pushes move it as far as the beam lets
    it, then again), never a node inside it; the beam is pushed up."""
    text = SCENE.format(extra="", ball=BALL + "\nmove = [0, 0, 0.04]\ncurve = \"lift\"")
    text = text.replace("[contact]\n", "[curves.lift]\ntimes = [0, 1]\nvalues = [0, 1]\n\n"
                                       "[contact]\n")
    text = text.replace("[material]", "[[boundary]]\nwhere = \"x-min\"\nheld = true\n\n"
                                      "[material]")
    (beam_file / "lift.toml").write_text(text)
    scene = af.load_scene(str(beam_file / "lift.toml"))
    roll = af.simulate(scene, 40, dt=0.02, warn=False)
    assert roll.converged
    for k, s in enumerate(roll.steps, 1):
        wanted = scene.at(k * 0.02).contact.obstacles[1].position
        assert np.allclose(roll.obstacles[k, 1], wanted, atol=1e-12), k
        placed = af.physics.obstacles.Sphere(roll.obstacles[k, 1], 0.03)
        nodes = ContactTerm(scene).nodes
        assert placed.distance(s.x[nodes])[0].min() > 0
    assert roll.positions[-1][:, 2].max() > roll.positions[0][:, 2].max() + 0.005


def test_a_soft_ball_pressed_on_a_plane_follows_hertz():
    """Hertz on curved quadratic tets (tests/data/hemisphere_quarter_2.msh, Gmsh at second
    order, 0.15 mm at the pole): a 10 mm ball pressed 0.1 mm onto a plane; the force within 5%
    of Hertz's at a contact distance of 0.3 um, and closer as the distance shrinks (1e-5,
    1e-6, 3e-7 m)."""
    from anisofem.studies.hertz import pressed
    mesh = af.read_mesh(os.path.join(os.path.dirname(__file__), "data",
                                     "hemisphere_quarter_2.msh"))
    assert mesh.curved
    off = []
    for distance in (1e-5, 1e-6, 3e-7):
        force, hertz, result = pressed(mesh, 0.01, 1e-4, distance)
        assert result.converged
        off.append(abs(force / hertz - 1))
    assert off[-1] < 0.05 and off[0] > off[1] > off[2], off


def box_surface(center, half, name="block", friction=None):
    """A closed box of 12 triangles (outward), as a Surface obstacle."""
    corners = np.array([[i, j, k] for i in (-1, 1) for j in (-1, 1) for k in (-1, 1)], float)
    faces = [[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
             [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]]
    return af.Surface(np.asarray(center) + corners * half, faces, name=name, friction=friction)


def test_a_beam_draped_over_a_surface_box_never_crosses_its_edges():
    """The beam dropped at 10 g over a block given as a surface of triangles (onto the
    ground): every step converged, and by ipctk's own test no step intersects, nor any point
    a solve evaluated (the analytic box's barrier acts on the beam's nodes only, and its edge
    cuts into a face between them here; docs/contact.md)."""
    pytest.importorskip("ipctk")
    from anisofem.physics import self_contact
    mesh, material = body("beam")
    middle = mesh.vertices.mean(axis=0)
    block = box_surface((middle[0], middle[1], 0.005), (0.02, 0.05, 0.005))
    scene = af.Scene(mesh, material, gravity=(0, 0, -98.1),
                     contact=af.Contact([af.Plane(name="ground"), block], friction=0.3))
    seen, energy = [], self_contact.SelfContact.energy

    def watched(contact, x, grad=None):
        seen.append(bool(contact.ipctk.has_intersections(contact.mesh, contact.vertices(x))))
        return energy(contact, x, grad)
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(self_contact.SelfContact, "energy", watched)
        roll = af.simulate(scene, 20, dt=0.01, warn=False)
    assert roll.completed and roll.converged
    assert len(seen) > 20 and not any(seen)
    pairs = ContactTerm(scene).itself
    last = roll.steps[-1].x
    assert 0 < pairs.nearest(last) < pairs.dhat                   # it lies on the block
    assert last[:, 2].max() > 0.01 and last[:, 2].min() < 0.005   # and droops beside it
    analytic = af.Scene(mesh, material, gravity=(0, 0, -98.1), contact=af.Contact(
        [af.Plane(name="ground"), af.Box(block.position, (0.02, 0.05, 0.005))], friction=0.3))
    crossed = block_crossings(analytic, block, af.simulate(analytic, 20, dt=0.01, warn=False))
    assert crossed > 0   # what the surface is for


def block_crossings(scene, block, roll):
    """How many steps of roll the body's surface crosses the surface `block` in."""
    from anisofem.physics.self_contact import SelfContact
    pairs = SelfContact(scene.mesh, 1e-4, 1.0, surfaces=(block,), itself=False)
    return sum(bool(pairs.ipctk.has_intersections(pairs.mesh, pairs.vertices(s.x)))
               for s in roll.steps)


@pytest.mark.parametrize("friction", [0.0, 0.5])
def test_surface_contact_derivatives_match_central_differences(friction):
    """A step's potential with the beam's nodes, edges and faces within reach of a surface
    block's faces, edges and corners (its friction lagged at the step's start): gradient and
    Hessian within 1e-6 of central differences."""
    pytest.importorskip("ipctk")
    mesh, material = body("beam")
    X = mesh.vertices
    low = X[:, 2].min()
    block = box_surface((0.1, 0.0, low - 0.005 - 5e-5), (0.0123, 0.05, 0.005),
                        friction=friction)
    scene = af.Scene(mesh, material, gravity=(0, 0, -9.81), contact=af.Contact([block]))
    rng = np.random.default_rng(6)
    x_start = scene.initial_positions()
    pot = Potential(scene, x_start, 0.01, x_start=x_start)
    x = x_start + rng.normal(scale=3e-6, size=x_start.shape)
    x[:, 0] += 1e-5
    assert pot.contact.itself.nearest(x) < pot.contact.dhat
    _, g, data = pot.hessian_data(x, scene.full_layout)
    H = scene.full_layout.matrix(data) + pot.coupled_hessian(x, scene.full_layout)
    assert_derivatives(pot, x, g, H, rng.normal(size=(3,) + x.shape))


def test_a_block_slides_on_a_surface_by_its_own_friction():
    """A 2 cm cube on a surface rectangle under gravity tilted by atan(0.5) (turned on over
    0.1 s), the surface's own friction 0.3 over the contact's 0.9: it slides with
    g (sin t - 0.3 cos t) within 5%."""
    pytest.importorskip("ipctk")
    theta, g, dt, mu = np.arctan(0.5), 9.81, 0.01, 0.3
    cube = af.box_beam(size=(0.02, 0.02, 0.02), cells=(2, 2, 2))
    C = cube.vertices - cube.vertices.min(axis=0) + [0.01, -0.01, 5e-5]
    mesh = af.TetMesh(C, cube.tets)
    floor = af.Surface([[0, -0.05, 0], [0.4, -0.05, 0], [0.4, 0.05, 0], [0, 0.05, 0]],
                       [[0, 1, 2], [0, 2, 3]], name="floor", friction=mu)
    material = af.Material(1e7, 0.4, 1000.0, model="neohookean")
    m = af.Scene(mesh, material).masses
    push = np.zeros((mesh.n_vertices, 3))
    push[:, 0] = m * g * np.sin(theta)
    scene = af.Scene(mesh, material, gravity=(0, 0, -g * np.cos(theta)), nodal_force=push,
                     contact=af.Contact([floor], friction=0.9))
    tilted = scene.following([Timed(af.LoadCurve([0, 0.1, 10], [0, 1, 1]), force=push)])
    roll = af.simulate(tilted, 40, dt=dt, warn=False)
    assert roll.converged
    slide = np.array([m @ s.x[:, 0] for s in roll.steps]) / m.sum()
    t = dt * np.arange(1, len(slide) + 1)
    late = t > 0.15
    a = 2 * np.polyfit(t[late], slide[late], 2)[0]
    assert a == pytest.approx(g * (np.sin(theta) - mu * np.cos(theta)), rel=0.05)
    assert roll.steps[-1].x[:, 2].min() > 0    # on it all along


def test_surfaces_refuse_what_they_cannot_take(tmp_path):
    pytest.importorskip("ipctk")
    mesh, material = body("beam")
    low = mesh.vertices[:, 2].min()
    through = box_surface((0.1, 0.0, low), (0.02, 0.05, 0.005))
    with pytest.raises(ValueError, match=r"contact: the body starts inside obstacle 'block' "
                                         r"\(surface\): its triangles cross the body's "
                                         r"surface, near \("):
        af.Scene(mesh, material, contact=af.Contact([through]))
    block = box_surface((0.1, 0.0, low - 0.01), (0.02, 0.05, 0.005))
    scene = af.Scene(mesh, material, gravity=(0, 0, -9.81), contact=af.Contact([block]))
    with pytest.raises(ValueError, match="method: 'cg' cannot take self-contact or surface"):
        af.simulate(scene, 1, method="cg")
    from anisofem.reduced import ReducedModel
    held = af.Scene(mesh, af.Material(1e5, 0.45, 1000.0), fixed=mesh.vertices[:, 0] < 1e-9,
                    contact=af.Contact([block]))
    with pytest.raises(ValueError, match="capsules and itself, not surface obstacles; step it "
                                         "with the FEM"):
        ReducedModel(held, modes=4)
    with pytest.raises(ValueError, match="block: triangles index vertices 0 to 7"):
        af.Surface(block.vertices, [[0, 1, 8]], name="block")
    af.write_mesh(str(tmp_path / "beam.vtu"), mesh)
    with pytest.raises(ValueError, match="holds no triangles"):
        af.read_surface(str(tmp_path / "beam.vtu"))
    with pytest.raises(FileNotFoundError, match="no such surface file"):
        af.read_surface(str(tmp_path / "bowl.stl"))


def test_a_scene_file_takes_a_surface_from_a_file(beam_file):
    """[contact.obstacles.NAME] surface = {file = ...}: the triangles read from an .stl next
    to the scene file, its friction its own; a missing file in one line."""
    pytest.importorskip("ipctk")
    import meshio
    block = box_surface((0.05, 0.0, -0.03), (0.02, 0.05, 0.005))
    meshio.write(str(beam_file / "block.stl"), meshio.Mesh(block.vertices,
                                                           [("triangle", block.triangles)]))
    (beam_file / "surface.toml").write_text(SCENE.format(
        extra="", ball='surface = {file = "block.stl"}'))
    scene = af.load_scene(str(beam_file / "surface.toml"))
    ground, ball = scene.contact.obstacles
    assert (ball.kind, ball.name, ball.friction) == ("surface", "ball", 0.1)
    assert np.allclose(np.sort(ball.vertices, axis=0), np.sort(block.vertices, axis=0))
    from anisofem.io.scenefile import SceneFileError
    (beam_file / "missing.toml").write_text(SCENE.format(
        extra="", ball='surface = {file = "bowl.stl"}'))
    with pytest.raises(SceneFileError, match=r"contact.obstacles.ball.surface.file: no such "
                                             r"surface file"):
        af.load_scene(str(beam_file / "missing.toml"))


def test_a_surface_moved_along_a_curve_pushes_the_body():
    """A surface block lifted 16 mm over 0.32 s under the beam held at one end: every step it
    reaches where its curve puts it, the beam is pushed up over it, and no point any solve
    evaluated intersects the block where that solve had it (ipctk; the block moves into where
    the step began, and each solve starts from where the last push left the beam)."""
    pytest.importorskip("ipctk")
    mesh, material = body("beam")
    low = mesh.vertices[:, 2].min()
    block = box_surface((0.15, 0.0, low - 0.006), (0.02, 0.05, 0.005))
    scene = af.Scene(mesh, material, gravity=(0, 0, -9.81), fixed=mesh.vertices[:, 0] < 1e-9,
                     contact=af.Contact([block]))
    lifted = scene.following([Timed(af.LoadCurve([0, 0.32], [0, 1]),
                                    obstacle=("block", (0, 0, 0.016)))])
    seen, evaluate = [], Potential.energy_gradient

    def watched(potential, x):
        pairs = potential.contact.itself
        seen.append(bool(pairs.ipctk.has_intersections(pairs.mesh, pairs.vertices(x))))
        return evaluate(potential, x)
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(Potential, "energy_gradient", watched)
        roll = af.simulate(lifted, 16, dt=0.02, warn=False)
    assert roll.converged and len(seen) > 16 and not any(seen)
    for k in range(1, 17):
        wanted = lifted.at(k * 0.02).contact.obstacles[0].position
        assert np.allclose(roll.obstacles[k, 0], wanted, atol=1e-12), k
    tip = mesh.vertices[:, 0] > 0.2 - 1e-9
    assert roll.positions[-1][tip, 2].min() > mesh.vertices[tip, 2].min() + 0.01


@pytest.fixture(scope="module")
def gripping():
    """The gripper's reduced model (2 modes) after 25 steps of its grip: the fingers on the
    box."""
    pytest.importorskip("ipctk")
    from anisofem.io.scenefile import SceneFile
    from anisofem.reduced import ReducedModel
    read = SceneFile(os.path.join(os.path.dirname(__file__), os.pardir, "examples", "scenes",
                                  "gripper.toml"))
    model = ReducedModel(read.scene.at(0.0), modes=2, validate=False)
    q, v = np.zeros(model.r), np.zeros(model.r)
    for k in range(1, 26):
        q, v, report = model.step(q, v, 0.01, controls=read.scene.at(0.01 * k).control_values)
        assert report.converged, report
    box = np.unique(read.scene.mesh.tets[read.region("box")])
    return model, q, box


def test_near_pairs_are_ipctks_pairs(gripping):
    """The few pairs NearPairs keeps give the barrier's energy, gradient and Hessian and the
    collision-free share of ipctk's search over the whole surface, exactly."""
    from anisofem.physics.self_contact import NearPairs, SelfContact, collision_mesh
    model, q, _ = gripping
    term = model.contact.term
    x = model.positions(q)
    near = NearPairs(collision_mesh(model.scene.mesh)[0], term.dhat, 4 * term.dhat)
    whole, few = (SelfContact(model.scene.mesh, term.dhat, term.kappa, near=n)
                  for n in (None, near))
    assert 0 < whole.nearest(x) < term.dhat, "the fingers press on the box"
    g_whole, g_few = np.zeros_like(x), np.zeros_like(x)
    assert few.energy(x, g_few) == whole.energy(x, g_whole) > 0
    assert np.array_equal(g_few, g_whole)
    assert abs(few.hessian(x) - whole.hessian(x)).max() == 0
    assert len(near.found) < 0.1 * len(whole.collisions(whole.vertices(x))) + 1000
    rng = np.random.default_rng(3)
    for scale in (1e-5, 1e-4, 3e-3):   # within the margin (0.4 mm), and beyond it
        dx = (model.basis @ rng.normal(size=model.r)).reshape(-1, 3)
        dx *= scale / np.abs(dx).max()
        exact, share = whole.max_step(x, dx), few.max_step(x, dx)
        if scale < 2e-4:
            assert share == pytest.approx(exact, rel=1e-9)
        else:   # as far as the pairs found hold
            assert 0.05 < share <= exact


def test_a_free_body_moves_rigidly_in_the_basis(gripping):
    """The box, a part of the mesh with no held vertex, translates exactly in the basis (its
    rigid motions are columns) and its translation strains nothing."""
    model, _, box = gripping
    for axis in range(3):
        u = np.zeros((model.scene.mesh.n_vertices, 3))
        u[box, axis] = 1e-3
        q, *_ = np.linalg.lstsq(model.basis, u.ravel(), rcond=None)
        assert np.abs(model.basis @ q - u.ravel()).max() < 1e-12
        assert abs(model.polynomial.energy(q)) < 1e-12 * model.polynomial.energy(
            np.linalg.norm(q) * np.eye(model.r)[-1])


def test_a_reduced_model_with_self_contact_is_not_exported(gripping, tmp_path):
    from export.writers.reduced import write
    model, *_ = gripping
    with pytest.raises(ValueError, match="model: the runtimes take contact with planes, "
                                         "spheres, boxes and capsules, not self-contact"):
        write(model, str(tmp_path / "gripper.npz"))
    with pytest.raises(ValueError, match="carried"):
        model.step(np.zeros(model.r), np.zeros(model.r), 0.01, carried=(0, 0, 0))


def test_reduced_self_contact_derivatives_match_central_differences(gripping):
    """The subspace self-contact's reduced gradient and Hessian (barrier and lagged friction
    of the fingers on the box) match central differences of its energy along random reduced
    directions."""
    model, q, _ = gripping
    rng = np.random.default_rng(11)
    q_lag = q - 1e-6 * rng.normal(size=model.r)
    *_, pairs = model.contact.touching(q_lag, 0.01)
    assert pairs.term.friction is not None, "the fingers touch the box: friction is lagged"
    g = pairs.gradient(q)
    H, _ = pairs.hessian(q)
    for _ in range(3):
        p = rng.normal(size=model.r)
        p *= 1e-3 / np.abs(model.basis @ p).max()     # a direction moving nodes up to 1 mm
        h = 1e-5
        slope = (pairs.energy(q + h * p) - pairs.energy(q - h * p)) / (2 * h)
        assert slope == pytest.approx(float(g @ p), rel=1e-5)
        change = (pairs.gradient(q + h * p) - pairs.gradient(q - h * p)) / (2 * h)
        assert np.abs(change - H @ p).max() <= 1e-4 * np.abs(H @ p).max()


def test_a_free_body_asks_for_rollouts_not_a_static_check():
    pytest.importorskip("ipctk")
    from anisofem.io.scenefile import SceneFile
    from anisofem.reduced import ReducedModel
    read = SceneFile(os.path.join(os.path.dirname(__file__), os.pardir, "examples", "scenes",
                                  "gripper.toml"))
    with pytest.raises(ValueError, match="validate: the scene has a part no held vertex "
                                         "holds, whose static equilibrium is not unique"):
        ReducedModel(read.scene.at(0.0), modes=2)
