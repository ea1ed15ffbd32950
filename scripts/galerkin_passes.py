"""How far a Galerkin-stepped rollout is from anisofem's equilibrium every 200 steps, with one
Galerkin pass per step (the shipped models) or more (ModelConfig.galerkin_passes).

    python scripts/galerkin_passes.py CASE [PASSES...] [--model directional] [--float64]

CASE: an index into anisognn.evaluate.cases() (0-3 cantilevers, 4-9 imbalance, 10 tension).
Prints, for each PASSES (default 1 2), the largest vertex distance to the FEM equilibrium over
the largest FEM displacement after 200, 400, ..., 1,000 steps of the model's rollout from rest
(in float32, the shipped models' dtype, or with --float64 in float64). Run with
OMP_NUM_THREADS=1.
"""
import argparse

import numpy as np

import anisofem
from anisognn import evaluate, rollout, shipped
from anisognn.model import with_galerkin


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("case", type=int)
    p.add_argument("passes", type=int, nargs="*", default=[1, 2])
    p.add_argument("--model", default="directional")
    p.add_argument("--float64", action="store_true", help="model and rollout in float64")
    args = p.parse_args()
    case = evaluate.cases()[args.case]
    scene = case.scene
    x_fem = anisofem.solve(scene).x
    scale = np.linalg.norm(x_fem - scene.mesh.vertices, axis=1).max()
    model = shipped.model(args.model)
    if args.float64:
        model = model.double()
    for passes in args.passes:
        positions = rollout(with_galerkin(model, True, passes), scene, 1000)[200::200]
        errors = np.linalg.norm(positions - x_fem, axis=2).max(axis=1) / scale
        print(f"{case.label[:40]:40} {args.model} {'float64 ' * args.float64}passes {passes}: "
              + " ".join(f"{e:.2g}" for e in errors), flush=True)


if __name__ == "__main__":
    main()
