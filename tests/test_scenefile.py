"""Scene files (anisofem.io.scenefile): regions and their materials, fiber fields, boundary
conditions on named surfaces, sides and boxes, pressure, load curves in time, the example
scenes, the schema's page and the refusals (each one line, CLI exit 2)."""
import os
import subprocess
import sys
import textwrap

import meshio
import numpy as np
import pytest

import anisofem as af
from anisofem.io import scene_schema
from anisofem.io.meshes import write_tagged_mesh
from anisofem.physics.meshgen import box_beam, tube

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCENES = os.path.join(ROOT, "examples", "scenes")


def two_halves(folder, fibers=None):
    """A 0.04 m bar in two physical volumes ("soft" x < 0.02, "stiff" beyond), its ends the
    physical surfaces "base" and "end", written to folder/bar.msh; with fibers, to
    folder/bar.vtu with the cell field "fibers" (groups by number: 1, 2; 3, 4)."""
    mesh = box_beam((0.04, 0.01, 0.01), (8, 2, 2))
    X, faces = mesh.vertices, mesh.boundary_faces
    volumes = np.where(X[mesh.tets].mean(axis=1)[:, 0] < 0.02, 1, 2)
    x = X[faces][:, :, 0]
    surfaces = {3: faces[(x < 1e-12).all(axis=1)], 4: faces[(x > 0.04 - 1e-12).all(axis=1)]}
    if fibers is None:
        write_tagged_mesh(folder / "bar.msh", mesh, volumes, surfaces,
                          {"soft": 1, "stiff": 2, "base": 3, "end": 4})
    else:
        write_tagged_mesh(folder / "bar.vtu", mesh, volumes, surfaces,
                          cell_data={"fibers": fibers})
    return mesh, volumes


def scene_file(folder, text, name="scene.toml"):
    path = folder / name
    path.write_text(textwrap.dedent(text))
    return path


BAR = """
    mesh = "bar.msh"
    gravity = [0, 0, -9.81]
    [material]
    young = 1e5
    fiber_stiffness = 2e5
    fiber = [1, 0, 0]
    [regions.stiff]
    young = 4e5
    law = "neohookean"
    fiber = [0, 0, 2]
    [[boundary]]
    where = "base"
    held = true
    """


def test_two_physical_volumes_get_two_materials(tmp_path):
    mesh, volumes = two_halves(tmp_path)
    scene = af.load_scene(scene_file(tmp_path, BAR))
    el = scene.elements
    stiff = volumes == 2
    assert 0 < stiff.sum() < mesh.n_tets
    E = el.mu * (3 * el.lam + 2 * el.mu) / (el.lam + el.mu)
    assert np.allclose(E[stiff], 4e5) and np.allclose(E[~stiff], 1e5)
    assert np.array_equal(el.model[stiff] == 1, np.ones(stiff.sum(), bool))
    assert (el.model[~stiff] == 0).all()
    assert np.allclose(el.fiber[stiff], [0, 0, 1]) and np.allclose(el.fiber[~stiff], [1, 0, 0])
    held = np.flatnonzero(scene.fixed_mask.all(axis=1))
    assert np.allclose(mesh.vertices[held, 0], 0.0) and held.size == 9
    assert np.allclose(scene.gravity, [0, 0, -9.81])
    assert af.solve(scene).converged


def test_fiber_field_from_cell_data_round_trips_through_vtu(tmp_path):
    """A per-tet fiber field in the mesh file reaches the elements (normalized, with a warning
    where not unit), and write_mesh's .vtu gives it back."""
    mesh = box_beam((0.04, 0.01, 0.01), (8, 2, 2))
    rng = np.random.default_rng(0)
    field = rng.standard_normal((mesh.n_tets, 3))
    two_halves(tmp_path, fibers=field)
    text = (BAR.replace('fiber = [1, 0, 0]', 'fiber = {cell_data = "fibers"}')
            .replace('fiber = [0, 0, 2]\n', '').replace("bar.msh", "bar.vtu")
            .replace("stiff]", '"2"]').replace('"base"', '"3"'))
    with pytest.warns(UserWarning, match="not unit length.*normalized"):
        scene = af.load_scene(scene_file(tmp_path, text))
    unit = field / np.linalg.norm(field, axis=1, keepdims=True)
    assert np.allclose(scene.elements.fiber, unit, atol=1e-12)
    af.write_mesh(tmp_path / "out.vtu", scene.mesh, scene.mesh.vertices, scene)
    back = meshio.read(tmp_path / "out.vtu").cell_data["fiber_direction"][0]
    assert np.allclose(back, scene.elements.fiber, atol=1e-12)


def test_fiber_field_refusals(tmp_path):
    mesh = box_beam((0.04, 0.01, 0.01), (8, 2, 2))
    field = np.tile([1.0, 0.0, 0.0], (mesh.n_tets, 1))
    field[5] = 0.0
    two_halves(tmp_path, fibers=field)
    text = (BAR.replace('fiber = [1, 0, 0]', 'fiber = {cell_data = "fibers"}')
            .replace("bar.msh", "bar.vtu").replace("stiff]", '"2"]').replace('"base"', '"3"'))
    with pytest.raises(ValueError, match=r"material.fiber.cell_data: zero or NaN direction at "
                                         r"tet 5"):
        af.load_scene(scene_file(tmp_path, text))
    two_halves(tmp_path, fibers=np.ones((mesh.n_tets, 2)))
    with pytest.raises(ValueError, match=r"one 3-vector per tet"):
        af.load_scene(scene_file(tmp_path, text))
    with pytest.raises(ValueError, match=r"no cell field 'fibres'; it has: fibers"):
        af.load_scene(scene_file(tmp_path, text.replace('"fibers"', '"fibres"')))


def test_helix_fibers(tmp_path):
    """A helix about z: each tet's fiber makes the winding angle with the axis, lies in the
    plane of the axis and the circumferential direction, changes linearly from angle to
    angle_end along the axis, and alternates sign when crossed."""
    mesh = tube(0.01, 0.02, 0.04, (2, 8, 8), sweep=360.0)
    write_tagged_mesh(tmp_path / "tube.msh", mesh)
    text = """
        mesh = "tube.msh"
        [material]
        fiber_stiffness = 1e5
        fiber = {helix = {axis = [0, 0, 2], angle = 80, angle_end = 40}}
        [[boundary]]
        where = "z-min"
        held = true
        """
    scene = af.load_scene(scene_file(tmp_path, text))
    d = scene.elements.fiber
    c = mesh.vertices[mesh.tets].mean(axis=1)
    radial = c * [1, 1, 0]
    radial /= np.linalg.norm(radial, axis=1, keepdims=True)
    share = (c[:, 2] - c[:, 2].min()) / np.ptp(c[:, 2])
    expected = np.radians(80 - 40 * share)
    assert np.allclose(d[:, 2], np.cos(expected), atol=1e-12)
    assert np.abs(np.sum(d * radial, axis=1)).max() < 1e-12
    crossed = af.load_scene(scene_file(tmp_path, text.replace("angle_end = 40",
                                                              "crossed = true")))
    twist = np.cross(radial, crossed.elements.fiber)[:, 2]
    assert (twist[0::2] > 0).all() and (twist[1::2] < 0).all()


def test_pressure_and_rollers_from_a_scene_file_match_the_api(tmp_path):
    """The quarter tube of test_pressure, from a scene file: rollers by box, pressure on a
    named surface; the same equilibrium as built in Python."""
    mesh = tube(0.01, 0.02, 0.005, (2, 8, 1))
    inner = mesh.faces_where(lambda c: np.hypot(c[:, 0], c[:, 1]) < 0.015)
    write_tagged_mesh(tmp_path / "tube.msh", mesh, surfaces={7: inner}, names={"cavity": 7})
    text = """
        mesh = "tube.msh"
        [material]
        poisson = 0.3
        [[boundary]]
        where = {box = [[0, -1, -1], [0, 1, 1]]}
        held = ["x"]
        [[boundary]]
        where = "y-min"
        held = ["y"]
        [[boundary]]
        where = {box = [[-1, -1, -1], [1, 1, 1]]}
        held = ["z"]
        [[boundary]]
        where = "cavity"
        pressure = 2e3
        """
    scene = af.load_scene(scene_file(tmp_path, text))
    X = mesh.vertices
    fixed = np.zeros((mesh.n_vertices, 3), bool)
    fixed[np.abs(X[:, 0]) < 1e-12, 0] = True
    fixed[np.abs(X[:, 1]) < 1e-12, 1] = True
    fixed[:, 2] = True
    api = af.Scene(mesh, af.Material(1e5, 0.3), fixed=fixed, pressure=af.Pressure(inner, 2e3))
    assert np.array_equal(scene.fixed_mask, api.fixed_mask)
    assert np.allclose(af.solve(scene).x, af.solve(api).x, rtol=0, atol=1e-12)


def test_load_curves_and_prescribed_rotation(tmp_path):
    """A traction on a curve is scaled by it at each time, a rotation on a curve turns by the
    curve's share of the angle (on the arc, not the chord), statics take both as written, and
    a rollout follows the curve to the static answer."""
    two_halves(tmp_path)
    text = BAR + """
        [[boundary]]
        where = "end"
        traction = [0, 0, -300]
        curve = "ramp"
        [[boundary]]
        where = "x-max"
        held = ["x"]
        rotation = {axis = [0, 0, 1], origin = [0.04, 0, 0], angle = 10}
        curve = "ramp"
        [curves.ramp]
        times = [0, 0.2]
        values = [0, 1]
        """
    scene = af.load_scene(scene_file(tmp_path, text))
    X = scene.mesh.vertices
    end = np.flatnonzero(X[:, 0] > 0.04 - 1e-12)
    half = scene.at(0.1)
    f_full = scene.external_force - scene.at(0.0).external_force
    assert np.allclose(half.external_force - scene.at(0.0).external_force, 0.5 * f_full)
    arm = X[end] - [0.04, 0, 0]
    for t, degrees in ((0.1, 5.0), (0.3, 10.0)):
        a = np.radians(degrees)
        turned = arm[:, 0] * np.cos(a) - arm[:, 1] * np.sin(a) + 0.04
        assert np.allclose(scene.at(t).fixed_positions[end, 0], turned, atol=1e-15)
    assert np.allclose(scene.fixed_positions[end, 0],
                       arm[:, 0] * np.cos(np.radians(10)) - arm[:, 1] * np.sin(np.radians(10))
                       + 0.04)
    rollout = af.simulate(scene, 40, 0.02)
    static = af.solve(scene)
    assert rollout.converged and static.converged
    assert np.abs(rollout.positions[-1] - static.x).max() < 0.02 * np.abs(static.x - X).max()


@pytest.mark.parametrize("change, message", [
    (("young = 1e5", "yung = 1e5"), r"material.yung: unknown key; did you mean 'young'\?"),
    (("[regions.stiff]", "[regions.hard]"),
     r"regions.hard: the mesh has no physical volume 'hard'; it has: soft, stiff"),
    (('where = "base"', 'where = "bottom"'),
     r"boundary\[0\].where: the mesh has no physical surface 'bottom'; it has: base, end"),
    (('mesh = "bar.msh"', 'mesh = "nowhere.msh"'), r"mesh: no such file 'nowhere.msh'"),
    (("held = true", "held = true\ncurve = \"c\"\n[curves.c]\ntimes = [0, 1, 1]\n"
                     "values = [0, 1, 2]"), r"curves.c: times must increase, got 1 then 1"),
    (("held = true", 'pressure = 1e3'),
     r"boundary: pressure faces: the surface is not closed, and its rim vertex \d+ is free"),
    (("held = true", "held = [\"w\"]"), r"boundary\[0\].held: true or a list of axes"),
    (("law = \"neohookean\"", "law = \"rubber\""), r"regions.stiff.law: expected stvk or "
                                                     r"neohookean"),
])
def test_bad_scene_files_say_what_and_where(tmp_path, change, message):
    two_halves(tmp_path)
    text = textwrap.dedent(BAR).replace(*change)
    if "pressure" in change[1]:  # the end face, open, its rim free: base held only
        text = textwrap.dedent(BAR) + '[[boundary]]\nwhere = "end"\npressure = 1e3\n'
    path = scene_file(tmp_path, text)
    with pytest.raises(ValueError, match=message):
        af.load_scene(path)
    r = subprocess.run([sys.executable, "-m", "anisofem", "solve", str(path), "-o",
                        str(tmp_path / "x.vtu")], capture_output=True, text=True, cwd=ROOT)
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1, r.stderr


def test_cli_takes_scene_files_and_refuses_flags_they_set(tmp_path):
    two_halves(tmp_path)
    path = scene_file(tmp_path, BAR)
    r = subprocess.run([sys.executable, "-m", "anisofem", "solve", str(path), "-o",
                        str(tmp_path / "x.vtu")], capture_output=True, text=True, cwd=ROOT)
    assert r.returncode == 0 and "converged: True" in r.stdout, r.stderr
    assert meshio.read(tmp_path / "x.vtu").point_data["displacement"][:, 2].min() < -1e-4
    r = subprocess.run([sys.executable, "-m", "anisofem", "solve", str(path), "--kappa", "3",
                        "-o", str(tmp_path / "x.vtu")], capture_output=True, text=True,
                       cwd=ROOT)
    assert r.returncode == 2 and "--kappa: the scene file" in r.stderr


def test_example_meshes_are_what_the_generator_writes(tmp_path):
    """The committed meshes of examples/scenes equal make_meshes.py's."""
    sys.path.insert(0, SCENES)
    try:
        import make_meshes
    finally:
        sys.path.remove(SCENES)
    for name, make in make_meshes.MESHES.items():
        write_tagged_mesh(tmp_path / name, *make())
        ours, theirs = (af.io.read_tagged_mesh(p) for p in (tmp_path / name,
                                                            os.path.join(SCENES, name)))
        assert np.array_equal(ours[0].vertices, theirs[0].vertices)
        assert np.array_equal(ours[0].cells, theirs[0].cells)
        assert np.array_equal(ours[1].volumes, theirs[1].volumes)
        assert ours[1].names == theirs[1].names


def test_schema_page_is_generated_from_the_code():
    with open(os.path.join(ROOT, "docs", "scenes.md")) as f:
        page = f.read()
    assert scene_schema.schema_markdown() in page


def test_readme_scene_file_loads(tmp_path):
    """The README's scene file, next to the example actuator's mesh, is a scene."""
    import re
    import shutil
    with open(os.path.join(ROOT, "README.md")) as f:
        block, = re.findall(r"```toml\n(.*?)```", f.read(), flags=re.S)
    shutil.copy(os.path.join(SCENES, "actuator.msh"), tmp_path / "actuator.msh")
    scene = af.load_scene(scene_file(tmp_path, block))
    assert scene.pressures[0].magnitude == 2.0e4 and scene.fixed_mask.any()
    # the whole example (examples/actuator.py inflates it without turning an element inside
    # out): the same materials, fibers, held vertices and cavity tet by tet
    example = af.load_scene(os.path.join(SCENES, "actuator.toml"))
    m = scene.mesh.n_tets
    for key in ("young", "poisson", "density", "fiber_stiffness"):
        assert np.array_equal(np.broadcast_to(getattr(scene.material, key), m),
                              np.broadcast_to(getattr(example.material, key), m)), key
    assert np.allclose(scene.material.fiber_direction, example.material.fiber_direction)
    assert np.array_equal(scene.fixed_mask, example.fixed_mask)
    assert np.array_equal(scene.pressures[0].nodes, example.pressures[0].nodes)


def test_named_surfaces_hold_midside_nodes_on_quadratic_tets(tmp_path):
    """order = 2 raises the file's linear tets; a surface named in the file then holds its
    faces' midside nodes too, as the side rule does."""
    two_halves(tmp_path)
    by_name = af.load_scene(scene_file(tmp_path, BAR.replace('gravity', 'order = 2\ngravity')))
    by_side = af.load_scene(scene_file(tmp_path, BAR.replace('gravity', 'order = 2\ngravity')
                                       .replace('"base"', '"x-min"'), "side.toml"))
    assert by_name.mesh.order == 2
    assert np.array_equal(by_name.fixed_mask, by_side.fixed_mask)
    assert by_name.fixed_mask.all(axis=1).sum() == 25   # 3 x 3 corners and 16 midside nodes


def test_solve_ramps_a_scene_file_into_a_series(tmp_path):
    """solve --ramp K: static answers at 1/K, ..., 1 of the loads, written as a ParaView
    collection whose last state is the whole load's answer."""
    two_halves(tmp_path)
    path = scene_file(tmp_path, BAR)
    r = subprocess.run([sys.executable, "-m", "anisofem", "solve", str(path), "--ramp", "3",
                        "-o", str(tmp_path / "out" / "ramp.pvd")], capture_output=True,
                       text=True, cwd=ROOT)
    assert r.returncode == 0, r.stderr
    assert r.stdout.count("of the loads:") == 3
    files = sorted((tmp_path / "out").glob("ramp_*.vtu"))
    assert len(files) == 4 and "ramp_0003.vtu" in (tmp_path / "out" / "ramp.pvd").read_text()
    scene = af.load_scene(path)
    last = meshio.read(files[-1]).point_data["displacement"]
    assert np.allclose(last, af.solve(scene).x - scene.mesh.vertices, atol=1e-9)
