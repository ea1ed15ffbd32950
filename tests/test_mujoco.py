"""The soft body as a MuJoCo plugin (export/mujoco.py, export/c/mujoco_plugin.c): it steps a
model file as the C runtime does, rides the body that carries it, and bad input fails MuJoCo's
compilation with one line naming the file and the problem."""
import subprocess
import sys

import numpy as np
import pytest

import anisofem as af
from anisofem.reduced import FramedModel, ReducedModel
from export import native
from export.writers import reduced as writer

mujoco = pytest.importorskip("mujoco")
pytestmark = pytest.mark.skipif(native.compiler() is None, reason="no C compiler")

from export import mujoco as plugin  # noqa: E402

GRAVITY = np.array([0.0, 0.0, -9.81])


@pytest.fixture(scope="module", autouse=True)
def registered(tmp_path_factory):
    """The plugin built in a folder of its own and registered with MuJoCo."""
    return plugin.load_plugin(str(tmp_path_factory.mktemp("plugin")))


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """A 0.1 m beam held at x = 0, its reduced and its framed model written: (reduced path,
    framed path)."""
    folder = tmp_path_factory.mktemp("mujoco")
    mesh = af.box_beam(size=(0.1, 0.02, 0.02), cells=(8, 2, 2))
    scene = af.Scene(mesh, af.Material(1e5, 0.45, 1000.0),
                     fixed=af.metrics.end_vertices(mesh, 0, "min"), gravity=GRAVITY)
    reduced, framed = str(folder / "beam"), str(folder / "beam_framed")
    writer.write(ReducedModel(scene, modes=4, snapshots=8, validate=False), reduced)
    writer.write_framed(FramedModel(scene, validate=False), framed)
    return reduced, framed


def compiled(xml, dt):
    model = mujoco.MjModel.from_xml_string(xml)
    model.opt.gravity[:] = GRAVITY
    model.opt.timestep = dt
    return model, mujoco.MjData(model)


def alone(path, steps, dt, before_each=None):
    """The C runtime's (CModel, state) after `steps` steps of dt s from rest under gravity,
    stepping the file by itself; before_each(model, k) for k = 1 .. steps sets its inputs."""
    c = native.CModel(path)
    state = np.zeros(c.state_size)
    c._c.af_rest_state(c._handle, native._pointer(state))
    c.set_constant_force(c.masses[:, None] * GRAVITY)
    for k in range(1, steps + 1):
        if before_each is not None:
            before_each(c, k)
        c.advance(state, None, dt)
    return c, state


def test_the_plugin_steps_like_the_c_runtime(files):
    """The beam under gravity, its body fixed: after 500 MuJoCo steps of 0.02 s its state (500
    soft steps, each ahead over the MuJoCo step whose forces it computes) equals the C
    runtime's stepped alone, to 1e-9."""
    path, _ = files
    model, data = compiled(plugin.mjcf(path), 0.02)
    for _ in range(500):
        mujoco.mj_step(model, data)
    c, state = alone(path, 500, 0.02)
    soft = data.plugin_state[plugin.HEADER:]
    assert data.plugin_state[0] == pytest.approx(10.0)
    x, x_alone = c._positions(soft), c._positions(state)
    assert (x_alone - c.rest_positions)[:, 2].min() < -1e-3, "the beam sags"
    assert np.abs(x - x_alone).max() < 1e-9


def test_the_soft_body_steps_at_its_own_time_step(files):
    """MuJoCo at 0.002 s, the soft body at 0.01 s (config timestep): it steps every fifth
    MuJoCo step, as the C runtime alone at 0.01 s (1e-9 m after 100 soft steps)."""
    path, _ = files
    model, data = compiled(plugin.mjcf(path, timestep=0.01), 0.002)
    for _ in range(496):     # the 100th soft step is taken at t = 0.99 s
        mujoco.mj_step(model, data)
    c, state = alone(path, 100, 0.01)
    assert data.plugin_state[0] == pytest.approx(1.0)
    assert np.abs(c._positions(data.plugin_state[plugin.HEADER:])
                  - c._positions(state)).max() < 1e-9
    with pytest.raises(ValueError, match="timestep: expected a time step > 0 s, got '-1'"):
        mujoco.MjModel.from_xml_string(plugin.mjcf(path).replace(
            '<config key="substeps" value="1"/>',
            '<config key="substeps" value="1"/><config key="timestep" value="-1"/>'))


def test_a_framed_model_rides_its_body(files):
    """The framed beam on a body 0.5 m up spun about z at 2 rad/s: placed where the body
    starts, its held vertices are where the body carries them at the soft state's time (1e-12
    m), its free end swings behind."""
    _, path = files
    xml = plugin.mjcf(path, pos=(0.1, 0.2, 0.5)).replace(
        '<plugin instance="soft"/>', '<joint type="hinge" axis="0 0 1"/>'
        '<geom type="box" size="0.01 0.01 0.01" mass="0.5"/><plugin instance="soft"/>')
    model, data = compiled(xml, 0.01)
    data.qvel[0] = 2.0
    for _ in range(50):
        mujoco.mj_step(model, data)
    body = model.body("soft").id
    R, p = data.xmat[body].reshape(3, 3), data.xpos[body]   # at the soft state's time
    runtime = native.CModel(path)
    x = runtime._positions(data.plugin_state[plugin.HEADER:])
    held = runtime.held.all(axis=1)
    assert np.abs(x[held] - (runtime.rest_positions[held] @ R.T + p)).max() < 1e-12
    carried = runtime.rest_positions @ R.T + p
    assert 1e-4 < np.abs(x - carried).max() < 0.05


@pytest.mark.parametrize("change, says", [
    (lambda xml, path: xml.replace(path, path + "_missing"), "_missing.json"),
    (lambda xml, path: xml.replace('value="1"', 'value="0"'),
     "substeps: expected a whole number from 1 to 10000, got '0'"),
    (lambda xml, path: xml.replace('<plugin instance="soft"/>',
                                   '<freejoint/><geom size="0.01"/><plugin instance="soft"/>'),
     "is a reduced model, which moves with its body only by translation, on body 'soft', "
     "which can turn"),
    (lambda xml, path: xml.replace('<plugin instance="soft"/>', ''),
     "no body carries the instance")])
def test_bad_input_fails_compilation_in_one_line(files, change, says):
    path, _ = files
    with pytest.raises(ValueError, match="anisofem.soft: ") as error:
        mujoco.MjModel.from_xml_string(change(plugin.mjcf(path), path))
    assert says in str(error.value) and "\n" not in str(error.value)


def test_a_corrupt_file_fails_compilation_naming_it(files, tmp_path):
    path, _ = files
    (tmp_path / "broken.json").write_text("{not json")
    with pytest.raises(ValueError, match="broken.json: not complete JSON"):
        mujoco.MjModel.from_xml_string(plugin.mjcf(str(tmp_path / "broken")))
    with open(path + ".json") as f:
        header = f.read()
    (tmp_path / "short.json").write_text(header.replace('"beam.bin"', '"short.bin"'))
    (tmp_path / "short.bin").write_bytes(b"\0" * 10)
    with pytest.raises(ValueError, match=r"anisofem.soft: .*short.json: array \w+ .* runs "
                                         r"past the end of the 10-byte .bin file"):
        mujoco.MjModel.from_xml_string(plugin.mjcf(str(tmp_path / "short")))


def test_the_command_prints_mjcf_that_compiles(files):
    path, _ = files
    run = [sys.executable, "-m", "export", "mujoco"]
    done = subprocess.run(run + [path, "--body", "hand"], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert '<body name="hand"' in done.stdout
    mujoco.MjModel.from_xml_string(done.stdout)
    done = subprocess.run(run + [path + "_missing"], capture_output=True, text=True)
    assert done.returncode == 2 and "_missing.json" in done.stderr
    assert len(done.stderr.strip().splitlines()) == 1


def test_a_framed_state_is_carried_rigidly(files):
    """af_carry_state moves a framed rest state's every vertex by the base (1e-12 m); a reduced
    model takes the identity only, and a base that is not rigid is refused."""
    reduced, framed = files
    c = native.CModel(framed)
    state = np.zeros(c.state_size)
    c._c.af_rest_state(c._handle, native._pointer(state))
    turn = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    shift = np.array([0.1, 0.2, 0.5])
    base = np.concatenate([turn.ravel(), shift])
    assert c._c.af_carry_state(c._handle, native._pointer(state), native._pointer(base)) == 0
    assert np.abs(c._positions(state) - (c.rest_positions @ turn.T + shift)).max() < 1e-12
    bent = base.copy()
    bent[0] = 1.5
    assert c._c.af_carry_state(c._handle, native._pointer(state), native._pointer(bent)) < 0
    assert b"not a rigid motion" in c._c.af_error(c._handle)
    r = native.CModel(reduced)
    flat = np.zeros(r.state_size)
    assert r._c.af_carry_state(r._handle, native._pointer(flat), native._pointer(base)) < 0
    assert b"only a framed model is carried" in r._c.af_error(r._handle)



@pytest.mark.parametrize("integrator, every", [("Euler", 1), ("implicitfast", 1),
                                               ("implicitfast", 4)])
def test_a_free_body_and_its_soft_body_keep_their_momentum(files, integrator, every):
    """No gravity: a free sphere carrying the framed beam, pushed and spun. The soft body pulls
    its carrier by the carrier's impulse on it (its momentum's change), so the two together
    keep their linear and angular momentum (about the origin) to 1e-6 over 1,000 steps, while
    the soft body carries a quarter of the one and most of the other; also where the soft body
    steps every fourth MuJoCo step (its pull spread over the four)."""
    _, path = files
    xml = plugin.mjcf(path, timestep=0.005 * every).replace(
        '<plugin instance="soft"/>', '<freejoint/><geom type="sphere" size="0.02" mass="0.2"/>'
        '<plugin instance="soft"/>').replace(
        "<worldbody>", f'<option integrator="{integrator}" gravity="0 0 0"/><worldbody>')
    model = mujoco.MjModel.from_xml_string(xml)
    model.opt.timestep = 0.005
    data = mujoco.MjData(model)
    data.qvel[:] = [0.05, -0.02, 0.01, 0.5, 1.0, 2.0]
    body, runtime = model.body("soft").id, native.CModel(path)
    half = runtime.state_size // 2

    def momenta():   # the rigid body's at its time, the soft body's a step before (its state)
        R = data.xmat[body].reshape(3, 3)
        inertia = R @ np.diag(model.body_inertia[body]) @ R.T
        v, w = data.qvel[:3], R @ data.qvel[3:6]
        state = data.plugin_state[plugin.HEADER:]
        x = runtime._positions(state)
        u = (x - runtime._positions(state[half:])) / (0.005 * every)
        mu = runtime.masses[:, None] * u
        rigid = np.concatenate([model.body_mass[body] * v, model.body_mass[body]
                                * np.cross(data.qpos[:3], v) + inertia @ w])
        return rigid, np.concatenate([mu.sum(axis=0), np.cross(x, mu).sum(axis=0)])

    mujoco.mj_step(model, data)
    start = sum(momenta())
    for _ in range(1000 + every - 1):   # to where the last soft step's pull is all applied
        mujoco.mj_step(model, data)
    rigid, soft = momenta()
    for part in (slice(0, 3), slice(3, 6)):
        assert np.linalg.norm((rigid + soft - start)[part]) <= 1e-6 * np.linalg.norm(start[part])
    assert np.linalg.norm(soft[:3]) > 0.2 * np.linalg.norm(start[:3])
    assert np.linalg.norm(soft[3:]) > 0.5 * np.linalg.norm(start[3:])


def test_the_hinges_reaction_is_the_swinging_soft_bodys_momentum_change(files):
    """The framed beam (40 g) on a 50 g ball hinged to the world at its centre (two connect
    constraints on the y axis: MuJoCo's constraint solver finds the hinge's force) swings down
    under gravity. Every step the hinge's force on the ball (qfrc_constraint) is what the ball
    and the soft body together need: their momentum change (the soft body's from its states,
    over the step whose pull MuJoCo applied) less their weight's impulse, within 1%, the soft
    body's part (its momentum change less its weight) a third of the force or more."""
    _, path = files
    dt = 0.005
    xml = plugin.mjcf(path, pos=(0.0, 0.0, 0.5)).replace(
        '<plugin instance="soft"/>', '<freejoint/><geom type="sphere" size="0.02" mass="0.05" '
        'contype="0" conaffinity="0"/><plugin instance="soft"/>').replace(
        "</worldbody>", '</worldbody><equality><connect body1="soft" anchor="0 0.02 0"/>'
        '<connect body1="soft" anchor="0 -0.02 0"/></equality>').replace(
        "<worldbody>", '<option integrator="Euler"/><worldbody>')
    model, data = compiled(xml, dt)
    runtime = native.CModel(path)
    half, mass = runtime.state_size // 2, runtime.masses[:, None]
    ball, soft_mass = model.body_mass[model.body("soft").id], runtime.masses.sum()

    def momentum():   # the soft body's, over its last step
        state = data.plugin_state[plugin.HEADER:]
        return (mass * (runtime._positions(state) - runtime._positions(state[half:]))
                ).sum(axis=0) / dt

    mujoco.mj_step(model, data)
    soft, v = momentum(), data.qvel[:3].copy()
    worst, shares = 0.0, []
    for _ in range(200):
        mujoco.mj_step(model, data)
        hinge = data.qfrc_constraint[:3].copy()
        soft_now, v_now = momentum(), data.qvel[:3].copy()
        needed = (ball * (v_now - v) + soft_now - soft) / dt - (ball + soft_mass) * GRAVITY
        worst = max(worst, np.linalg.norm(hinge - needed) / np.linalg.norm(hinge))
        shares.append(np.linalg.norm((soft_now - soft) / dt - soft_mass * GRAVITY)
                      / np.linalg.norm(hinge))
        soft, v = soft_now, v_now
    assert worst < 0.01
    assert np.mean(shares) > 0.3
    turned = np.degrees(np.arccos(np.clip(data.xmat[model.body("soft").id][0], -1, 1)))
    assert turned > 10.0, f"the beam swung down {turned} degrees"


def test_rk4_is_refused(files):
    path, _ = files
    xml = plugin.mjcf(path).replace("<worldbody>", '<option integrator="RK4"/><worldbody>')
    with pytest.raises(ValueError, match="anisofem.soft: the RK4 integrator"):
        mujoco.MjModel.from_xml_string(xml)


def actuated(path, names):
    """The MJCF of the file on a fixed body, with a plugin actuator named for each control."""
    actuators = "".join(f'<plugin name="{name}" instance="soft" site="here"/>' for name in names)
    return plugin.mjcf(path).replace(
        '<plugin instance="soft"/>', '<site name="here"/><plugin instance="soft"/>').replace(
        "</worldbody>", f"</worldbody><actuator>{actuators}</actuator>")


@pytest.fixture(scope="module")
def finger_file(tmp_path_factory):
    """The pneumatic finger of test_controls (controls push, curl, squeeze), its reduced model
    written."""
    from test_controls import finger
    path = str(tmp_path_factory.mktemp("finger") / "finger")
    writer.write(ReducedModel(finger(), modes=4, validate=False), path)
    return path


def test_the_controls_are_mujoco_actuators(files, finger_file):
    """The finger's three controls as plugin actuators, set every step from a curve (ctrl):
    500 soft steps equal the C runtime's under the same controls, to 1e-9 m."""
    from test_controls import controls_at
    model, data = compiled(actuated(finger_file, ("push", "curl", "squeeze")), 0.01)
    for k in range(501):
        data.ctrl[:] = controls_at(k)
        mujoco.mj_step(model, data)
    c, state = alone(finger_file, 500, 0.01, lambda c, k: c.set_controls(controls_at(k)))
    x, x_alone = c._positions(data.plugin_state[plugin.HEADER:]), c._positions(state)
    assert np.abs(x_alone - c.rest_positions).max() > 1e-3, "the controls move the finger"
    assert np.abs(x - x_alone).max() < 1e-9
    with pytest.raises(ValueError, match="actuator 'pull' names no control of .*finger .*its "
                                         "controls: push curl squeeze"):
        mujoco.MjModel.from_xml_string(actuated(finger_file, ("push", "pull")))


def test_the_soft_surface_is_drawn_in_mujocos_scene(files):
    """mjv_updateScene draws the soft surface as MuJoCo draws a flex: its faces (each two right
    triangles meeting at the foot of its height, their corners soft vertices, their areas the
    surface's, facing out) and its edges as lines (each once), at the soft body's positions;
    without the flex switches, neither."""
    path, _ = files
    model, data = compiled(plugin.mjcf(path, pos=(0.0, 0.0, 0.3)), 0.02)
    for _ in range(20):
        mujoco.mj_step(model, data)
    runtime = native.CModel(path)
    x = runtime._positions(data.plugin_state[plugin.HEADER:]) + [0.0, 0.0, 0.3]

    def drawn(option):
        scene = mujoco.MjvScene(model, maxgeom=5000)
        mujoco.mjv_updateScene(model, data, option, None, mujoco.MjvCamera(),
                               mujoco.mjtCatBit.mjCAT_ALL, scene)
        geoms = [scene.geoms[i] for i in range(scene.ngeom)]
        return ([g for g in geoms if g.type == mujoco.mjtGeom.mjGEOM_LINE],
                [g for g in geoms if g.type == mujoco.mjtGeom.mjGEOM_TRIANGLE])

    def nearest(points):    # the largest distance of a point from the soft vertices
        return np.abs(points[:, None, :] - x[None]).sum(axis=2).min(axis=1).max()

    lines, triangles = drawn(mujoco.MjvOption())
    edges = {tuple(sorted(pair)) for tri in runtime.surface
             for pair in ((tri[0], tri[1]), (tri[1], tri[2]), (tri[2], tri[0]))}
    assert len(lines) == len(edges)
    assert nearest(np.array([g.pos for g in lines])) < 1e-6
    assert len(triangles) == 2 * len(runtime.surface)
    frames = [np.array(g.mat).reshape(3, 3) for g in triangles]
    corners = np.array([g.pos + g.size[k] * R[:, k] for g, R in zip(triangles, frames)
                        for k in (0, 1)])
    assert nearest(corners) < 1e-6
    a, b, c = (x[runtime.surface[:, k]] for k in range(3))
    area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1).sum()
    assert sum(0.5 * g.size[0] * g.size[1] for g in triangles) == pytest.approx(area, rel=1e-6)
    outward = np.repeat(np.cross(b - a, c - a), 2, axis=0)    # each face's pair faces out
    assert all(R[:, 2] @ n > 0 for R, n in zip(frames, outward))
    option = mujoco.MjvOption()
    for flag in ("mjVIS_FLEXEDGE", "mjVIS_FLEXSKIN", "mjVIS_FLEXFACE"):
        option.flags[getattr(mujoco.mjtVisFlag, flag)] = 0
    assert drawn(option) == ([], [])


def test_a_geom_moves_the_obstacle_it_is_named_for(tmp_path):
    """The beam 1 cm over the ground with a ball under its tip (the file's obstacles "ground"
    and "ball"); in MuJoCo a mocap geom named "ball" rises 2 mm over 0.4 s: the ball follows
    it (where it is at each soft step's start), pushes the tip up, and the soft body equals
    the C runtime's with the ball moved alike (af_move_obstacle), to 1e-9 m."""
    beam = af.box_beam(size=(0.2, 0.02, 0.02), cells=(20, 2, 2))
    mesh = af.TetMesh(beam.vertices + [0, 0, 0.01 - beam.vertices[:, 2].min()], beam.tets)
    ball = af.Sphere((0.19, 0.0, 0.0015), 0.008, name="ball")
    scene = af.Scene(mesh, af.Material(1e5, 0.45, 1000.0), gravity=GRAVITY,
                     fixed=beam.vertices[:, 0] <= 1e-9,
                     contact=af.Contact([af.Plane(name="ground"), ball], friction=0.3))
    path = str(tmp_path / "beam")
    writer.write(ReducedModel(scene, modes=4, snapshots=6, validate=False), path)
    xml = plugin.mjcf(path, world='<body name="mover" mocap="true" pos="0.19 0 0.0015">'
                                  '<geom name="ball" type="sphere" size="0.008" '
                                  'contype="0" conaffinity="0"/></body>')
    model, data = compiled(xml, 0.02)
    rise = [np.array([0.19, 0.0, 0.0015 + 1e-4 * min(k, 20)]) for k in range(41)]
    for k in range(41):
        data.mocap_pos[0] = rise[k]
        mujoco.mj_step(model, data)

    def move_ball(c, k):
        assert c._c.af_move_obstacle(c._handle, 1, native._pointer(rise[k - 1])) == 0
    c, state = alone(path, 41, 0.02, move_ball)
    x, x_alone = c._positions(data.plugin_state[plugin.HEADER:]), c._positions(state)
    assert np.abs(x - x_alone).max() < 1e-9
    at = np.zeros(3)
    c._c.af_obstacle_position(c._handle, 1, native._pointer(at))
    assert np.allclose(at, rise[40])
    tip = beam.vertices[:, 0] >= 0.2 - 1e-9
    assert (x[tip, 2] - c.rest_positions[tip, 2]).mean() > 5e-4, "the ball lifts the tip"


@pytest.fixture(scope="module")
def box_file(tmp_path_factory):
    """The 0.1 m beam held at x = 0 with a 2 x 3 x 2 cm box (the file's obstacle "box") 0.5 mm
    over its tip, its reduced model written."""
    beam = af.box_beam(size=(0.1, 0.02, 0.02), cells=(10, 2, 2))
    box = af.Box((0.09, 0.0, 0.0205), (0.01, 0.015, 0.01), name="box")
    scene = af.Scene(beam, af.Material(1e5, 0.45, 1000.0), gravity=GRAVITY,
                     fixed=beam.vertices[:, 0] <= 1e-9, contact=af.Contact([box], friction=0.5))
    path = str(tmp_path_factory.mktemp("box") / "beam")
    writer.write(ReducedModel(scene, modes=6, snapshots=8, validate=False), path)
    return path


BOX_BODY = ('<body name="carton" pos="0.09 0 0.0205"><freejoint/><geom name="box" type="box" '
            'size="0.01 0.015 0.01" mass="0.005" contype="0" conaffinity="0"/></body>')


def cube_file(folder, x):
    """A stiff 0.1 m beam held at x = 0 with a 2 cm cube (the file's obstacle "box") 0.5 mm over
    it, centred at x (m), its reduced model written in folder; returns its path."""
    beam = af.box_beam(size=(0.1, 0.02, 0.02), cells=(10, 2, 2))
    cube = af.Box((x, 0.0, 0.0205), (0.01, 0.01, 0.01), name="box")
    scene = af.Scene(beam, af.Material(1e7, 0.45, 1000.0), gravity=GRAVITY,
                     fixed=beam.vertices[:, 0] <= 1e-9, contact=af.Contact([cube], friction=0.5))
    path = str(folder / f"cube{x}")
    writer.write(ReducedModel(scene, modes=6, snapshots=8, validate=False), path)
    return path


def cube_body(x):
    """A 5 g MuJoCo cube on a free joint whose geom is named as the file's obstacle "box"."""
    return (f'<body name="carton" pos="{x} 0 0.0205"><freejoint/><geom name="box" type="box" '
            'size="0.01 0.01 0.01" mass="0.005" contype="0" conaffinity="0"/></body>')


def test_a_free_body_geom_is_stepped_with_the_soft_body(tmp_path):
    """A 5 g MuJoCo cube on a free joint (its geom named as the file's obstacle) dropped onto a
    held beam: each soft step solves its move and turn with the beam's and MuJoCo moves it by
    the soft body's force and moment over the same step. Dropped mid-beam it lands and rests
    upright, pushed up by its weight (0.1%), within 0.1 mm of where the C runtime's free
    obstacle stepped alone (af_obstacle_motion, the same inertia) rests (how far it slides as
    it lands follows Newton's tolerance there: 30 um apart); dropped with its center over the
    beam's end it tips over the edge and falls off."""
    rest, edge = (cube_file(tmp_path, x) for x in (0.07, 0.1))
    model, data = compiled(plugin.mjcf(rest, world=cube_body(0.07)), 0.01)
    box = model.jnt_qposadr[model.body("carton").jntadr[0]]
    c = native.CReducedSimulator(rest)
    c.set_constant_force(c.masses[:, None] * GRAVITY)
    q, w = c.rest_state()
    c.set_obstacle_motion("box", 0.005, np.zeros(6), np.r_[GRAVITY, 0, 0, 0],
                          inertia=0.005 * 0.02 ** 2 / 6 * np.eye(3))
    for _ in range(200):
        mujoco.mj_step(model, data)
        c.step(q, w, None, 0.01, max_iter=500)
    x = c._positions(data.plugin_state[plugin.HEADER:])
    assert np.abs(x - c.positions(q)).max() < 1e-4
    assert np.abs(data.qpos[box:box + 3] - c.obstacle_position("box")).max() < 1e-4
    assert data.qpos[box + 3] > np.cos(np.radians(0.5) / 2), "it rests upright"
    assert np.abs(data.qvel[:6]).max() < 1e-3
    assert c.obstacle_wrench("box")[2] == pytest.approx(0.005 * 9.81, rel=1e-3)
    model, data = compiled(plugin.mjcf(edge, world=cube_body(0.1)), 0.01)
    turned = 0.0
    for _ in range(60):
        mujoco.mj_step(model, data)
        turned = max(turned, 2 * np.degrees(np.arccos(min(1.0, abs(data.qpos[box + 3])))))
    assert turned > 90.0 and data.qpos[box + 2] < -0.1, "it tipped over the edge and fell"


def test_a_free_capsule_rests_along_the_beam(tmp_path):
    """A 10 g MuJoCo capsule on a free joint (the file's obstacle "rod": its position is its
    end, MuJoCo's geom its middle) dropped along the top of the stiff held beam rests on its
    surface nodes (between two rows of them: 0.5 mm), its axis still along the beam (within 1
    degree), pushed up by its weight (0.1%)."""
    beam = af.box_beam(size=(0.1, 0.02, 0.02), cells=(10, 4, 4))
    rod = af.Capsule((0.04, 0.0, 0.0205), (0.08, 0.0, 0.0205), 0.01, name="rod")
    scene = af.Scene(beam, af.Material(1e7, 0.45, 1000.0), gravity=GRAVITY,
                     fixed=beam.vertices[:, 0] <= 1e-9, contact=af.Contact([rod], friction=0.5))
    path = str(tmp_path / "rod")
    writer.write(ReducedModel(scene, modes=6, snapshots=8, validate=False), path)
    body = ('<body name="stick" pos="0.06 0 0.0205"><freejoint/><geom name="rod" type="capsule" '
            'fromto="-0.02 0 0 0.02 0 0" size="0.01" mass="0.01" contype="0" '
            'conaffinity="0"/></body>')
    model, data = compiled(plugin.mjcf(path, world=body), 0.01)
    stick = model.body("stick").id
    for _ in range(200):
        mujoco.mj_step(model, data)
    assert np.abs(data.qvel[:6]).max() < 1e-3
    axis = data.xmat[stick].reshape(3, 3)[:, 0]
    assert axis[0] > np.cos(np.radians(1.0)), "it lies along the beam"
    assert 0.0195 < data.xipos[stick, 2] < 0.0202, "on the beam (its surface nodes), not in it"
    touched = data.plugin_state[plugin.TOUCHED + 2] / 0.01
    assert touched == pytest.approx(0.01 * 9.81, rel=1e-3), "the beam holds its weight"


@pytest.mark.parametrize("geom, says", [
    ('type="box" size="0.02 0.03 0.02"', "a box of half sizes 0.01 0.01 0.015 m, but is a box "
                                         "of half sizes 0.02 0.02 0.03 m"),
    ('type="sphere" size="0.01"', "a box of half sizes 0.01 0.01 0.015 m, but is a sphere "
                                  "(MJCF sizes are half extents)")])
def test_a_geom_of_another_shape_than_its_obstacle_is_refused(box_file, geom, says):
    """A geom named as the file's obstacle "box" but of other sizes (full extents for half) or
    another kind fails MuJoCo's compilation in one line saying both shapes."""
    world = BOX_BODY.replace('type="box" size="0.01 0.015 0.01"', geom)
    with pytest.raises(ValueError, match="anisofem.soft: geom 'box' is named as the obstacle "
                                         "of .*beam, ") as error:
        mujoco.MjModel.from_xml_string(plugin.mjcf(box_file, world=world))
    assert says in str(error.value) and "\n" not in str(error.value)


def test_a_carrier_the_soft_body_and_a_free_body_keep_their_momentum(box_file):
    """No gravity: the reduced beam (40 g) on a 100 g body free to translate (three slides),
    a 5 g box thrown down onto its tip at 0.3 m/s. The box's impulse bends the beam, the beam
    pulls its carrier: the three keep their linear momentum to 1e-6 of the box's over 300
    steps (the soft body counted at its state a step before, whose pull MuJoCo has applied,
    less the box's impulse on it since), and the carrier ends up moving."""
    slides = "".join(f'<joint name="{a}" type="slide" axis="{v}"/>'
                     for a, v in (("x", "1 0 0"), ("y", "0 1 0"), ("z", "0 0 1")))
    xml = plugin.mjcf(box_file, world=BOX_BODY).replace(
        '<plugin instance="soft"/>', f'{slides}<geom type="sphere" size="0.01" mass="0.1" '
        'contype="0" conaffinity="0"/><plugin instance="soft"/>').replace(
        "<worldbody>", '<option gravity="0 0 0"/><worldbody>')
    model = mujoco.MjModel.from_xml_string(xml)
    model.opt.timestep = 0.01
    data = mujoco.MjData(model)
    data.qvel[5] = -0.3                       # the box's: slides 0-2, then its free joint
    runtime = native.CModel(box_file)
    half, m = runtime.state_size // 2, runtime.masses[:, None]
    x0 = runtime.rest_positions
    carrier = 0.1

    def soft(state, u):      # the soft body's momentum: its carrier's velocity u and its own
        return (m * (u + runtime._positions(state[half:]) - x0)).sum(axis=0)

    start = 0.005 * data.qvel[3:6].copy()
    before = (data.plugin_state[plugin.HEADER:].copy(), data.qvel[:3].copy())
    for _ in range(300):
        mujoco.mj_step(model, data)
        last, before = before, (data.plugin_state[plugin.HEADER:].copy(), data.qvel[:3].copy())
    touched = data.plugin_state[plugin.TOUCHED:plugin.TOUCHED + 3]
    total = (carrier * data.qvel[:3] + 0.005 * data.qvel[3:6] + soft(*last) - touched)
    assert np.abs(total - start).max() < 1e-6 * np.abs(start).max()
    assert np.abs(data.qvel[:3]).max() > 1e-3


def test_without_mujoco_the_plugin_says_how_to_install_it(monkeypatch):
    monkeypatch.setitem(sys.modules, "mujoco", None)
    with pytest.raises(ImportError, match="pip install mujoco"):
        plugin.build_plugin()
