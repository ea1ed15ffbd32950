"""Why the reduced runtime evaluates its polynomial in numpy: the reduced gradient and Hessian
(runtime.ReducedSimulator's derivative evaluation at one point) as an onnxruntime graph against
the same numpy expressions, for random coefficients of r = 20, 27 and 44.

    python scripts/reduced_onnx.py

Prints microseconds per evaluation (least of 5 repeats of 500), float64 and float32, one
onnxruntime thread. Run alone.
"""
import timeit

import numpy as np
import onnxruntime as ort
from onnx import TensorProto, helper, numpy_helper

from export.runtime import _triple_rows


def graph(r, dtype):
    """An ONNX model q (r,) -> (g (r,), H (r, r)) with random coefficients, and the numpy
    function computing the same."""
    rng = np.random.default_rng(0)
    T = r * (r + 1) * (r + 2) // 6
    W4, S3, C2, c1 = (rng.standard_normal(s).astype(dtype) for s in ((T, r), (r * r, r),
                                                                     (r, r), (r,)))
    rows = _triple_rows(r).reshape(-1)
    consts = {"W4": W4, "S3": S3, "C2": C2, "c1": c1, "rows": rows,
              "rr_r": np.array([r * r, r]), "r_r": np.array([r, r])}
    consts.update({f"k{k}": np.array(k, dtype) for k in (3, 4, 6, 12)})
    node = helper.make_node
    nodes = [node("MatMul", ["W4", "q"], ["A"]), node("Gather", ["A", "rows"], ["Af"]),
             node("Reshape", ["Af", "rr_r"], ["G"]), node("MatMul", ["G", "q"], ["Xf"]),
             node("Reshape", ["Xf", "r_r"], ["X"]), node("MatMul", ["S3", "q"], ["Yf"]),
             node("Reshape", ["Yf", "r_r"], ["Y"]), node("Mul", ["Y", "k3"], ["Y3"]),
             node("Mul", ["X", "k4"], ["X4"]), node("Add", ["C2", "Y3"], ["K1"]),
             node("Add", ["K1", "X4"], ["K"]), node("MatMul", ["K", "q"], ["Kq"]),
             node("Add", ["c1", "Kq"], ["g"]), node("Mul", ["Y", "k6"], ["Y6"]),
             node("Mul", ["X", "k12"], ["X12"]), node("Add", ["C2", "Y6"], ["H1"]),
             node("Add", ["H1", "X12"], ["H"])]
    kind = TensorProto.DOUBLE if dtype == np.float64 else TensorProto.FLOAT
    model = helper.make_model(helper.make_graph(
        nodes, "reduced", [helper.make_tensor_value_info("q", kind, [r])],
        [helper.make_tensor_value_info("g", kind, [r]),
         helper.make_tensor_value_info("H", kind, [r, r])],
        [numpy_helper.from_array(v, k) for k, v in consts.items()]),
        opset_imports=[helper.make_opsetid("", 17)])

    def numpy_eval(q):
        X = (W4 @ q)[rows].reshape(r * r, r) @ q
        Y = S3 @ q
        g = c1 + (C2 + 3 * Y.reshape(r, r) + 4 * X.reshape(r, r)) @ q
        return g, C2 + 6 * Y.reshape(r, r) + 12 * X.reshape(r, r)
    return model, numpy_eval


def main():
    options = ort.SessionOptions()
    options.intra_op_num_threads = 1
    print(f"{'r':>3} {'dtype':>8} {'numpy us':>9} {'onnxruntime us':>15}")
    for r in (20, 27, 44):
        for dtype in (np.float64, np.float32):
            model, numpy_eval = graph(r, dtype)
            session = ort.InferenceSession(model.SerializeToString(), options,
                                           providers=["CPUExecutionProvider"])
            q = (np.random.default_rng(1).standard_normal(r) * 1e-2).astype(dtype)
            g, H = session.run(None, {"q": q})
            g_np, H_np = numpy_eval(q)
            assert np.allclose(g, g_np, rtol=1e-3) and np.allclose(H, H_np, rtol=1e-3)

            def best(fn):
                return min(timeit.repeat(fn, number=500, repeat=5)) / 500 * 1e6
            print(f"{r:>3} {np.dtype(dtype).name:>8} {best(lambda: numpy_eval(q)):>9.1f} "
                  f"{best(lambda: session.run(None, {'q': q})):>15.1f}")


if __name__ == "__main__":
    main()
