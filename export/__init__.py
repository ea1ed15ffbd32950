"""export: what is deployed, what writes it, and what measures it.

- Deployed: the C runtime of reduced and framed models (c/, the one implementation engines
  link, Python calls through `native` and the browser runs as WebAssembly), and the numpy
  runtimes, one file each, its readable reference (`runtime`: also model.onnx through
  onnxruntime, OnnxSimulator; `framed_runtime`).
- Writers (`writers`): a trained anisognn model as ONNX (`python -m export MODEL -o
  model.onnx`), baked scenes, reduced and framed model files.
- Benches (`benches`): `python -m export bench`, `bench-reduced`.

This package imports nothing at import time, so `from export.runtime import OnnxSimulator`
needs no torch.

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
