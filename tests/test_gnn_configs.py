"""The configs in configs/ and experiments/configs/ parse, the shipped models' configs train, and the paper's is
the paper's size."""
import glob
import math
import os

import pytest

import anisognn
from anisognn import train

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


@pytest.mark.parametrize("path", sorted(
    glob.glob(os.path.join(ROOT, "configs", "*.toml"))
    + glob.glob(os.path.join(ROOT, "experiments", "configs", "*", "*.toml"))))
def test_shipped_configs_parse(path):
    config = train.load_config(path)
    assert config.model.dt == config.sampler.dt == 0.02
    assert config.train.iterations > 0


def test_paper_config_is_the_papers():
    m = train.load_config(os.path.join(ROOT, "configs", "paper.toml")).model
    assert (m.latent, m.hidden_layers, m.steps) == (128, 2, 15)


@pytest.mark.parametrize("name", ["directional", "meshgraphnets"])
def test_the_shipped_models_configs_train_and_their_model_takes_two_passes(tmp_path, name):
    """What `make pretrained` runs, for two iterations: the network trains without the
    Galerkin step and the finished model takes two passes."""
    config = train.load_config(os.path.join(ROOT, "configs", f"shipped-{name}.toml"),
                               iterations=2, out=str(tmp_path / name))
    trained, summary = train.train(config, progress=False)
    assert summary["iterations"] == 2 and math.isfinite(summary["final_loss"])
    assert not trained.config.galerkin
    finished = anisognn.load(str(tmp_path / name / "model.pt"))
    assert finished.config.galerkin and finished.config.galerkin_passes == 2
