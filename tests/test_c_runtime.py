"""The C runtime (export/c): built with the system C compiler, it steps a reduced model like
runtime.ReducedSimulator and a framed one like framed_runtime.FramedSimulator to round-off in
double precision, from Python through ctypes and from a C program, and refuses files it cannot
step with a message that names the file and what is wrong."""
import json
import os
import pathlib
import re
import shutil
import subprocess

import numpy as np
import pytest

from anisofem.reduced import ReducedModel
from corrupt_files import corrupt, cut_bin, nan_at, set_spec, truncated_header
from export import native
from export.writers import reduced as writer
from export.runtime import ReducedSimulator, read_arrays
from test_framed_model import cubature_model  # noqa: F401 (a fixture)
from test_framed_runtime import cubature_written, displayed, tip_drag  # noqa: F401 (fixtures)
from test_reduced import cantilever

pytestmark = pytest.mark.skipif(native.compiler() is None, reason="no C compiler")
HERE = pathlib.Path(__file__).parent


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
    with pytest.raises(RuntimeError, match="constant force: vertex 0, component 0 is not finite"):
        once.set_constant_force(bad)


def test_c_program_prints_the_runtime_rollout(built, tmp_path):
    scene, path, _ = built
    exe = tmp_path / "example"
    done = subprocess.run([native.compiler(), "-std=c99", "-O2", "-o", str(exe),
                           f"{native.FOLDER}/example.c", *native.SOURCES, "-lm"],
                          capture_output=True, text=True)
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
    with pytest.raises(ValueError, match="old.json: holds model_format 'anisofem-reduced-0'.*"
                                         "rebuild"):
        native.CReducedSimulator(str(old), lib)
    with pytest.raises(ValueError, match="cannot read .*missing.json"):
        native.CReducedSimulator(str(tmp_path / "missing"), lib)
    with pytest.raises(ValueError, match="angle: .*long.json holds no model at fiber angle 30"):
        native.CReducedSimulator(path, lib, angle="30")
    c = native.CReducedSimulator(path, lib)
    q, w = c.rest_state()
    bad = scene.external_force.copy()
    bad[3, 1] = np.nan
    with pytest.raises(RuntimeError, match="force: vertex 3, component 1 is not finite"):
        c.step(q, w, bad, 0.02)
    with pytest.raises(RuntimeError, match="dt: a positive time step, got 0 s"):
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
    with pytest.raises(RuntimeError, match="constant force: vertex 0, component 0"):
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


def test_one_api_loads_both_kinds_and_the_simulators_name_the_other(framed, built):
    _, framed_path, lib = framed
    _, linear_path, _ = built
    assert native.CModel(framed_path, lib).kind == native.FRAMED
    assert native.CModel(linear_path, lib).kind == native.REDUCED
    with pytest.raises(ValueError, match="a framed model: step it with CFramedSimulator"):
        native.CReducedSimulator(framed_path, lib)
    with pytest.raises(ValueError, match="not a framed one: step it with CReducedSimulator"):
        native.CFramedSimulator(linear_path, lib)
    c = native.CFramedSimulator(framed_path, lib)
    now = c.rest_state()
    bad = np.zeros((c.n, 3))
    bad[2, 0] = np.nan
    with pytest.raises(RuntimeError, match="force: vertex 2, component 0 is not finite"):
        c.step(now, now, bad, 0.02)
    with pytest.raises(RuntimeError, match="dt: a positive time step, got -0.02 s"):
        c.step(now, now, np.zeros((c.n, 3)), -0.02)
    with pytest.raises(RuntimeError, match="base: not a rigid motion"):
        c.step(now, now, np.zeros((c.n, 3)), 0.02, base=np.ones((3, 4)))
    with pytest.raises(RuntimeError, match="base: a reduced model's held vertices stay"):
        native.CReducedSimulator(linear_path, lib).advance(np.zeros(40), None, 0.02,
                                                           base=np.eye(3, 4))


def _compiles(command):
    done = subprocess.run(command, capture_output=True, text=True)
    return done.returncode == 0, done.stderr


@pytest.mark.parametrize("language", ["c99", "c++17"])
def test_the_runtime_compiles_cleanly_as_c99_and_as_cpp17(language, tmp_path):
    cc = native.compiler() if language == "c99" else shutil.which("c++") or shutil.which("g++")
    if cc is None:
        pytest.skip("no C++ compiler")
    flags = ["-std=c99", "-pedantic"] if language == "c99" else ["-std=c++17", "-x", "c++"]
    for source in native.SOURCES:
        ok, err = _compiles([cc, *flags, "-Wall", "-Wextra", "-Werror", "-c", source, "-o",
                             str(tmp_path / "x.o")])
        assert ok, f"{source} as {language}:\n{err}"


def _sanitized(tmp_path):
    """tests/c/load_and_step.c built with AddressSanitizer and UndefinedBehaviorSanitizer, or a
    skip where the compiler has no sanitizer runtime."""
    exe = str(tmp_path / "load_and_step")
    ok, err = _compiles([native.compiler(), "-std=c99", "-g", "-O1",
                         "-fsanitize=address,undefined", "-fno-sanitize-recover=all",
                         f"-I{native.FOLDER}", "-o", exe, str(HERE / "c" / "load_and_step.c"),
                         *native.SOURCES, "-lm"])
    if not ok:
        pytest.skip(f"no sanitizer runtime: {err.splitlines()[-1] if err else ''}")
    return exe


def test_under_the_sanitizers_good_files_step_and_bad_files_say_what_is_wrong(built, framed,
                                                                               tmp_path):
    """Both kinds step 50 steps; each corrupt file gives one message that names the file and
    what is wrong; AddressSanitizer and UndefinedBehaviorSanitizer see no invalid access."""
    _, reduced, _ = built
    _, t, _ = framed
    exe = _sanitized(tmp_path)
    out = str(tmp_path / "bad")
    truncated = truncated_header(reduced, out + "-truncated-json")
    cases = [
        (reduced, r"ok 1 "),
        (t, r"ok 2 "),
        (corrupt(reduced, out + "-no-format", lambda h: h.pop("format")),
         r"no-format.json: no \"format\" key"),
        (corrupt(reduced, out + "-no-model", lambda h: h.pop("model_format")),
         r"no-model.json: no \"model_format\" key"),
        (truncated, r"truncated-json.json: not complete JSON"),
        (corrupt(reduced, out + "-short-bin", edit_bin=cut_bin),
         r"short-bin.json: array \w+ \(\d+ bytes at offset \d+\) runs past the end of the "
         r"\d+-byte .bin"),
        (corrupt(reduced, out + "-nan", edit_bin=nan_at("c1")),
         r"nan.json: array c1 holds a non-finite number at entry 0"),
        (corrupt(reduced, out + "-dtype", set_spec("basis", "dtype", lambda _: "float32")),
         r"dtype.json: array basis is float32, expected float64"),
        (corrupt(reduced, out + "-offset", set_spec("W4", "offset", lambda o: o + 4)),
         r"offset.json: array W4 starts at offset \d+, not a multiple of its 8-byte entries"),
        (corrupt(reduced, out + "-rank", set_spec("C2", "shape", lambda s: s[:1])),
         r"rank.json: array C2 has 1 dimensions, expected 2"),
        (corrupt(reduced, out + "-r", set_spec("c1", "shape", lambda s: [s[0] - 1])),
         r"r.json: the arrays c1, C2, S3 and W4 do not fit a basis of r = 20"),
        (corrupt(reduced, out + "-n", lambda h: h.update(n=h["n"] + 1)),
         r"n.json: the header says n = \d+ vertices, and array rest_positions has \d+"),
        (corrupt(reduced, out + "-missing", lambda h: h["arrays"].pop("C2")),
         r"missing.json: no array C2 in its arrays table"),
        (corrupt(reduced, out + "-tets", set_spec("tets", "dtype", lambda _: "int64")),
         r"tets.json: array tets is int64, expected int32"),
        (corrupt(t, out + "-labels", set_spec("labels", "dtype", lambda _: "int64")),
         r"labels.json: array labels is int64, expected int32"),
        (corrupt(t, out + "-joint-nan", edit_bin=nan_at("joint_grads")),
         r"joint-nan.json: array joint_grads holds a non-finite number at entry 0"),
        (corrupt(t, out + "-kind", lambda h: h.update(model_format="anisofem-framed-0")),
         r"kind.json: holds model_format 'anisofem-framed-0', and this runtime reads "
         r"'anisofem-reduced-1' and 'anisofem-framed-1'; rebuild"),
        (str(tmp_path / "nowhere"), r"path: cannot read .*nowhere.json"),
    ]
    no_bin = corrupt(reduced, out + "-no-bin")
    os.remove(no_bin + ".bin")
    cases.append((no_bin, r"no-bin.json names its arrays' file .*no-bin.bin, and it cannot be "
                          r"read"))
    done = subprocess.run([exe, *(path for path, _ in cases)], capture_output=True, text=True)
    assert done.returncode == 0 and "Sanitizer" not in done.stderr, done.stderr[-3000:]
    lines = done.stdout.splitlines()
    assert len(lines) == len(cases)
    for (path, expected), line in zip(cases, lines):
        assert re.search(expected, line), (path, line)
    assert all(line.startswith("error ") for line in lines[2:])


def test_the_models_body_from_the_file(built, framed):
    """The arrays an engine draws and loads with: masses, rest positions, held flags, surface
    triangles and tets, as the file holds them; gravity where the header states it."""
    for path in (built[1], framed[1]):
        header, arrays = read_arrays(path)
        c = native.CModel(path, built[2])
        for name in ("masses", "rest_positions", "held", "surface", "tets"):
            assert np.array_equal(getattr(c, name), arrays[name]), name
        assert c.gravity is None if header.get("gravity") is None else np.allclose(
            c.gravity, header["gravity"])


def test_a_path_with_backslashes_finds_its_bin_beside_it(built, tmp_path, monkeypatch):
    """A Windows path (folders separated by '\\'): the .bin the header names is looked for in
    the header's folder. On this system '\\' is part of a file's name, so the files are named
    as a Windows folder would place them."""
    _, path, lib = built
    monkeypatch.chdir(tmp_path)
    corrupt(path, str(tmp_path / "models\\beam"))
    header = json.loads(open(tmp_path / "models\\beam.json").read())
    header["bin"] = "beam.bin"
    (tmp_path / "models\\beam.json").write_text(json.dumps(header))
    c = native.CReducedSimulator("models\\beam", lib)
    assert c.n == read_arrays(path)[0]["n"]


def test_a_cpp17_program_steps_a_model_like_the_numpy_runtime(built, tmp_path):
    """export/c/example.cpp (C++17, the runtime's sources compiled as C++): 200 steps of the
    0.2 m beam, dragged then released; its lowest height per step within 1e-12 m of numpy's."""
    cxx = shutil.which("c++") or shutil.which("g++")
    if cxx is None:
        pytest.skip("no C++ compiler")
    scene, path, _ = built
    exe = str(tmp_path / "example")
    ok, err = _compiles([cxx, "-std=c++17", "-O2", "-Wall", "-Wextra", "-Werror", "-x", "c++",
                         f"-I{native.FOLDER}", "-o", exe, f"{native.FOLDER}/example.cpp",
                         *native.SOURCES])
    assert ok, err
    done = subprocess.run([exe, path, "200", "0.02"], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    py = ReducedSimulator(path)
    gravity = py.masses[:, None] * np.array([0.0, 0.0, -9.81])
    top = int(np.argmax(py.rest_positions[:, 2]))
    drag = np.zeros_like(gravity)
    drag[top, 0] = 0.5 * py.masses[top] * 9.81
    q, w = py.rest_state()
    expected = []
    for k in range(200):
        q, w = py.step(q, w, gravity + (drag if k < 100 else 0.0), 0.02)
        expected.append(py.positions(q)[:, 2].min())
    assert np.abs(np.array(done.stdout.split(), dtype=float) - expected).max() < 1e-12


def test_cmake_builds_and_installs_the_library_with_pkg_config(tmp_path):
    """export/c/CMakeLists.txt: the library, the example linked to it, the header and a
    relocatable anisofem.pc installed; pkg-config's flags build a program against them."""
    if shutil.which("cmake") is None:
        pytest.skip("no cmake")
    build, prefix = tmp_path / "build", tmp_path / "prefix"
    for command in (["cmake", "-S", native.FOLDER, "-B", str(build)],
                    ["cmake", "--build", str(build)],
                    ["cmake", "--install", str(build), "--prefix", str(prefix)]):
        ok, err = _compiles(command)
        assert ok, f"{command}:\n{err}"
    pc = next(prefix.glob("lib*/pkgconfig/anisofem.pc"))
    assert (prefix / "include" / "anisofem.h").exists()
    if shutil.which("pkg-config"):
        flags = subprocess.run(["pkg-config", "--cflags", "--libs", "anisofem"],
                               capture_output=True, text=True,
                               env={**os.environ, "PKG_CONFIG_PATH": str(pc.parent)}).stdout
        ok, err = _compiles([native.compiler(), "-std=c99", "-o", str(tmp_path / "linked"),
                             f"{native.FOLDER}/example.c", *flags.split()])
        assert ok, err


def test_a_csharp_program_steps_a_model_through_the_shared_library(built, tmp_path):
    """export/c/Example.cs through P/Invoke (Mono's compiler and runtime, which Debian
    packages; .NET loads the library the same way): 30 steps of the 0.2 m beam under gravity,
    its lowest height per step within 1e-12 m of numpy's."""
    if not (shutil.which("mcs") and shutil.which("mono")):
        pytest.skip("no C# compiler and runtime (mcs, mono)")
    _, path, lib = built
    exe = str(tmp_path / "Example.exe")
    ok, err = _compiles(["mcs", f"-out:{exe}", f"{native.FOLDER}/Example.cs"])
    assert ok, err
    done = subprocess.run(["mono", exe, path, "30", "0.02"], capture_output=True, text=True,
                          env={**os.environ, "LD_LIBRARY_PATH": os.path.dirname(lib)})
    assert done.returncode == 0, done.stderr
    py = ReducedSimulator(path)
    gravity = py.masses[:, None] * np.array([0.0, 0.0, -9.81])
    q, w = py.rest_state()
    expected = []
    for _ in range(30):
        q, w = py.step(q, w, gravity, 0.02)
        expected.append(py.positions(q)[:, 2].min())
    assert np.abs(np.array(done.stdout.split(), dtype=float) - expected).max() < 1e-12


def test_without_a_c_compiler_the_build_says_what_to_do_instead(tmp_path, monkeypatch):
    monkeypatch.setattr(native.shutil, "which", lambda name: None)
    with pytest.raises(RuntimeError, match="needs a C compiler .* the numpy runtimes"):
        native.build(str(tmp_path / "nowhere"))
