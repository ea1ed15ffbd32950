"""How the exported network's step and anisofem's steps scale with the mesh, and where the
network would be ten times faster than the exact step: the 0.1 x 0.02 x 0.02 m cantilever of
the trade table (fibers at 40 degrees in x-z, kappa = E, gravity, dt = 0.02 s) refined 1, 2, 4
and 8 times per direction (200 to 102,400 tets).

    python scripts/crossover.py [--refinements 1 2 4 8] [--json crossover.json] [--gpu]

Per size, ms per step (steps 2 to STEPS, the first holding set-up and compilation) of: the
exact step (Newton with the default direct solver, up to 12,800 tets: at 10^5 one SuperLU
factorization takes tens of seconds), the exact step by multigrid CG (the large-mesh path, the
same tolerance), the kept factorization to rtol 1e-2 ("reuse", with multigrid CG to rtol
1e-2 the trade table's fastest accurate rung; up to 12,800 tets), the shipped
directional.onnx by export/runtime.py (and with --gpu the same model in torch on the GPU,
float32 and float64); and the ONNX network's tip error against the exact
rollout after STEPS steps, over the tip's static deflection. Then the exponents of the step
times between the two largest sizes. Run alone.
"""
import argparse
import math
import time

import numpy as np
import torch

import anisofem
from anisofem.io.output import result_path, write_json
from anisofem.solvers.solve import Stepper
from anisognn import pretrained
from anisognn.rollout import network_step

import export
from export.runtime import OnnxSimulator

STEPS = 10
DT = 0.02
MODEL = export.model_path("directional")
FIBER = (math.cos(math.radians(40)), 0.0, math.sin(math.radians(40)))
#: the FEM paths: label -> (method options, largest tets it runs on)
PATHS = {"exact": ({}, 12_800), "exact, multigrid CG": ({"method": "cg", "preconditioner": "amg"},
                                                        10 ** 6),
         "reuse rtol 1e-2": ({"method": "reuse", "rtol": 1e-2}, 12_800)}


def scene_of(refinement):
    mesh = anisofem.box_beam(size=(0.1, 0.02, 0.02), cells=(10 * refinement, 2 * refinement,
                                                             2 * refinement))
    material = anisofem.Material(1e5, 0.48, 1000.0, FIBER, 1e5)
    return anisofem.Scene(mesh, material, fixed=anisofem.physics.metrics.end_vertices(mesh, 0,
                          "min"), gravity=(0, 0, -9.81))


def timed_steps(advance, x):
    """Positions after each of STEPS calls x, v = advance(x, v) from x at rest ((STEPS + 1, n,
    3)), and the ms per step over steps 2..STEPS."""
    v = np.zeros_like(x)
    out, times = [x], []
    for _ in range(STEPS):
        start = time.perf_counter()
        x, v = advance(x, v)
        times.append(time.perf_counter() - start)
        out.append(x)
    return np.array(out), 1e3 * float(np.mean(times[1:]))


def fem_steps(scene, options):
    options = dict(options)
    stepper = Stepper(scene, DT, options.pop("method", "newton"), warn=False, **options)

    def advance(x, v):
        res = stepper(x, v)
        return res.x, res.v
    return timed_steps(advance, scene.initial_positions())


def network_steps(scene):
    mesh = scene.mesh
    sim = OnnxSimulator(MODEL, mesh.vertices, mesh.tets, fixed=scene.fixed_mask,
                        fiber_direction=FIBER, fiber_stiffness=1e5)
    return timed_steps(lambda x, v: sim.step(x, v, scene.external_force), sim.rest_positions)


def gpu_steps(scene, dtype):
    """The shipped directional model in torch on the GPU, in dtype (torch.float32/float64)."""
    advance = network_step(pretrained("directional", "cuda").to(dtype), scene)
    return timed_steps(lambda x, v: advance(x, v)[:2], scene.initial_positions())


def measure(refinements, gpu=False):
    rows = []
    for r in refinements:
        scene = scene_of(r)
        row = {"tets": scene.mesh.n_tets, "ms_per_step": {}}
        reference = None
        for label, (options, largest) in PATHS.items():
            if scene.mesh.n_tets <= largest:
                positions, row["ms_per_step"][label] = fem_steps(scene, options)
                if reference is None:
                    reference = positions
        network, row["ms_per_step"]["directional.onnx"] = network_steps(scene)
        if gpu:
            for dtype in (torch.float32, torch.float64):
                label = f"directional, torch {str(dtype)[6:]} on the GPU"
                row["ms_per_step"][label] = gpu_steps(scene, dtype)[1]
        static = np.linalg.norm(anisofem.solve(scene, warn=False, **PATHS[
            "exact, multigrid CG"][0]).x - scene.mesh.vertices, axis=1)
        tip = static >= 0.99 * static.max()
        row["network_tip_error"] = float(np.linalg.norm(
            (network[-1] - reference[-1])[tip].mean(axis=0)) / static.max())
        rows.append(row)
        print(" | ".join([f"{row['tets']:>7} tets"] + [f"{k} {v:.3g} ms" for k, v in
                                                         row["ms_per_step"].items()])
              + f" | network tip error at step {STEPS}: {row['network_tip_error']:.2f}",
              flush=True)
    return rows


def exponents(rows):
    """{path: p} with time ~ tets^p between the two largest sizes where the path ran."""
    out = {}
    for label in rows[-1]["ms_per_step"]:
        ran = [r for r in rows if label in r["ms_per_step"]]
        if len(ran) >= 2:
            a, b = ran[-2], ran[-1]
            out[label] = math.log(b["ms_per_step"][label] / a["ms_per_step"][label]) / math.log(
                b["tets"] / a["tets"])
    return out


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--refinements", type=int, nargs="+", default=[1, 2, 4, 8])
    p.add_argument("--json", default=result_path("crossover.json"))
    p.add_argument("--gpu", action="store_true",
                   help="also time the directional model in torch on the GPU (needs CUDA)")
    args = p.parse_args()
    if args.gpu:
        if not torch.cuda.is_available():
            p.error("--gpu: torch sees no CUDA device here")
    rows = measure(args.refinements, args.gpu)
    slopes = exponents(rows)
    print("time ~ tets^p between the two largest sizes: " + ", ".join(
        f"{k} p = {v:.2f}" for k, v in slopes.items()))
    write_json(args.json, {"steps": STEPS, "dt": DT, "rows": rows, "exponents": slopes})
    print(f"-> {args.json}")


if __name__ == "__main__":
    main()
