"""`python -m anisognn bench`: per-step cost of the network (inference), of the physics loss
(anisofem energy + gradient) and of one training iteration, on box-beam cantilevers of about
100, 1,000 and 10,000 tets, for a small configuration and the paper's, both aggregations. Prints a
table and writes JSON (atomically)."""
import time

import numpy as np
import torch

from anisofem import box_beam, default_scene
from anisofem.io.output import publish, result_path
from anisofem.studies.timing import best_time

from .graph import from_scene
from .model import GraphNet, ModelConfig
from .sampler import Sample, Sampler, SamplerConfig
from .train import batch_loss, make_batch

MESHES = {"1e2": (5, 2, 2), "1e3": (10, 4, 5), "1e4": (25, 10, 8)}
CONFIGS = {"small (64 wide, 8 steps)": dict(latent=64, steps=8),
           "paper (128 wide, 15 steps)": dict(latent=128, steps=15)}


def bench_case(cells, model_kwargs, aggregation):
    """Best-of-k seconds of inference, loss and training iteration on a box beam of cells."""
    scene = default_scene(box_beam(cells=cells))
    x = scene.initial_positions()
    batch = make_batch([Sample(scene, x, np.zeros_like(x))], 0.02, "cpu")
    model = GraphNet(ModelConfig(aggregation=aggregation, **model_kwargs))
    optimizer = torch.optim.Adam(model.parameters(), lr=1e-5)

    def inference():
        with torch.no_grad():
            model(batch.x, batch.v, batch.f_ext, batch.graph)

    def loss_only():
        batch.potential.energy_gradient(x)

    def iteration():
        loss, _ = batch_loss(model, batch, 0.02)
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
    return {"tets": scene.mesh.n_tets, "edges": int(batch.graph.n_edges),
            "inference_s": best_time(inference, 30),
            "loss_s": best_time(loss_only, 30),
            "iteration_s": best_time(iteration, 10)}


def bench_sampler(count=32):
    """Mean seconds per training sample (scene, pre-deformation rollout, noise) and per graph
    built from a sample."""
    times = {}
    sampler = Sampler(0, SamplerConfig())
    sampler.sample(0)  # compile
    t0 = time.perf_counter()
    samples = [sampler.sample(i) for i in range(1, count + 1)]
    times["sample_s"] = (time.perf_counter() - t0) / count
    t1 = time.perf_counter()
    for s in samples:
        from_scene(s.scene)
    times["graph_s"] = (time.perf_counter() - t1) / count
    return times


def run(out=result_path("bench_anisognn.json")):
    """Time every case; print the table, write JSON to out (if given)."""
    rows = []
    for label, kwargs in CONFIGS.items():
        for aggregation in ("directional", "sum"):
            for size, cells in MESHES.items():
                row = bench_case(cells, kwargs, aggregation)
                row.update(config=label, aggregation=aggregation)
                rows.append(row)
    report = {"rows": rows, "sampler": bench_sampler(), "torch_threads": torch.get_num_threads()}
    return publish(report, print_report, out)


def print_report(report):
    rows = report["rows"]
    print(f"anisognn per step on the CPU ({report['torch_threads']} torch threads), batch of 1")
    print(f"{'config':27} {'aggregation':11} {'tets':>6} | {'inference ms':>12} "
          f"{'loss ms':>8} {'train it ms':>11} {'loss share':>10}")
    for r in rows:
        print(f"{r['config']:27} {r['aggregation']:11} {r['tets']:6d} | "
              f"{1e3 * r['inference_s']:12.2f} {1e3 * r['loss_s']:8.3f} "
              f"{1e3 * r['iteration_s']:11.2f} {r['loss_s'] / r['iteration_s']:10.1%}")
    sam = report["sampler"]
    print(f"\nsampler: {1e3 * sam['sample_s']:.1f} ms per training sample, "
          f"{1e3 * sam['graph_s']:.1f} ms per graph built from it")
