"""The speed/accuracy trade: anisofem.trade and `python -m anisofem trade`."""
import json
import math
import subprocess
import sys

import numpy as np
import pytest

import anisofem as af
from anisofem.studies import trade as ladder
from anisofem.studies import rungs as ladder_rungs
from anisofem.studies import trade_report


@pytest.fixture(scope="module")
def result(beam):
    d = np.array([np.cos(np.radians(40)), 0.0, np.sin(np.radians(40))])
    scene = af.Scene(beam, af.Material(1e5, 0.48, 1000.0, d, 1e5),
                     fixed=af.metrics.end_vertices(beam, 0, "min"), gravity=(0, 0, -9.81))
    return ladder.trade(scene, steps=20, rungs=ladder_rungs.fem_rungs(), progress=False)


def test_exact_is_the_reference_and_capped_rungs_are_not(result):
    rows = {r["name"]: r for r in result["rungs"]}
    assert result["times"] == pytest.approx([0.2, 0.4])
    assert rows["exact"]["errors"] == [0.0, 0.0] and rows["exact"]["stable"]
    assert min(rows["newton x1"]["errors"]) > 1e-6
    assert rows["exact dt x5"]["dt"] == pytest.approx(0.1)
    for r in result["rungs"]:
        assert r["kind"] in ("fem", "reduced") and len(r["errors"]) == 2
        assert r["max_error"] == max(r["errors"]) and math.isfinite(r["ms_per_step"])
        assert r["min_volume_ratio"] > 0.5 and r["stable"]
    # the recommendation is the cheapest stable rung within the tolerance
    within = [r for r in result["rungs"] if r["stable"] and r["max_error"] <= 0.01]
    assert result["recommended"] == min(within, key=lambda r: r["ms_per_step"])["name"]


def test_the_front_holds_the_rungs_no_other_beats_at_every_time():
    rows = [{"name": "a", "ms_per_step": 1.0, "errors": [0.1, 0.1], "stable": True},
            {"name": "b", "ms_per_step": 2.0, "errors": [0.2, 0.05], "stable": True},
            {"name": "c", "ms_per_step": 3.0, "errors": [0.2, 0.1], "stable": True},
            {"name": "d", "ms_per_step": 0.5, "errors": [0.0, 0.0], "stable": False}]
    ladder.mark_front(rows)
    assert [r["on_front"] for r in rows] == [True, True, False, False]


def test_rungs_must_start_with_exact_and_land_on_the_checked_times(beam):
    scene = af.default_scene(beam)
    with pytest.raises(ValueError, match="rungs: the first rung must be the exact one"):
        ladder.trade(scene, rungs=[ladder_rungs.fem_rung("newton x1", iterations=1)])
    with pytest.raises(ValueError, match="steps: must be a multiple of 10"):
        ladder.trade(scene, steps=15)
    with pytest.raises(TypeError, match="bogus: not an option"):
        ladder_rungs.fem_rung("x", bogus=1)
    for tolerance in (-1, 0, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="tolerance: a share of the static deflection"):
            ladder.trade(scene, steps=10, tolerance=tolerance)


def run(*args, cwd):
    return subprocess.run([sys.executable, "-m", "anisofem", *args], cwd=cwd,
                          capture_output=True, text=True, timeout=600)


def test_trade_command_on_a_mesh_file_with_the_surrogates(tmp_path):
    assert run("mesh", "box", "-o", "beam.msh", cwd=tmp_path).returncode == 0
    r = run("trade", "beam.msh", "--fixed", "x-min", "--gravity", "0", "0", "-9.81",
            "--fiber", "0.766", "0", "0.643", "--kappa", "1e5", "--steps", "20",
            "--json", "t.json", "--png", "t.png", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    print(r.stdout)
    out = json.loads((tmp_path / "t.json").read_text())
    assert out["scene"]["tets"] == 200 and out["scene"]["dt"] == 0.02
    assert out["scene"]["steps"] == 20
    rows = {row["name"]: row for row in out["rungs"]}
    assert rows["exact"]["errors"] == [0.0, 0.0]
    assert rows["newton x1"]["max_error"] > 0
    surrogates = [row for row in out["rungs"] if row["kind"] == "surrogate"]
    assert {"directional (shipped)", "directional + newton x1", "directional + cg x40",
            "directional.onnx (shipped)",
            "no network + cg x40"} <= {s["name"] for s in surrogates}
    assert all(np.isfinite(s["errors"]).all() for s in surrogates)
    # forty CG iterations after the step bring the end of the transient closer to the FEM
    shipped, refined = rows["directional (shipped)"], rows["directional + cg x40"]
    assert refined["errors"][-1] < 0.5 * shipped["errors"][-1]
    assert out["recommended"] in rows
    assert (tmp_path / "t.png").stat().st_size > 20_000
    assert "cheapest stable rung within 0.01" in r.stdout


@pytest.mark.parametrize("shape, flags", [("cylinder", ["--cells", "6", "1"]),
                                          ("t", ["--fixed", "z-min"])])
def test_trade_command_on_generated_shapes(tmp_path, shape, flags):
    r = run("trade", shape, *flags, "--steps", "10", "--no-surrogates", "--json", "t.json",
            cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    out = json.loads((tmp_path / "t.json").read_text())
    assert out["rungs"][0]["name"] == "exact" and out["rungs"][0]["max_error"] == 0
    assert all(row["stable"] for row in out["rungs"])


def test_trade_command_errors_are_one_line(tmp_path):
    r = run("trade", "box", "--steps", "15", cwd=tmp_path)
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert "steps: must be a multiple of 10" in r.stderr


@pytest.mark.parametrize("material", [af.Material(1e5, 0.499, 1000.0, (1, 0, 0), 1e5),
                                      af.Material(1e5, 0.48, 1000.0, (1, 0, 0), 1e7)],
                         ids=["nu 0.499", "kappa 100 E"])
def test_surrogate_rungs_at_the_extremes_report_instead_of_returning_nan(beam, material):
    """Where the networks fail, the table says so (unstable, or inf once a state is not
    finite), never NaN."""
    scene = af.Scene(beam, material, fixed=af.metrics.end_vertices(beam, 0, "min"),
                     gravity=(0, 0, -9.81))
    notes = []
    rungs = [ladder_rungs.fem_rung("exact")] + ladder_rungs.registered_rungs(scene, 0.02, notes)
    out = ladder.trade(scene, steps=10, rungs=rungs, progress=False)
    assert len(out["rungs"]) >= 6 and out["rungs"][0]["stable"]
    print([(r["name"], r["max_error"], r["stable"]) for r in out["rungs"]], notes)
    for r in out["rungs"]:
        assert not any(math.isnan(e) for e in r["errors"] + [r["energy_drift"]])


@pytest.mark.filterwarnings("ignore::anisofem.InversionWarning")
def test_surrogates_are_not_scored_against_an_inverted_or_foreign_reference():
    mesh = af.box_beam(cells=(10, 2, 2))
    x = mesh.vertices[:, 0]

    def scene(model):
        return af.Scene(mesh, af.Material(1e5, 0.48, 1000.0, (1, 0, 0), 1e5, model=model),
                        fixed=np.flatnonzero(x <= 1e-9), gravity=(0, 0, -98.1))

    still = ladder_rungs.Rung("still", "surrogate",
                        lambda scene, dt: lambda x, v: (x, v, {"failed": False}))
    rungs = [ladder_rungs.fem_rung("exact"), ladder_rungs.fem_rung("newton x1", iterations=1),
             still]
    stvk = ladder.trade(scene("stvk"), steps=10, rungs=list(rungs), progress=False)
    assert [r["name"] for r in stvk["rungs"]] == ["exact", "newton x1"]
    assert stvk["rungs"][0]["inverted"] > 0
    assert any("surrogate rungs not scored" in n for n in stvk["notes"])
    nh = ladder.trade(scene("neohookean"), steps=10, rungs=list(rungs), progress=False)
    assert [r["name"] for r in nh["rungs"]] == ["exact", "newton x1", "still"]
    assert all(r["inverted"] == 0 for r in nh["rungs"]) and not nh["notes"]
    notes = []
    assert ladder_rungs.registered_rungs(scene("neohookean"), 0.02, notes) == []
    assert "trained on the StVK base material" in notes[0]
    assert notes[1].startswith("ONNX rung skipped: runtime.py steps the trained material (StVK")
    notes = []
    assert ladder_rungs.registered_rungs(scene("stvk"), 0.01, notes) == []
    assert notes == ["surrogate rungs skipped: the shipped models step dt = 0.02 s, the trade "
                     "runs dt = 0.01 s",
                     "ONNX rung skipped: the model steps dt = 0.02 s, the trade runs dt = 0.01 s"]


def test_plot_labels_of_crowded_rungs_stack_up_inside_the_axes():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    rows = [{"name": f"rung {k}", "ms_per_step": 10.0, "max_error": 1.0} for k in range(6)]
    fig, ax = plt.subplots()
    ax.set_xscale("log")
    ax.set_yscale("log")
    xlim, ylim = (1.0, 100.0), (1e-3, 2.0)
    ax.set_xlim(*xlim)
    ax.set_ylim(*ylim)
    labels, top = trade_report._label_positions(ax, rows, lambda r: r["max_error"], xlim, ylim)
    ys = [xytext[1] for _, _, xytext, _ in labels]
    plt.close(fig)
    assert all(b > a for a, b in zip(ys, ys[1:]))  # each moved above the one before
    assert [moved for *_, moved in labels][1:] == [True] * 5
    assert top > ys[-1] > ylim[1]  # six labels stacked above 1 rise past 2: the plot grows


def test_bodies_measure_every_rung_against_the_finest_mesh_of_the_body():
    mesh = af.box_beam(cells=(4, 2, 2))

    def cantilever(mesh):
        return af.Scene(mesh, af.Material(1e5, 0.48, 1000.0, (1, 0, 0), 1e5),
                        fixed=np.flatnonzero(mesh.vertices[:, 0] <= 1e-9),
                        gravity=(0, 0, -9.81))
    scene = cantilever(mesh)
    bodies = [("order 2", cantilever(mesh.raised())),
              ("refined, order 2", cantilever(mesh.refined().raised()))]
    result = af.trade(scene, steps=10, rungs=[ladder_rungs.fem_rung("exact"),
                                              ladder_rungs.fem_rung("newton x1", "newton",
                                                              iterations=1)],
                      progress=False, bodies=bodies, tolerance=0.05)
    rows = {r["name"]: r for r in result["rungs"]}
    assert result["reference"]["name"] == "refined, order 2"
    assert rows["refined, order 2"]["continuum_errors"] == [0.0, 0.0, 0.0, 0.0]
    assert rows["order 2"]["kind"] == "discretization"
    # linear tets lock: the exact rollout is far from the body, the quadratic one near it
    assert rows["exact"]["max_continuum_error"] > 0.3 > 0.05 > rows["order 2"][
        "max_continuum_error"]
    assert rows["exact"]["max_error"] == 0.0 and rows["order 2"]["max_error"] > 0.3
    # a reduced model of the finest body, drawn on the scene's mesh, follows the body
    reduced = rows["reduced m4 s16 of the body"]
    assert reduced["kind"] == "reduced" and reduced["body"] == "refined, order 2"
    assert reduced["stable"] and reduced["max_error"] > 0.3
    assert reduced["max_continuum_error"] < 0.02
    assert result["recommended_continuum"] == "reduced m4 s16 of the body"
    assert "vs body" in trade_report.trade_table(result)
    with pytest.raises(ValueError, match="bodies"):
        af.trade(scene, steps=10, rungs=[ladder_rungs.fem_rung("exact")], progress=False,
                 bodies=[("other", cantilever(af.box_beam(cells=(5, 2, 2))))])


def test_the_table_marks_a_rung_that_inverts_elements_and_says_what_min_j_is(result):
    """A rung whose elements turned inside out reads "!" beside its min J, "stable" or not;
    the others read a space; a line under the table says what min J and the mark mean."""
    rows = [dict(r) for r in result["rungs"]]
    rows[1].update(inverted=3, min_volume_ratio=-0.82)
    lines = trade_report.trade_table({**result, "rungs": rows}).splitlines()
    marked = [line for line in lines if line.startswith(rows[1]["name"] + " ")]
    assert len(marked) == 1 and " -0.82! " in marked[0]
    assert not any("!" in line for line in lines if line.startswith(rows[0]["name"] + " "))
    assert any(line.startswith("min J: the smallest volume ratio det F") for line in lines)
