"""The C runtime (export/c): built with the system C compiler, it steps a reduced model like
runtime.ReducedSimulator to round-off in double precision, from Python through ctypes and
from a C program, and refuses files it cannot step."""
import json
import subprocess

import numpy as np
import pytest

from anisofem.reduced import ReducedModel
from export import native
from export import reduced as writer
from export.runtime import ReducedSimulator
from test_framed_model import cubature_model  # noqa: F401 (a fixture)
from test_framed_runtime import cubature_written, displayed, tip_drag  # noqa: F401 (fixtures)
from test_reduced import cantilever

pytestmark = pytest.mark.skipif(native.compiler() is None, reason="no C compiler")


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    folder = tmp_path_factory.mktemp("c")
    scene = cantilever(length=0.2)
    model = ReducedModel(scene, modes=4, snapshots=16, validate=False)
    path = str(folder / "long")
    writer.write(model, path, "long")
    return scene, path, native.build(str(folder / "lib"))


def test_c_steps_like_the_numpy_runtime_over_200_steps(built):
    """A drag that swings the 0.2 m beam sideways for 100 steps, then released: positions
    within 1e-9 of the deflection."""
    scene, path, lib = built
    py, c = ReducedSimulator(path), native.CReducedSimulator(path, lib)
    assert (c.n, c.r) == (scene.mesh.n_vertices, 20)
    drag = scene.external_force.copy()
    drag[np.argmax(scene.mesh.vertices[:, 0]), 1] += 0.2
    qp, wp = py.rest_state()
    qc, wc = c.rest_state()
    worst = size = 0.0
    for k in range(200):
        f = drag if k < 100 else scene.external_force
        qp, wp = py.step(qp, wp, f, 0.02)
        c.step(qc, wc, f, 0.02)
        assert c.iterations == py.iterations
        x = py.positions(qp)
        worst = max(worst, np.abs(c.positions(qc) - x).max())
        size = max(size, np.abs(x - scene.mesh.vertices).max())
    assert size > 0.05  # the tip swung by a quarter of the beam's length or more
    assert worst < 1e-9 * size


def test_a_constant_force_set_once_steps_like_passing_it_every_step(built):
    scene, path, lib = built
    every, once = (native.CReducedSimulator(path, lib) for _ in range(2))
    once.set_constant_force(scene.external_force)
    drag = np.zeros_like(scene.external_force)
    drag[np.argmax(scene.mesh.vertices[:, 0]), 2] = 0.3
    (qe, we), (qo, wo) = every.rest_state(), once.rest_state()
    for k in range(40):
        every.step(qe, we, scene.external_force + (drag if k < 20 else 0.0), 0.02)
        once.step(qo, wo, drag if k < 20 else None, 0.02)
    assert np.abs(qo).max() > 0 and np.abs(qo - qe).max() < 1e-9 * np.abs(qe).max()
    bad = scene.external_force.copy()
    bad[0, 0] = np.inf
    with pytest.raises(RuntimeError, match="bad input"):
        once.set_constant_force(bad)


def test_c_program_prints_the_runtime_rollout(built, tmp_path):
    scene, path, _ = built
    exe = tmp_path / "example"
    c_dir = native.SOURCE.rsplit("/", 1)[0]
    done = subprocess.run([native.compiler(), "-std=c99", "-O2", "-o", str(exe),
                           f"{c_dir}/example.c", native.SOURCE, "-lm"], capture_output=True,
                          text=True)
    assert done.returncode == 0, done.stderr
    out = subprocess.run([str(exe), path, "30", "0.02"], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    lowest = np.array(out.stdout.split(), dtype=float)
    py = ReducedSimulator(path)
    q, w = py.rest_state()
    force = py.masses[:, None] * np.array([0.0, 0.0, -9.81])
    expected = []
    for _ in range(30):
        q, w = py.step(q, w, force, 0.02)
        expected.append(py.positions(q)[:, 2].min())
    assert lowest.shape == (30,) and np.abs(lowest - expected).max() < 1e-12


def test_c_runtime_reads_a_file_of_several_fiber_angles(tmp_path, built):
    _, _, lib = built
    path = str(tmp_path / "baked")
    writer.bake("cantilever", path, modes=2, angles=[0, 45])
    for angle in (0, 45):
        py = ReducedSimulator(path, angle=angle)
        c = native.CReducedSimulator(path, lib, angle=f"{angle:g}")
        force = py.masses[:, None] * np.array([0.0, 0.0, -9.81])
        qp, wp = py.rest_state()
        qc, wc = c.rest_state()
        for _ in range(10):
            qp, wp = py.step(qp, wp, force, 0.02)
            c.step(qc, wc, force, 0.02)
        assert np.abs(c.positions(qc) - py.positions(qp)).max() < 1e-12


def test_c_runtime_refuses_other_files_and_bad_input(built, tmp_path):
    scene, path, lib = built
    with open(path + ".json") as f:
        header = json.load(f)
    header["model_format"] = "anisofem-reduced-0"
    old = tmp_path / "old"
    (tmp_path / "old.json").write_text(json.dumps({**header, "bin": "long.bin"}))
    (tmp_path / "long.bin").write_bytes(open(path + ".bin", "rb").read())
    with pytest.raises(ValueError, match="anisofem-reduced-0.*rebuild"):
        native.CReducedSimulator(str(old), lib)
    with pytest.raises(ValueError, match="cannot read"):
        native.CReducedSimulator(str(tmp_path / "missing"), lib)
    with pytest.raises(ValueError, match="no float64 array basis@30"):
        native.CReducedSimulator(path, lib, angle="30")
    c = native.CReducedSimulator(path, lib)
    q, w = c.rest_state()
    bad = scene.external_force.copy()
    bad[3, 1] = np.nan
    with pytest.raises(RuntimeError, match="bad input"):
        c.step(q, w, bad, 0.02)
    with pytest.raises(RuntimeError, match="bad input"):
        c.step(q, w, scene.external_force, 0.0)
    assert not q.any() and not w.any()


@pytest.fixture(scope="module")
def framed(tmp_path_factory, built):
    from anisofem.reduced import FramedModel
    from test_framed_model import t_scene
    scene = t_scene()
    path = str(tmp_path_factory.mktemp("framed") / "t")
    writer.write_framed(FramedModel(scene, validate=False), path, "t")
    return scene, path, built[2]


def test_c_steps_the_framed_model_like_the_numpy_runtime_over_200_steps(framed):
    """A drag of half the T's weight at an arm's tip for 100 steps, then released, while the
    foot is turned and moved (test_framed_model.swung_base): the same Newton iterations,
    positions within 1e-9 of the deflection."""
    from test_framed_model import swung_base
    from export.framed_runtime import FramedSimulator
    scene, path, lib = framed
    py, c = FramedSimulator(path), native.CFramedSimulator(path, lib)
    drag = scene.external_force.copy()
    drag[np.argmax(scene.mesh.vertices[:, 0]), 1] += 0.5 * scene.masses.sum() * 9.81
    a = b = py.rest_state()
    ca = cb = c.rest_state()
    worst = size = 0.0
    for k in range(200):
        f = drag if k < 100 else scene.external_force
        a, b = py.step(a, b, f, 0.02, base=swung_base(k + 1)), a
        ca, cb = c.step(ca, cb, f, 0.02, base=swung_base(k + 1)), ca
        assert c.iterations == py.iterations
        x = py.positions(a)
        worst = max(worst, np.abs(c.positions(ca) - x).max())
        size = max(size, np.abs(x - scene.mesh.vertices).max())
    assert size > 0.03  # the arm swung by more than a third of its length
    assert worst < 1e-9 * size


def test_c_steps_a_joint_cubature_like_the_numpy_runtime_over_200_steps(cubature_written,
                                                                          built):
    """The beam whose joints are a cubature, under a sideways drag at its tip that swings
    back and forth (a period of 40 steps): the same Newton iterations, positions within 1e-9
    of the deflection. (A body come to rest makes steps whose first Newton move sits at the
    tolerance, where the two may part by an iteration.)"""
    from export.framed_runtime import FramedSimulator
    model, path, _ = cubature_written
    scene = model.scene
    py, c = FramedSimulator(path), native.CFramedSimulator(path, built[2])
    a = b = py.rest_state()
    ca = cb = c.rest_state()
    worst = size = 0.0
    for k in range(200):
        f = scene.external_force + np.sin(2 * np.pi * k / 40) * tip_drag(scene)
        a, b = py.step(a, b, f, 0.02), a
        ca, cb = c.step(ca, cb, f, 0.02), ca
        assert c.iterations == py.iterations
        x = py.positions(a)
        worst = max(worst, np.abs(c.positions(ca) - x).max())
        size = max(size, np.abs(x - scene.mesh.vertices).max())
    assert size > 0.01
    assert worst < 1e-9 * size


def test_the_framed_models_constant_force_set_once_steps_like_passing_it_every_step(framed):
    """Gravity set once (af_framed_set_constant_force), a drag at an arm's tip passed per step
    and then none (NULL): the same states as the whole force passed every step."""
    scene, path, lib = framed
    every, once = (native.CFramedSimulator(path, lib) for _ in range(2))
    once.set_constant_force(scene.external_force)
    drag = np.zeros_like(scene.external_force)
    drag[np.argmax(scene.mesh.vertices[:, 0]), 1] = 0.5 * scene.masses.sum() * 9.81
    a = b = every.rest_state()
    ca = cb = once.rest_state()
    for k in range(40):
        a, b = every.step(a, b, scene.external_force + (drag if k < 20 else 0.0), 0.02), a
        ca, cb = once.step(ca, cb, drag if k < 20 else None, 0.02), ca
    moved = np.abs(every.positions(a) - scene.mesh.vertices).max()
    assert moved > 1e-3 and np.abs(once.positions(ca) - every.positions(a)).max() < 1e-9 * moved
    bad = scene.external_force.copy()
    bad[0, 0] = np.nan
    with pytest.raises(RuntimeError, match="bad input"):
        once.set_constant_force(bad)


def test_c_steps_a_framed_display_file_like_the_numpy_runtime(displayed, built):
    """The framed model written for a coarser mesh: gravity set once, a drag at the display's
    tip, the base moving; positions within 1e-9 of the deflection, the same iterations."""
    from export.framed_runtime import FramedSimulator
    _, _, shown, path = displayed
    py, c = FramedSimulator(path), native.CFramedSimulator(path, built[2])
    assert c.n == shown.n_vertices
    gravity = py.masses[:, None] * np.array([0.0, 0.0, -9.81])
    c.set_constant_force(gravity)
    drag = np.zeros((c.n, 3))
    drag[np.argmax(shown.vertices[:, 0]), 1] = 0.3 * py.masses.sum() * 9.81
    a = b = py.rest_state()
    ca = cb = c.rest_state()
    worst = size = 0.0
    for k in range(60):
        f = drag if k < 30 else None
        base = np.hstack([np.eye(3), [[0.0], [0.002 * k], [0.0]]])
        a, b = py.step(a, b, gravity + (drag if k < 30 else 0.0), 0.02, base=base), a
        ca, cb = c.step(ca, cb, f, 0.02, base=base), ca
        assert c.iterations == py.iterations
        x = py.positions(a)
        worst = max(worst, np.abs(c.positions(ca) - x).max())
        size = max(size, np.abs(x - shown.vertices).max())
    assert size > 0.02 and worst < 1e-9 * size


def test_c_runtime_refuses_a_framed_file_for_the_linear_step_and_back(framed, built):
    _, framed_path, lib = framed
    _, linear_path, _ = built
    with pytest.raises(ValueError, match="anisofem-framed-1.*rebuild.*python -m export reduced$"):
        native.CReducedSimulator(framed_path, lib)
    with pytest.raises(ValueError, match="anisofem-reduced-1.*rebuild.*reduced --framed"):
        native.CFramedSimulator(linear_path, lib)
    c = native.CFramedSimulator(framed_path, lib)
    now = c.rest_state()
    bad = np.zeros((c.n, 3))
    bad[2, 0] = np.nan
    with pytest.raises(RuntimeError, match="bad input"):
        c.step(now, now, bad, 0.02)
    with pytest.raises(RuntimeError, match="bad input"):
        c.step(now, now, np.zeros((c.n, 3)), -0.02)
    with pytest.raises(RuntimeError, match="bad input"):  # a base that is not a rigid motion
        c.step(now, now, np.zeros((c.n, 3)), 0.02, base=np.ones((3, 4)))
