"""Checkpoints: written atomically (temporary file, then rename), read with
torch.load(weights_only=True) and checked, so that a corrupted or foreign file gives a clear
error instead of a crash deep in torch."""
import os

import torch

from anisofem.io.output import atomic_path

from .model import GraphNet, ModelConfig

FORMAT = "anisognn-checkpoint"
VERSION = 1


def save(path, model, **extra):
    """Write the model (config + state_dict) and extra entries (tensors, numbers, strings,
    lists and dicts of them) to path atomically."""
    payload = {"format": FORMAT, "version": VERSION, "config": model.config.to_dict(),
               "model": model.state_dict(), **extra}
    with atomic_path(path, ".pt") as tmp:
        torch.save(payload, tmp)


def read(path, map_location="cpu"):
    """The checked contents of a checkpoint file (a dict with "config", "model", ...)."""
    path = os.fspath(path)
    if not os.path.isfile(path):
        raise FileNotFoundError(f"checkpoint: no such file {path!r}")
    try:
        payload = torch.load(path, map_location=map_location, weights_only=True)
    except Exception as err:
        raise ValueError(f"checkpoint {path!r}: not a readable torch file (corrupted or "
                         f"truncated?): {type(err).__name__}: {str(err)[:200]}") from None
    if not isinstance(payload, dict) or payload.get("format") != FORMAT:
        raise ValueError(f"checkpoint {path!r}: not an anisognn checkpoint (no "
                         f"format={FORMAT!r} entry)")
    if payload.get("version") != VERSION:
        raise ValueError(f"checkpoint {path!r}: format version {payload.get('version')!r}, "
                         f"this anisognn reads version {VERSION}")
    return payload


def model_from(payload):
    """A GraphNet with the checkpoint's config and weights."""
    try:
        config = ModelConfig(**payload["config"])
    except (TypeError, ValueError) as err:
        raise ValueError(f"checkpoint: bad model config: {err}") from None
    model = GraphNet(config)
    try:
        model.load_state_dict(payload["model"])
    except RuntimeError as err:
        raise ValueError(f"checkpoint: weights do not fit the config: {str(err)[:300]}") from None
    return model


def load(path, device="cpu"):
    """The trained model stored at path, in eval mode on device (anisognn.load)."""
    model = model_from(read(path))
    return model.to(device).eval()
