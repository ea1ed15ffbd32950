"""The shipped models: anisognn.pretrained("directional") and ("meshgraphnets").

Each lives in anisognn/pretrained/NAME/ with model.pt, the config it was trained with
(config.toml) and its training log (log.jsonl), all produced by `make pretrained` (the repo's
own `python -m anisognn train`); see anisognn/pretrained/README.md.
"""
import os

from .checkpoint import load

FOLDER = os.path.join(os.path.dirname(os.path.abspath(__file__)), "pretrained")
NAMES = ("directional", "meshgraphnets")


def path(name):
    """The model file of a shipped model name (one of NAMES)."""
    if name not in NAMES:
        raise ValueError(f"name: expected one of {NAMES}, got {name!r}")
    file = os.path.join(FOLDER, name, "model.pt")
    if not os.path.isfile(file):
        raise FileNotFoundError(f"pretrained {name!r}: {file} is missing from this install")
    return file


def pretrained(name, device="cpu"):
    """The shipped model `name` ("directional" or "meshgraphnets"), a GraphNet in eval mode."""
    return load(path(name), device)


def model(spec, device="cpu"):
    """A model from a shipped name (one of NAMES) or else a model.pt / checkpoint.pt path."""
    if spec in NAMES:
        return pretrained(spec, device)
    return load(spec, device)
