"""export: a trained anisognn model as ONNX (to_onnx, `python -m export MODEL -o model.onnx`)
and runtime.py, the one-file numpy + onnxruntime runtime (OnnxSimulator). This package imports
nothing at import time, so `from export.runtime import OnnxSimulator` needs no torch."""
