"""The reduced model written by export.writers.reduced and stepped by runtime.ReducedSimulator
(numpy only) moves like the library's stepper, refuses another mesh and another file, and the
command writes it."""
import json
import re
import subprocess
import sys

import numpy as np
import pytest

from anisofem.reduced import ReducedModel
from corrupt_files import corrupt, cut_bin, nan_at, set_spec, truncated_header
from export.writers import reduced as writer
from export.writers.bake import write_arrays
from export.cli import main
from export.runtime import ReducedSimulator
from test_reduced import FIBER, cantilever


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    scene = cantilever()
    model = ReducedModel(scene, modes=5)
    path = str(tmp_path_factory.mktemp("reduced") / "cantilever")
    writer.write(model, path, "cantilever", gravity=(0, 0, -9.81))
    return scene, model, path


def rollouts(scene, model, sim, steps, drag=None):
    """Largest position difference between the library's and the runtime's rollouts, over the
    largest displacement."""
    q, w = np.zeros(model.r), np.zeros(model.r)
    qs, ws = sim.rest_state()
    worst = size = 0.0
    force = scene.external_force if drag is None else scene.external_force + drag
    for _ in range(steps):
        q, w, report = model.step(q, w, 0.02, force=drag)
        assert report.converged
        qs, ws = sim.step(qs, ws, force, 0.02)
        x = model.positions(q)
        worst = max(worst, np.abs(x - sim.positions(qs)).max())
        size = max(size, np.abs(x - scene.mesh.vertices).max())
    return worst / size


def test_runtime_steps_like_the_library_in_float64_and_close_in_float32(written):
    scene, model, path = written
    sim = ReducedSimulator(path, scene.mesh.vertices, scene.mesh.tets)
    assert rollouts(scene, model, sim, 200) < 1e-6
    assert rollouts(scene, model, ReducedSimulator(path, dtype=np.float32), 200) < 0.01


def test_nodal_forces_per_step_reach_the_runtime_as_in_the_library(written):
    scene, model, path = written
    drag = np.zeros((scene.mesh.n_vertices, 3))
    drag[np.argmax(scene.mesh.vertices[:, 0]), 1] = 0.05
    sim = ReducedSimulator(path)
    assert rollouts(scene, model, sim, 20, drag) < 1e-6
    q, w = sim.step(*sim.rest_state(), scene.external_force + drag, 0.02)
    assert sim.positions(q)[:, 1].max() > 1e-6  # the drag moved the beam sideways


def test_header_holds_the_model_and_its_validation(written):
    scene, model, path = written
    with open(path + ".json") as f:
        header = json.load(f)
    assert header["r"] == model.r == 20 and header["n"] == scene.mesh.n_vertices
    assert 0 < header["validation"]["tip_error"] < 0.01
    assert len(header["frequencies"]) == 5


def test_a_fitted_model_steps_in_the_runtime_like_the_library(tmp_path, capsys):
    """A basis fitted to declared loads (the 0.2 m cantilever, bending through large rotation)
    is written, described and stepped like a modal one."""
    out = str(tmp_path / "long")
    fiber = [repr(float(c)) for c in FIBER]
    main(["reduced", "box", "--size", "0.2", "0.02", "0.02", "--cells", "10", "2", "2",
          "--fiber", *fiber, "--kappa", "1e5", "--modes", "2", "--snapshots", "8", "-o", out])
    said = capsys.readouterr().out
    assert "r = 10 (2 modes + 8 fitted)" in said and "on 3 unseen loads" in said
    with open(out + ".json") as f:
        header = json.load(f)
    assert header["snapshots"] == 8 and header["validation"]["cases"] == 3
    scene = cantilever(length=0.2)
    model = ReducedModel(scene, modes=2, snapshots=8, validate=False)
    sim = ReducedSimulator(out)
    drag = np.zeros((scene.mesh.n_vertices, 3))
    drag[np.argmax(scene.mesh.vertices[:, 0]), 1] = 0.1
    assert rollouts(scene, model, sim, 30, drag) < 1e-6


def test_body_flag_builds_on_the_finer_body_and_writes_the_scene_mesh(tmp_path, capsys):
    """Linear tets lock in bending: the model built on the quadratic body, drawn on the
    200-tet mesh, sags about twice as far as the one built on that mesh."""
    sags = {}
    for body in ([], ["--body", "quadratic"]):
        out = str(tmp_path / f"box{len(body)}")
        main(["reduced", "box", "--cells", "10", "2", "2", "--modes", "3", *body, "-o", out])
        with open(out + ".json") as f:
            header = json.load(f)
        assert header["n"] == 99 and header["m"] == 200
        sim = ReducedSimulator(out, cantilever().mesh.vertices)
        force = sim.masses[:, None] * np.array([0.0, 0.0, -9.81])
        q, w = sim.rest_state()
        for _ in range(100):
            q, w = sim.step(q, w, force, 0.02)
        sags[len(body)] = sim.rest_positions[:, 2].min() - sim.positions(q)[:, 2].min()
    assert sags[2] > 1.5 * sags[0]
    with pytest.raises(SystemExit):
        main(["reduced", "box", "--body", "quadratic", "--display", "x.msh", "-o", out])
    assert "give one" in capsys.readouterr().err


def test_runtime_refuses_another_mesh_and_another_file(written, tmp_path):
    scene, model, path = written
    other = cantilever(cells=(5, 2, 2))
    with pytest.raises(ValueError, match="vertices: not the mesh"):
        ReducedSimulator(path, other.mesh.vertices)
    with pytest.raises(ValueError, match="tets: not the mesh"):
        ReducedSimulator(path, scene.mesh.vertices, scene.mesh.tets[::-1])
    write_arrays(tmp_path / "baked", {"x": np.zeros(3)}, {"model_format": "anisognn-step-2"})
    with pytest.raises(ValueError, match="holds no reduced model"):
        ReducedSimulator(tmp_path / "baked")
    with pytest.raises(ValueError, match="dt"):
        ReducedSimulator(path).step(np.zeros(20), np.zeros(20), scene.external_force, 0.0)


def test_command_writes_a_scene_the_runtime_steps(tmp_path, capsys):
    out = str(tmp_path / "box")
    main(["reduced", "box", "--cells", "10", "2", "2", "--kappa", "1e5", "--modes", "4",
          "-o", out])
    assert "r = 14 (4 modes)" in capsys.readouterr().out
    sim = ReducedSimulator(out)
    force = sim.masses[:, None] * np.array([0.0, 0.0, -9.81])
    q, w = sim.rest_state()
    for _ in range(5):
        q, w = sim.step(q, w, force, 0.02)
    assert sim.positions(q)[:, 2].min() < sim.rest_positions[:, 2].min() - 1e-4
    with pytest.raises(SystemExit) as ended:
        main(["reduced", "box", "--material", "neohookean", "-o", out])
    assert ended.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("python -m export reduced: error: scene:")
    assert "Neo-Hookean" in err[0]


def test_runtime_says_how_another_mesh_differs(written):
    scene, model, path = written
    fewer = cantilever(cells=(5, 2, 2)).mesh.vertices
    with pytest.raises(ValueError, match=f"it has {scene.mesh.n_vertices} vertices; got "
                                         f"{fewer.shape[0]}"):
        ReducedSimulator(path, fewer)
    moved = scene.mesh.vertices.copy()
    moved[7] += (0.0, 0.003, 0.0)
    moved[9] += (0.001, 0.0, 0.0)
    with pytest.raises(ValueError, match=r"the same \d+ vertices, 2 of them elsewhere; the "
                                         r"farthest, vertex 7, .* 0.003 m from its rest"):
        ReducedSimulator(path, moved)


def test_export_commands_fail_in_one_line_with_status_2(tmp_path):
    def export(*args):
        return subprocess.run([sys.executable, "-m", "export", *args], cwd=tmp_path,
                              capture_output=True, text=True, timeout=300)
    for args, says in [
            (("reduced", "nothere.msh", "-o", "r"), "path: no such mesh file 'nothere.msh'"),
            (("reduced", "box", "--young", "-1e5", "-o", "r"), "young: Young's modulus must"),
            (("reduced", "t", "--cells", "4", "2", "2", "-o", "r"), "--cells: the t shape"),
            # refused before it allocates: the polynomial of 200 modes would need terabytes
            (("reduced", "box", "--cells", "20", "4", "4", "--modes", "200", "-o", "r"),
             "modes fit"),
            (("bake", "box", "-o", "r"), "argument scene: invalid choice")]:
        r = export(*args)
        assert r.returncode == 2, (args, r.stdout, r.stderr)
        lines = r.stderr.strip().splitlines()
        assert says in lines[-1] and (len(lines) == 1 or lines[0].startswith("usage:")), args
        assert r.stdout == ""
    helped = export("--help").stdout
    assert all(f"  {name} " in helped for name in ("bench", "bake", "reduced", "bake-reduced",
                                                   "bench-reduced"))


def test_commands_make_the_folders_they_write_to(tmp_path):
    out = tmp_path / "made" / "here" / "box"
    main(["reduced", "box", "--cells", "4", "1", "1", "--modes", "3", "-o", str(out)])
    assert (tmp_path / "made" / "here" / "box.bin").exists()


def test_bench_row_measures_what_it_names(tmp_path):
    from export.benches import reduced as bench_reduced
    from export import native
    row = bench_reduced.measure((4, 1, 1), 3, str(tmp_path))
    assert row["tets"] == 20 and row["r"] == 9 and row["modes"] == 3
    assert row["file_mb"] > 0 and row["library_ms"] > 0 and row["runtime_ms"] > 0
    assert 0 <= row["tip_error"] < 0.5 and row["validation_cases"] == 0
    assert row["c_ms"] is None
    lib = native.build(str(tmp_path / "c")) if native.compiler() else None
    row = bench_reduced.measure((4, 1, 1), 2, str(tmp_path), snapshots=4, lib=lib)
    assert row["r"] == 6 and row["snapshots"] == 4 and row["validation_cases"] == 3
    assert row["snapshot_s"] > 0 and (lib is None or row["c_ms"] > 0)


def test_display_mesh_file_moves_the_coarse_vertices_by_the_fine_model(tmp_path):
    fine = cantilever(cells=(20, 4, 4))
    model = ReducedModel(fine, modes=4, validate=False)
    coarse = cantilever().mesh
    writer.write(model, str(tmp_path / "display"), display=coarse)
    sim = ReducedSimulator(str(tmp_path / "display"), coarse.vertices, coarse.tets)
    assert sim.positions(np.zeros(model.r)).shape == (coarse.n_vertices, 3)
    clamped = coarse.vertices[:, 0] <= 1e-12
    assert sim.held[clamped].all() and not sim.held[~clamped].any()
    assert abs(sim.masses.sum() - fine.masses.sum()) <= 1e-12 * fine.masses.sum()
    U = model.basis_at(coarse.vertices)
    q, w = np.zeros(model.r), np.zeros(model.r)
    qs, ws = sim.rest_state()
    force = sim.masses[:, None] * np.array([0.0, 0.0, -9.81])
    for _ in range(30):
        q, w, _ = model.step(q, w, 0.02)
        qs, ws = sim.step(qs, ws, force, 0.02)
    library = coarse.vertices + U @ q
    sag = np.abs(library - coarse.vertices).max()
    assert np.abs(sim.positions(qs) - library).max() < 0.02 * sag


def _refusals(sim_class, path, cases, tmp_path):
    """Each (name, edit_header, edit_bin, expected) case: a corrupt copy of path that sim_class
    refuses with a ValueError matching expected."""
    for name, edit_header, edit_bin, expected in cases:
        out = corrupt(path, str(tmp_path / name), edit_header, edit_bin)
        with pytest.raises(ValueError, match=expected):
            sim_class(out)


def test_the_numpy_runtime_checks_a_file_against_its_header(written, tmp_path):
    """What a corrupt file gives: one ValueError naming the file and what is wrong, never a
    numpy error from deep inside or a model that loads and steps to NaN."""
    _, _, path = written
    truncated = truncated_header(path, str(tmp_path / "truncated"))
    with pytest.raises(ValueError, match="truncated.json is not complete JSON"):
        ReducedSimulator(truncated)
    _refusals(ReducedSimulator, path, [
        ("short", None, cut_bin, r"short.json: array \w+ \(\d+ bytes at offset \d+\) runs past "
                                 r"the end of the \d+-byte .bin"),
        ("nan", None, nan_at("c1"), r"nan.json: array c1 holds a non-finite number at entry 0"),
        ("dtype", set_spec("basis", "dtype", lambda _: "float32"), None,
         r"dtype.json: array basis is float32, expected float64"),
        ("shape", set_spec("basis", "shape", lambda s: [s[0], 3 * s[2]]), None,
         r"shape.json: array basis has 2 dimensions, expected 3"),
        ("offset", set_spec("W4", "offset", lambda o: o + 4), None,
         r"offset.json: array W4 starts at offset \d+, not a multiple of 8"),
        ("missing", lambda h: h["arrays"].pop("C2"), None, r"missing.json has no array C2"),
        ("n", lambda h: h.update(n=h["n"] + 1), None,
         r"n.json: array rest_positions has shape \(\d+, 3\), expected \(\d+, 3\)"),
        ("r", lambda h: h.update(r=h["r"] + 1), None,
         r"r.json: the header says r = 21, and array basis has 20 columns"),
        ("tets", lambda h: h.update(m=h["m"] - 1), None,
         r"tets.json: array tets has shape \(\d+, 4\), expected \(\d+, any\)|"
         r"tets.json: the header says m = \d+ tets"),
        ("tets-dtype", set_spec("tets", "dtype", lambda _: "float32"), None,
         r"tets-dtype.json: array tets is float32, expected int32"),
        ("tets-long", set_spec("tets", "dtype", lambda _: "int64"), None,
         r"tets-long.json: array tets \(\d+ bytes at offset \d+\) runs past the end"),
        ("bin", lambda h: h.update(bin="nowhere.bin"), None,
         r"bin.json names its arrays' file .*nowhere.bin, and it is missing"),
    ], tmp_path)


def test_the_framed_numpy_runtime_checks_a_file_against_its_header(tmp_path):
    """The same for a framed model's arrays: their dtypes, their sizes against each other, the
    indices they hold."""
    from anisofem.reduced import FramedModel
    from export.framed_runtime import FramedSimulator
    from test_framed_model import t_scene
    path = str(tmp_path / "t")
    writer.write_framed(FramedModel(t_scene(), validate=False), path, "t")
    FramedSimulator(path)
    _refusals(FramedSimulator, path, [
        ("labels", set_spec("labels", "dtype", lambda _: "int64"), None,
         r"labels.json: array labels is int64, expected int32"),
        ("joint-nan", None, nan_at("joint_grads"),
         r"joint-nan.json: array joint_grads holds a non-finite number"),
        ("r", set_spec("r", "shape", lambda s: [s[0] - 1]), None,
         r"r.json: array (r|centre) has shape"),
        ("size", lambda h: h.pop("size"), None, r"size.json: the header's \"size\""),
        ("order", set_spec("order", "dtype", lambda _: "float32"), None,
         r"order.json: array order is float32, expected int32"),
    ], tmp_path)


def test_the_command_builds_for_the_loads_it_is_given_and_says_what_it_holds(tmp_path,
                                                                            capsys):
    """--drag and --cone declare what the model is fitted to and validated on (the header
    records them); once the input is checked, one line says which vertices it holds and why,
    then each stage of the build."""
    path = str(tmp_path / "beam")
    main(["reduced", "box", "--cells", "10", "2", "2", "--modes", "4", "--snapshots", "4",
          "--drag", "x-max", "0.3", "--drag", "x-max", "0.1", "0", "1", "0", "--cone", "10",
          "-o", path])
    err = capsys.readouterr().err
    assert "holding 9 vertices at x-min (the shape's default" in err
    assert "from the declared loads (2 drags, a 10 degree cone)" in err
    stages = [line.split("] ", 1)[1] for line in err.splitlines() if line.startswith("  [")]
    assert stages[:2] == ["the 4 lowest vibration modes",
                          "the full FEM's static equilibria under the declared loads"]
    assert re.fullmatch(r"the energy's polynomial in r = 8 coordinates \(about [0-9.e-]+ GiB "
                        r"at its peak; its quartic grows as r\^4\)", stages[2])
    assert stages[3:] == ["its validation against the full FEM"]
    header = json.load(open(path + ".json"))
    assert header["loads"] == {"drags": [{"vertices": 9, "magnitude": 0.3, "directions": None},
                                         {"vertices": 9, "magnitude": 0.1,
                                          "directions": [[0.0, 1.0, 0.0]]}],
                               "cone": 10.0, "carry": None, "controls": {}}
    assert header["validation"]["cases"] == 3
    for flags, message in ((["--drag", "x-mid", "1"], "--drag: expected AXIS-SIDE like x-min"),
                           (["--drag", "x-max", "one"], "--drag x-max: N and DX DY DZ"),
                           (["--drag", "x-max"], "--drag: WHERE N or WHERE N DX DY DZ"),
                           (["--drag", "x-min", "1"], r"drags\[0\].vertices: every one"),
                           (["--carry", "30", "0", "1"], "--carry: the framed model's")):
        with pytest.raises(SystemExit) as exit_:
            main(["reduced", "box", "--cells", "10", "2", "2", *flags, "-o", path])
        assert exit_.value.code == 2
        assert re.search(message, capsys.readouterr().err), flags


def test_the_command_warns_where_the_linear_basis_does_not_hold(tmp_path, capsys):
    """A 0.2 m beam dragged by 0.5 N at its tip, 2 modes and 1 fitted direction: the validation
    is far off, and the command says so and points to more snapshots and the framed model."""
    main(["reduced", "box", "--cells", "10", "2", "2", "--size", "0.2", "0.02", "0.02",
          "--modes", "2", "--snapshots", "1", "--drag", "x-max", "0.5", "-o",
          str(tmp_path / "w")])
    err = capsys.readouterr().err
    assert re.search(r"warning: \d+% off the full FEM: this body moves more than its linear "
                     r"basis holds; more --snapshots, or --framed", err), err


def test_the_command_says_where_the_loads_fold_the_body(tmp_path, capsys):
    """A drag pushing the 0.2 m beam's tip back along it at 20 times its weight: the snapshots
    and every validation case turn elements inside out; the command says both, no percentage
    of nothing."""
    import anisofem as af
    with pytest.warns(af.InversionWarning, match="3 turned elements inside out and 0 did not "
                      "converge"):
        main(["reduced", "box", "--cells", "10", "2", "2", "--size", "0.2", "0.02", "0.02",
              "--modes", "2", "--snapshots", "2", "--drag", "x-max", "16", "-1", "0", "0",
              "-o", str(tmp_path / "f")])
    said = capsys.readouterr()
    assert re.search(r"not validated: the full FEM turned elements inside out in all \d+ "
                     r"drawn cases", said.out), said.out
    assert "nan" not in said.out


def test_the_trade_notes_a_body_a_linear_basis_does_not_hold():
    """linear_basis_note: where every linear reduced rung misses and a framed one does not."""
    from anisofem.studies.trade import linear_basis_note
    rows = [{"name": "reduced m5", "kind": "reduced", "max_error": 0.2, "stable": True},
            {"name": "reduced framed b4 c12", "kind": "reduced", "max_error": 0.004,
             "stable": True}]
    note = linear_basis_note(rows, 0.01)
    assert note.startswith("the linear reduced models miss by 20% at best (reduced m5)")
    assert "the framed model (reduced framed b4 c12) follows" in note
    rows[0]["max_error"] = 0.005
    assert linear_basis_note(rows, 0.01) is None
