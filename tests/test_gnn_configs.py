"""The configs shipped in configs/ parse, and the CPU one's model is the documented size."""
import glob
import os

import pytest

from anisognn import train

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


@pytest.mark.parametrize("path", sorted(
    glob.glob(os.path.join(ROOT, "configs", "*.toml"))
    + glob.glob(os.path.join(ROOT, "configs", "*", "*.toml"))))
def test_shipped_configs_parse(path):
    config = train.load_config(path)
    assert config.model.dt == config.sampler.dt == 0.02
    assert config.train.iterations > 0


def test_paper_config_is_the_papers():
    m = train.load_config(os.path.join(ROOT, "configs", "paper.toml")).model
    assert (m.latent, m.hidden_layers, m.steps) == (128, 2, 15)
