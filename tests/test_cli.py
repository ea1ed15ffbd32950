"""The command line: generate a mesh, solve it, read the result back."""
import json
import os
import shutil
import subprocess
import sys

import meshio
import numpy as np
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def run(*args, cwd):
    return subprocess.run([sys.executable, "-m", "anisofem", *args], cwd=cwd,
                          capture_output=True, text=True, timeout=300)


def test_mesh_then_solve(tmp_path):
    r = run("mesh", "box", "--cells", "4", "2", "2", "-o", "beam.msh", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    r = run("solve", "beam.msh", "--fiber", "1", "0", "0", "--kappa", "1e5", "-o", "out.vtu",
            cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert "converged: True" in r.stdout
    assert r.stdout.splitlines()[0].strip() and not r.stderr  # nothing stray from meshio
    out = meshio.read(tmp_path / "out.vtu")
    u = out.point_data["displacement"]
    assert u[:, 2].min() < -1e-4 and np.abs(u[out.points[:, 0] == 0]).max() == 0
    assert {"energy", "fiber_direction"} <= set(out.cell_data)


def test_continuation_flag_ramps_the_load_and_says_so(tmp_path):
    run("mesh", "box", "--cells", "4", "2", "2", "-o", "beam.msh", cwd=tmp_path)
    r = run("solve", "beam.msh", "--continuation", "always", "-o", "out.vtu", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert "load increments, converged: True" in r.stdout and "a minimum" in r.stdout
    r = run("solve", "beam.msh", "--continuation", "sometimes", "-o", "o.vtu", cwd=tmp_path)
    assert r.returncode != 0 and "--continuation" in r.stderr


def test_material_flag_keeps_a_hard_squeeze_physical(tmp_path):
    run("mesh", "box", "--cells", "10", "2", "2", "-o", "beam.msh", cwd=tmp_path)
    said = {}
    for model in ("stvk", "neohookean"):
        r = run("solve", "beam.msh", "--fiber", "1", "0", "0", "--kappa", "1e5", "--gravity",
                "0", "0", "-98.1", "--material", model, "-o", f"{model}.vtu", cwd=tmp_path)
        assert r.returncode == 0, r.stderr
        said[model] = r.stdout
        inverted = meshio.read(tmp_path / f"{model}.vtu").cell_data["inverted"][0]
        assert (inverted.sum() > 0) == (model == "stvk")
    assert "not physical" in said["stvk"] and "not physical" not in said["neohookean"]


def test_bad_fixed_spec_is_a_clear_error(tmp_path):
    run("mesh", "box", "--cells", "2", "2", "2", "-o", "b.vtu", cwd=tmp_path)
    r = run("solve", "b.vtu", "--fixed", "left", "-o", "o.vtu", cwd=tmp_path)
    assert r.returncode != 0 and "--fixed: expected AXIS-SIDE" in r.stderr


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    """A folder with beam.msh (a 40-tet box), an empty empty.msh and empty.vtu, and a text file
    notamesh.msh."""
    path = tmp_path_factory.mktemp("cli")
    assert run("mesh", "box", "--cells", "4", "1", "2", "-o", "beam.msh", cwd=path).returncode == 0
    (path / "empty.msh").write_text("")
    (path / "empty.vtu").write_text("")
    (path / "notamesh.msh").write_text("these are my notes\n")
    return path


@pytest.mark.parametrize("args, says", [
    (("solve", "missing.msh", "-o", "o.vtu"), "path: no such mesh file 'missing.msh'"),
    (("solve", "beam.msh", "--poisson", "0.5", "-o", "o.vtu"), "poisson: Poisson's ratio"),
    (("mesh", "box", "--cells", "10", "2", "-o", "b.msh"), "cells: expected 3"),
    (("solve", "beam.msh", "-o", "out.txt"), "path: 'out.txt' has no mesh format"),
    (("solve", "beam.msh", "-o", "notamesh.msh/o.vtu"),
     "path: the folder of 'notamesh.msh/o.vtu' cannot be made"),
    (("solve", "beam.msh", "--fiber", "0", "0", "0", "--kappa", "1e5", "-o", "o.vtu"),
     "--fiber: a direction needs a nonzero vector"),
    (("solve", "empty.msh", "-o", "o.vtu"), "path: meshio cannot read 'empty.msh'"),
    (("solve", "empty.vtu", "-o", "o.vtu"), "path: meshio cannot read 'empty.vtu' (not vtu)"),
    (("solve", "notamesh.msh", "-o", "o.vtu"),
     "path: meshio cannot read 'notamesh.msh' (not gmsh; not ansys)"),
    (("solve", "beam.msh", "--young", "nan", "-o", "o.vtu"), "young: must be finite, got nan"),
    (("solve", "beam.msh", "--fiber", "nan", "0", "0", "--kappa", "1e5", "-o", "o.vtu"),
     "--fiber: must be finite, got [nan, 0.0, 0.0]"),
    (("solve", "beam.msh", "--gravity", "0", "0", "inf", "-o", "o.vtu"),
     "gravity: contains NaN or inf (at index [[2]])"),
    (("solve", "beam.msh", "--method", "lbfgs", "--iterations", "0", "-o", "o.vtu"),
     "iterations: a budget of at least 1"),
    (("solve", "beam.msh", "--material", "rubber", "-o", "o.vtu"),
     "argument --material: invalid choice: 'rubber'"),
    (("trade", "box", "--steps", "10", "--json", "notamesh.msh/t.json"),
     "--json: the folder of 'notamesh.msh/t.json' cannot be made"),
    (("mesh", "cylinder", "--tets-per-cell", "6", "-o", "c.msh"),
     "--tets-per-cell: the cylinder shape does not take it; it takes --size, --cells, --rings"),
    (("mesh", "t", "--size", "0.2", "0.02", "0.02", "-o", "t.msh"),
     "--size: the t shape does not take it; it takes no shape flag"),
    (("mesh", "y", "--cells", "20", "2", "2", "-o", "y.msh"),
     "--cells: the y shape does not take it"),
    (("mesh", "cylinder", "--cells", "10", "2", "2", "-o", "c.msh"),
     "--cells: expected 2 values for the cylinder shape, got 3"),
    (("trade", "beam.msh", "--cells", "4", "2", "2"),
     "--cells: a shape flag; the mesh of a file is read as it is"),
    (("solve", "beam.msh", "--young", "-1e5", "-o", "o.vtu"),
     "young: Young's modulus must be > 0 Pa, got min -100000.0"),
    (("solve", "beam.msh", "--gravity", "0", "0", "-9.81e0", "--young", "-2.5E+5", "-o",
      "o.vtu"), "young: Young's modulus must be > 0 Pa, got min -250000.0"),
    (("bench", "--busy", "2"), "--busy, --rungs: go with --under-load"),
    (("bench", "--refinements", "1", "2", "4"), "--refinements, --max-unknowns: go with"),
    (("bench", "--convergence", "--refinements", "1", "2"), "refinements: at least three"),
])
def test_bad_input_is_one_line_before_any_work(folder, args, says):
    r = run(*args, cwd=folder)
    assert r.returncode == 2, (r.stdout, r.stderr)
    lines = r.stderr.strip().splitlines()  # argparse's own errors come after its usage
    assert says in lines[-1] and (len(lines) == 1 or lines[0].startswith("usage:"))
    assert r.stdout == ""  # nothing ran, nothing stray


def test_help_names_the_defaults_the_commands_rely_on(tmp_path):
    said = run("solve", "--help", cwd=tmp_path).stdout
    for default in ("(default: x-min)", "(default: (0.0, 0.0, -9.81))", "(default: 0.0)",
                    "(default: stvk)", "(default: auto)"):
        assert default in said


def test_order_two_meshes_solves_and_trades_quadratic_tets(tmp_path):
    r = run("mesh", "box", "--cells", "4", "2", "2", "--order", "2", "-o", "q.msh",
            cwd=tmp_path)
    assert r.returncode == 0 and "quadratic tets" in r.stdout, r.stderr
    assert "tetra10" in {c.type for c in meshio.read(tmp_path / "q.msh").cells}
    run("mesh", "box", "--cells", "4", "2", "2", "-o", "l.msh", cwd=tmp_path)
    quadratic = run("solve", "q.msh", "-o", "q.vtu", cwd=tmp_path)
    raised = run("solve", "l.msh", "--order", "2", "-o", "r.vtu", cwd=tmp_path)
    assert "converged: True" in quadratic.stdout
    tip = [line for line in quadratic.stdout.splitlines() if line.startswith("tip")]
    assert tip == [line for line in raised.stdout.splitlines() if line.startswith("tip")]
    r = run("mesh", "box", "--cells", "4", "2", "2", "--order", "2", "--tets-per-cell", "6",
            "-o", "q6.msh", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert meshio.read(tmp_path / "q6.msh").cells[0].data.shape == (96, 10)
    r = run("solve", "q.msh", "--order", "1", "-o", "x.vtu", cwd=tmp_path)
    assert r.returncode == 2 and "--order 1: the mesh has quadratic tets" in r.stderr
    r = run("trade", "box", "--cells", "4", "2", "2", "--order", "2", "--steps", "10",
            "--rungs", "cg amg", "reduced m5", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert "quadratic" in r.stdout  # the note on the network's rungs


def test_bodies_flag_adds_the_continuum_column_and_refuses_a_quadratic_scene(tmp_path):
    r = run("trade", "box", "--cells", "4", "2", "2", "--steps", "10", "--no-surrogates",
            "--rungs", "reduced m5", "--bodies", "quadratic", "--json", "t.json", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert "vs body" in r.stdout and "exact, quadratic tets" in r.stdout
    import json
    result = json.loads((tmp_path / "t.json").read_text())
    assert result["reference"]["order"] == 2
    assert all("continuum_errors" in row for row in result["rungs"])
    r = run("trade", "box", "--order", "2", "--bodies", "quadratic", cwd=tmp_path)
    assert r.returncode == 2 and "quadratic tets already" in r.stderr


def test_petsc_engine_without_petsc4py_says_what_to_install(folder):
    """With petsc4py missing, --engine petsc is a one-line error naming the make target."""
    code = ("import sys; sys.modules['petsc4py'] = None; from anisofem.cli import main; "
            "sys.exit(main(['solve', 'beam.msh', '--engine', 'petsc', '-o', 'o.vtu']))")
    r = subprocess.run([sys.executable, "-c", code], cwd=folder, capture_output=True, text=True)
    assert r.returncode == 2
    assert "make install-mpi" in r.stderr and len(r.stderr.strip().splitlines()) == 1


@pytest.mark.parametrize("shape, axis", [("box", 0), ("cylinder", 0), ("t", 2), ("y", 2)])
def test_each_shape_holds_the_end_it_stands_on(shape, axis):
    from anisofem.cli import build_parser, scene_of
    args = build_parser().parse_args(["trade", shape])
    scene = scene_of(args)
    X = scene.mesh.vertices
    held = scene.fixed_mask.all(axis=1)
    assert held.any()
    np.testing.assert_allclose(X[held, axis], X[:, axis].min(), atol=1e-12)
    assert args.fixed == ("x-min" if axis == 0 else "z-min")


def test_the_trade_makes_the_folders_of_its_files(tmp_path):
    r = run("trade", "box", "--cells", "4", "1", "1", "--steps", "10", "--no-surrogates",
            "--rungs", "reduced m5", "--json", "results/trade/box.json", "--png",
            "results/trade/box.png", cwd=tmp_path)
    assert r.returncode == 0, r.stderr[-2000:]
    assert (tmp_path / "results" / "trade" / "box.json").exists()
    assert (tmp_path / "results" / "trade" / "box.png").exists()
    assert "machine" in json.loads((tmp_path / "results" / "trade" / "box.json").read_text())


@pytest.mark.parametrize("package", ["anisofem", "export", "anisognn"])
def test_warnings_print_as_one_line(package, tmp_path):
    """`python -m PACKAGE`: a warning raised by a command is one line, "warning: MESSAGE",
    not Python's file, line and source line (the command here warns before it runs)."""
    command = {"anisofem": "anisofem.cli", "export": "export.cli", "anisognn": "anisognn.cli"}
    code = (f"import runpy, sys, warnings; import {command[package]} as cli; "
            f"main = cli.main; cli.main = lambda *a: (warnings.warn('a test'), main(*a))[1]; "
            f"sys.argv = ['{package}', '--help']; runpy.run_module('{package}', "
            f"run_name='__main__')")
    done = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True,
                          text=True)
    assert done.stderr == "warning: a test\n", done.stderr


def test_fit_and_design_name_what_is_wrong_in_their_input(tmp_path):
    """A marker file that is empty, holds text where a number goes, bounds on a parameter not
    fitted, a mesh file where a scene file goes, a region the mesh lacks: one line each."""
    run("mesh", "box", "-o", "beam.msh", cwd=tmp_path)
    (tmp_path / "beam.toml").write_text('mesh = "beam.msh"\n[[boundary]]\nwhere = "x-min"\n'
                                        'held = true\n')
    (tmp_path / "empty.csv").write_text("x,y,z,ux,uy,uz\n")
    (tmp_path / "text.csv").write_text("x,y,z,ux,uy,uz\n0.1,0,0,0,0,-0.001\n0.1,0,0,0,0,abc\n")
    (tmp_path / "ok.csv").write_text("0.1,0,0,0,0,-0.001\n")
    cases = [
        (["fit", "beam.toml", "--markers", "empty.csv", "--params", "young"],
         "--markers: empty.csv holds no marker rows"),
        (["fit", "beam.toml", "--markers", "text.csv", "--params", "young"],
         "--markers: text.csv line 3: 'abc' is not a finite number"),
        (["fit", "beam.toml", "--markers", "ok.csv", "--params", "young", "--bounds",
          "kappa=0:1"], "bounds: 'kappa' is not fitted (fitted: young)"),
        (["fit", "beam.msh", "--markers", "ok.csv", "--params", "young"],
         "beam.msh: not text: a scene file is TOML text that names its mesh"),
        (["design", "beam.toml", "--region", "nowhere", "--tip", "x-max", "--target", "0", "0",
          "0"], "beam.toml: nowhere: the mesh has no physical volume 'nowhere'"),
        (["trade", "box", "--tolerance", "-1"], "tolerance: a share of the static deflection"),
    ]
    for args, message in cases:
        done = subprocess.run([sys.executable, "-m", "anisofem", *args], cwd=tmp_path,
                              capture_output=True, text=True)
        assert done.returncode == 2 and message in done.stderr, (args, done.stderr)
        assert len(done.stderr.strip().splitlines()) == 1, done.stderr


def test_a_static_solve_that_fails_writes_nothing(tmp_path):
    """A pressure of 1e30 Pa in the actuator's cavity, no continuation: the solve fails, says
    so, exits 1 and leaves no file that would look like an answer."""
    scenes = os.path.join(ROOT, "examples", "scenes")
    shutil.copy(os.path.join(scenes, "actuator.msh"), tmp_path)
    with open(os.path.join(scenes, "actuator.toml")) as f:
        (tmp_path / "p.toml").write_text(f.read().replace("pressure = 2.0e4", "pressure = 1e30"))
    r = run("solve", "p.toml", "--continuation", "never", "-o", "p.vtu", cwd=tmp_path)
    assert r.returncode == 1 and "converged: False" in r.stdout
    assert "nothing written to p.vtu" in r.stdout and not (tmp_path / "p.vtu").exists()


def test_runs_made_to_look_write_beside_the_examples_not_over_the_published_results():
    """The swing and the robustness grid, which the README invites a reader to run, write to
    out/ by default; results/, whose files the docs quote, only when told to."""
    import argparse
    import inspect
    import runpy

    from anisofem.studies import robustness
    assert inspect.signature(robustness.run).parameters["out"].default == os.path.join(
        "out", "robustness.json")
    parsers = []

    def capture(self, *args, **kwargs):   # scripts/swing.py's parser, caught before it runs
        parsers.append(self)
        raise SystemExit(0)
    original, argparse.ArgumentParser.parse_args = argparse.ArgumentParser.parse_args, capture
    try:
        with pytest.raises(SystemExit):
            runpy.run_path(os.path.join(ROOT, "scripts", "swing.py"))["main"]([])
    finally:
        argparse.ArgumentParser.parse_args = original
    assert [a.default for a in parsers[0]._actions if a.dest == "json"] == [
        os.path.join("out", "swing.json")]
