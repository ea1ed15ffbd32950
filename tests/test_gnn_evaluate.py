"""The evaluation suite's metrics, checked on simulators whose answers are known: anisofem's
own rollout (errors vanish), a body that never moves (errors equal the FEM's response), and one
that blows up (flagged, not crashed); then the CLI end to end."""
import json
import os
import subprocess
import sys

import numpy as np
import pytest
import torch

from anisognn import checkpoint, evaluate, shipped
from anisognn.model import GraphNet, ModelConfig

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


@pytest.fixture(scope="module")
def suite():
    return evaluate.cases()


def stay_put(scene, steps, x0=None):
    x = scene.mesh.vertices if x0 is None else x0
    return np.broadcast_to(x, (steps + 1,) + x.shape)


def blow_up(scene, steps, x0=None):
    out = np.array(stay_put(scene, steps, x0))
    out[-1] = np.nan
    return out


def give_up(scene, steps, x0=None):
    raise FloatingPointError("rollout: the predicted state is not finite")


@pytest.fixture(scope="module")
def results(suite):
    sims = {"fem": evaluate.fem_rollout, "still": stay_put, "nan": blow_up, "raise": give_up}
    return evaluate.evaluate(sims, steps=300, suite=suite)[0]


def test_suite_has_the_papers_cases(suite):
    groups = [c.group for c in suite]
    assert groups.count("cantilever") == 4 and groups.count("imbalance") == 6
    assert groups.count("tension") == 1


def test_fem_rollout_scores_as_the_equilibrium(results, suite):
    for row, case in zip(results["fem"], suite):
        assert row["bounded"]
        assert row["tip_ratio"] < 1e-6, case.label
        assert row["volume_change_error"] < 1e-6, case.label
        assert abs(row["energy_gap_ratio"]) < 1e-6, case.label
        load = np.abs(case.scene.external_force).sum(axis=1).mean()
        assert row["force_mean"] < 1e-6 * load, case.label
        assert row["rest_acceleration_max"] < 1e-6 * evaluate.GRAVITY, case.label
        assert row["rest_stiffness"] == pytest.approx(1.0, abs=1e-12), case.label


def test_a_body_that_stays_put_misses_by_the_whole_response(results, suite):
    for row in results["still"]:
        assert row["tip_ratio"] == pytest.approx(1.0, abs=1e-12)
        assert row["energy_gap_ratio"] == pytest.approx(1.0, abs=1e-9)
        assert row["volume_change_max"] < 1e-12
        assert row["volume_change_error"] == pytest.approx(1.0, abs=1e-9)
        assert row["force_mean"] > 0
        assert row["rest_acceleration_max"] == 0.0  # it stays at the FEM's rest too
        assert row["rest_stiffness"] == 0.0  # and at every other still state


def test_rest_stiffness_is_the_share_of_the_fems_response(suite):
    """A simulator that takes a fixed share of anisofem's step from every state at rest has
    that share of its stiffness at rest."""
    def damped(scene, steps, x0=None):
        positions = evaluate.fem_rollout(scene, steps, x0)
        return positions[0] + 0.3 * (positions - positions[0])
    case = suite[0]
    x_fem = evaluate.anisofem.solve(case.scene).x
    assert evaluate.rest_stiffness(damped, case.scene, x_fem)["rest_stiffness"] == pytest.approx(
        0.3, rel=1e-9)


def test_fibers_along_the_beam_stiffen_bending(results, suite):
    tip = {c.label: r["tip_fem"] for c, r in zip(suite, results["fem"]) if c.group == "cantilever"}
    for kind in ("box", "cylinder"):
        assert tip[f"{kind}, fibers orthogonal to gravity"] < 0.6 * tip[
            f"{kind}, fibers parallel to gravity"]


def test_a_blown_up_rollout_is_flagged(results, suite):
    for name in ("nan", "raise"):
        assert all(not r["finite"] and not r["bounded"] for r in results[name])
        assert all(r["rest_acceleration_mean"] == np.inf for r in results[name])
        assert all(np.isnan(r["rest_stiffness"]) for r in results[name])
    text = evaluate.format_tables(results, suite, ratio=("still", "fem"))
    assert "NO" in text and "still/fem" in text
    s = evaluate.summary(results, suite, ratio=("still", "fem"))
    assert not s["nan"]["all_bounded"] and s["fem"]["all_bounded"]
    assert s["still"]["tip_ratio_mean"] == pytest.approx(1.0)


def test_evaluate_command_writes_both_models_side_by_side(tmp_path):
    paths = []
    for aggregation in ("directional", "sum"):
        torch.manual_seed(0)
        model = GraphNet(ModelConfig(latent=8, steps=1, aggregation=aggregation))
        paths.append(str(tmp_path / aggregation / "model.pt"))
        checkpoint.save(paths[-1], model)
    out = tmp_path / "eval.json"
    run = subprocess.run([sys.executable, "-m", "anisognn", "evaluate", *paths, "--steps", "3",
                          "--json", str(out)], cwd=ROOT, capture_output=True, text=True,
                         timeout=600)
    assert run.returncode == 0, run.stderr[-2000:]
    assert "Table 1" in run.stdout and "directional/model.pt/sum/model.pt" in run.stdout
    report = json.loads(out.read_text())
    assert set(report["results"]) == {"directional/model.pt", "sum/model.pt", "fem"}
    assert "ratios" in report["summary"] and report["steps"] == 3


def test_unknown_model_names_are_refused():
    with pytest.raises(ValueError, match="name: expected one of"):
        shipped.path("graphnet")


def test_a_case_whose_reference_turns_inside_out_is_not_scored(suite):
    scene = suite[0].scene
    crushed = evaluate.Case("cantilever", "box under 100 g", evaluate.Scene(
        scene.mesh, scene.material, fixed=scene.fixed_mask, gravity=(0, 0, -981.0)))
    results, scored, not_scored = evaluate.evaluate({"still": stay_put}, steps=5,
                                                    suite=[suite[0], crushed])
    assert [c.label for c in scored] == [suite[0].label]
    assert len(results["still"]) == 1
    assert not_scored[0]["case"] == "box under 100 g"
    assert "inside out (StVK)" in not_scored[0]["reason"]
    assert np.isnan(evaluate.summary({"still": []}, [], None)["still"]["tip_ratio_mean"])
