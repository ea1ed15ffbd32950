"""export: ONNX export and torch-free runtime (not built yet, see issue 5)."""
