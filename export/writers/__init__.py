"""What writes the deployed files: a trained network as model.onnx (`to_onnx`), a scene's
constant tensors for an engine without numpy (`bake`), and reduced and framed models as arrays
files for the runtimes (`reduced`)."""
