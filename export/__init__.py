"""export: a trained anisognn model as ONNX (to_onnx, `python -m export MODEL -o model.onnx`)
and runtime.py, the one-file numpy + onnxruntime runtime (OnnxSimulator). This package imports
nothing at import time, so `from export.runtime import OnnxSimulator` needs no torch.

    sim = OnnxSimulator(export.model_path("directional"), vertices, tets, ...)
"""
import os

#: The shipped ONNX models, installed with the package.
MODELS = os.path.join(os.path.dirname(os.path.abspath(__file__)), "models")
NAMES = ("directional", "meshgraphnets")


def model_path(name):
    """The path of the shipped ONNX model `name` ("directional" or "meshgraphnets")."""
    if name not in NAMES:
        raise ValueError(f"name: expected one of {NAMES}, got {name!r}")
    return os.path.join(MODELS, f"{name}.onnx")
