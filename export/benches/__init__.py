"""The benches of what is deployed: onnxruntime against torch per step (`onnx`), and a reduced
or framed model's step in the library, the numpy runtime and the C runtime (`reduced`)."""
