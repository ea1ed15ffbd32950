"""Large meshes: the sparsity pattern built from the vertex adjacency matches the element
entries one by one, and `bench --large` measures each path against exact Newton."""
import json

import numpy as np
import scipy.sparse as sp

import anisofem as af
from anisofem.studies import bench_large
from anisofem.physics.assembly import CsrLayout, element_dofs


def test_csr_pattern_holds_every_element_entry_once_and_nothing_else():
    mesh = af.box_beam(cells=(3, 2, 2))
    rng = np.random.default_rng(4)
    fixed = rng.random((mesh.n_vertices, 3)) < 0.3  # rollers: single components held
    scene = af.Scene(mesh, af.Material(), fixed=fixed)
    layout = CsrLayout(mesh.tets, scene.dof_map)
    k = scene.n_free
    ed = element_dofs(mesh.tets, scene.dof_map)
    rows, cols = np.repeat(ed, 12, axis=1), np.tile(ed, (1, 12))
    valid = (rows >= 0) & (cols >= 0)
    # the pattern is exactly the set of (row, col) pairs the elements touch
    expected = sp.csr_matrix((np.ones(valid.sum()), (rows[valid], cols[valid])), shape=(k, k))
    expected.sum_duplicates()
    assert np.array_equal(layout.indptr, expected.indptr)
    assert np.array_equal(layout.indices, expected.indices)
    # each element entry points at its own (row, col), dropped entries at -1
    row_of = np.repeat(np.arange(k), np.diff(layout.indptr))
    assert np.array_equal(layout.map[~valid], np.full((~valid).sum(), -1))
    assert np.array_equal(row_of[layout.map[valid]], rows[valid])
    assert np.array_equal(layout.indices[layout.map[valid]], cols[valid])
    assert np.array_equal(layout.indices[layout.diag], np.arange(k))
    assert np.array_equal(row_of[layout.diag], np.arange(k))


def test_bench_large_compares_each_path_with_exact_newton(tmp_path, capsys):
    out = tmp_path / "large.json"
    report = bench_large.run(out=str(out), sizes={"tiny": (6, 2, 2)})
    rows = {r["path"]: r for r in report["rows"]}
    assert set(rows) == set(bench_large.PATHS)
    for row in rows.values():
        assert row["converged"] and row["tets"] == 120 and row["peak_memory_gb"] > 0
        assert row["difference_to_newton"] < 1e-6
        assert row["steps_converged"] and row["step_s"] > 0 and row["step_newton_iterations"] >= 1
    assert rows["cg amg"]["cg_iterations"] > 0 and rows["newton"]["cg_iterations"] == 0
    assert json.loads(out.read_text())["rows"][0]["size"] == "tiny"
    assert "cg amg" in capsys.readouterr().out


def test_bench_crossover_times_both_paths_per_poisson_ratio(tmp_path, capsys):
    out = tmp_path / "crossover.json"
    report = bench_large.crossover(out=str(out), sizes={"tiny": (6, 2, 2)},
                                   poissons=(0.3, 0.499))
    rows = report["rows"]
    assert sorted((r["poisson"], r["path"]) for r in rows) == [
        (0.3, "cg amg"), (0.3, "newton"), (0.499, "cg amg"), (0.499, "newton")]
    assert all(r["converged"] and r["steps_converged"] for r in rows)
    assert all(r["difference_to_newton"] < 1e-6 for r in rows)
    sags = {(r["poisson"], r["path"]): r["tip_sag_m"] for r in rows}
    assert sags[0.3, "newton"] != sags[0.499, "newton"]  # the ratio reached the material
    table = capsys.readouterr().out
    # 144 unknowns: auto takes exact Newton
    assert sum(line.endswith("| newton") for line in table.splitlines()) == 2
