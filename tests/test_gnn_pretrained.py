"""The shipped models: they load, they are what their logged training produced (parameter
digest), they were trained by the configs shipped beside them, and their rollouts of every
evaluation scene stay finite and bounded for 1,000 steps."""
import json
import os

import numpy as np
import pytest

import anisognn
from anisognn import evaluate, shipped, train


def read_log(name):
    with open(os.path.join(shipped.FOLDER, name, "log.jsonl")) as f:
        return [json.loads(line) for line in f]


@pytest.mark.parametrize("name", shipped.NAMES)
def test_shipped_model_is_its_logged_training(name):
    model = anisognn.pretrained(name)
    config = train.load_config(os.path.join(shipped.FOLDER, name, "config.toml"))
    assert model.config.to_dict() == config.model.__dict__
    assert model.config.aggregation == ("directional" if name == "directional" else "sum")
    done = read_log(name)[-1]
    assert done["event"] == "done" and done["iterations"] == config.train.iterations
    assert done["digest"] == train.parameter_digest(model)


def test_both_shipped_models_had_the_same_budget():
    a, b = (train.load_config(os.path.join(shipped.FOLDER, n, "config.toml"))
            for n in shipped.NAMES)
    assert a.train.__dict__ | {"out": ""} == b.train.__dict__ | {"out": ""}
    assert a.sampler == b.sampler
    assert a.model.__dict__ | {"aggregation": ""} == b.model.__dict__ | {"aggregation": ""}


@pytest.mark.parametrize("name", shipped.NAMES)
def test_thousand_step_rollouts_stay_finite_and_bounded(name):
    run = evaluate.model_rollout(anisognn.pretrained(name))
    for case in evaluate.cases():
        positions = run(case.scene, evaluate.STEPS)
        assert np.isfinite(positions).all(), case.label
        moved = np.linalg.norm(positions - case.scene.mesh.vertices, axis=2).max()
        assert moved < case.scene.mesh.size, case.label
