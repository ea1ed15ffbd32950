"""`python -m export bench`: seconds per step of an exported model in onnxruntime (the session
alone, and OnnxSimulator.step with its input checks) vs the same step in torch (no grad), on
box-beam cantilevers of about 100, 1,000 and 10,000 tets, for the shipped directional model
and the paper's configuration (128 wide, 15 steps; random weights: the cost
does not depend on their values). Prints a table and writes JSON (atomically)."""
import os
import tempfile

import numpy as np
import onnxruntime
import torch

from anisofem import box_beam, default_scene
from anisofem.io.output import publish, result_path
from anisofem.studies.timing import best_time
from anisognn import shipped
from anisognn.bench import MESHES
from anisognn.model import GraphNet, ModelConfig, with_galerkin

from ..runtime import INPUTS, OnnxSimulator
from ..writers.to_onnx import Step, export

#: the paper's reported step time for 100 elements (desktop GPU, LibTorch), s
PAPER_STEP_S = 9e-3


def models():
    """{label: GraphNet}: the shipped directional model, its network alone and with one Galerkin
    pass if it takes more (two if it takes one; the same weights, when it has the step) and a
    paper-sized directional one."""
    torch.manual_seed(0)
    paper = GraphNet(ModelConfig(latent=128, steps=15, aggregation="directional"))
    torch.nn.init.normal_(paper.decoder[-1].weight, std=0.01)
    ours = shipped.pretrained("directional")
    c = ours.config
    size = f"{c.latent} wide, {c.steps} steps" + (f", {c.galerkin_passes} passes" * c.galerkin)
    out = {f"shipped ({size})": ours}
    if c.galerkin:
        out["its network alone"] = with_galerkin(ours, False)
        other = with_galerkin(ours, True, 1 if c.galerkin_passes > 1 else 2)
        out[f"it, {other.config.stepping}"] = other
    out["paper (128 wide, 15 steps)"] = paper.eval()
    return out


def bench_case(net, onnx_path, cells):
    """Best-of-k seconds per step of one model on a box beam of cells: torch, session, step."""
    scene = default_scene(box_beam(cells=cells))
    mesh = scene.mesh
    sim = OnnxSimulator(onnx_path, mesh.vertices, mesh.tets, scene.fixed_mask)
    x = scene.initial_positions()
    v = np.zeros_like(x)
    f = scene.external_force
    feed = dict(sim.constants, positions=x, velocities=v, external_force=f)
    step = Step(net)
    inputs = [torch.as_tensor(feed[name]) for name, _, _ in INPUTS]  # what onnxruntime gets
    feed = {i.name: feed[i.name] for i in sim.session.get_inputs()}

    def torch_step():
        with torch.no_grad():
            step(*inputs)
    return {"tets": mesh.n_tets, "edges": len(feed["senders"]),
            "torch_s": best_time(torch_step, 30),
            "onnxruntime_s": best_time(lambda: sim.session.run(None, feed), 30),
            "runtime_step_s": best_time(lambda: sim.step(x, v, f), 30)}


def run(sizes=tuple(MESHES), out=result_path("bench_export.json")):
    """Time every model on every mesh size; print the table, write JSON to out (if given)."""
    rows = []
    with tempfile.TemporaryDirectory() as folder:
        for label, net in models().items():
            path = export(net, os.path.join(folder, "model.onnx"))
            for size in sizes:
                row = bench_case(net, path, MESHES[size])
                row["config"] = label
                rows.append(row)
    report = {"rows": rows, "torch_threads": torch.get_num_threads(),
              "onnxruntime": onnxruntime.__version__, "torch": torch.__version__,
              "cpu_count": os.cpu_count(), "paper_step_s": PAPER_STEP_S}
    return publish(report, print_report, out)


def print_report(report):
    print(f"one step per call, best of up to 30 (torch {report['torch_threads']} threads, "
          f"onnxruntime default threads, {report['cpu_count']} CPUs)")
    print(f"{'config':36} {'tets':>6} | {'torch ms':>9} {'ort ms':>8} {'step ms':>8} "
          f"{'torch/ort':>9}")
    for r in report["rows"]:
        print(f"{r['config']:36} {r['tets']:6d} | {1e3 * r['torch_s']:9.2f} "
              f"{1e3 * r['onnxruntime_s']:8.2f} {1e3 * r['runtime_step_s']:8.2f} "
              f"{r['torch_s'] / r['onnxruntime_s']:9.2f}")
    print(f"(paper: {1e3 * PAPER_STEP_S:g} ms per step for 100 elements, desktop GPU, LibTorch)")
