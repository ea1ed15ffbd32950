"""How far a Galerkin-stepped rollout is from anisofem's equilibrium after 200-1,000 steps, with
one Galerkin pass per step (what anisognn.galerkin does) or more: pass k > 1 solves again
from the point pass k-1 reached, over its own residual r_k / m, the step so far, the velocity
and the displacement (the full incremental potential's second-order model there; float64,
numpy and anisofem's Hessian, the network in float32 as shipped).

    python scripts/galerkin_passes.py CASE [PASSES...] [--model directional]

CASE: an index into anisognn.evaluate.cases() (0-3 cantilevers, 4-9 imbalance, 10 tension).
Prints, for each PASSES (default 1 2), the largest vertex distance to the FEM equilibrium over
the largest FEM displacement, every 200 steps. Run with OMP_NUM_THREADS=1.
"""
import argparse

import numpy as np
import torch

import anisofem
from anisofem import potential as P
from anisognn import evaluate, shipped
from anisognn.graph import from_scene
from anisognn.model import with_galerkin

DT = evaluate.DT


def subspace_minimum(scene, base, x_hat, directions):
    """base + s, s minimizing the second-order model of the backward-Euler potential (predictor
    x_hat) at base over the span of directions (list of (n, 3)) on the free components."""
    free = ~scene.fixed_mask
    r = -P.gradient(scene, base, x_hat, DT) * free
    B = np.stack([(d * free).ravel() / np.linalg.norm(d) for d in directions
                  if np.abs(d).max() > 0], axis=1)
    A = B.T @ (P.hessian(scene, base, x_hat, DT) @ B)
    coef = np.linalg.lstsq(A, B.T @ r.ravel(), rcond=1e-10)[0]
    return base + (B @ coef).reshape(-1, 3)


def step(scene, network, x, v, passes):
    """Positions after one step of `passes` Galerkin passes from (x, v)."""
    x_hat = x + DT * v
    mass = scene.masses[:, None]
    force = -P.gradient(scene, x_hat, x_hat, DT)
    moved = x - scene.mesh.vertices
    x_next = subspace_minimum(scene, x_hat, x_hat, [network(x, v), force / mass, v, moved])
    for _ in range(passes - 1):
        force = -P.gradient(scene, x_next, x_hat, DT)
        x_next = subspace_minimum(scene, x_next, x_hat, [force / mass, x_next - x_hat, v, moved])
    return x_next


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("case", type=int)
    p.add_argument("passes", type=int, nargs="*", default=[1, 2])
    p.add_argument("--model", default="directional")
    args = p.parse_args()
    case = evaluate.cases()[args.case]
    scene = case.scene
    net = with_galerkin(shipped.model(args.model), False)
    graph = from_scene(scene)
    f_ext = torch.tensor(scene.external_force, dtype=torch.float32)

    def network(x, v):
        with torch.no_grad():
            return net(torch.tensor(x, dtype=torch.float32), torch.tensor(v, dtype=torch.float32),
                       f_ext, graph).double().numpy()
    x_fem = anisofem.solve(scene).x
    scale = np.linalg.norm(x_fem - scene.mesh.vertices, axis=1).max()
    for passes in args.passes:
        x, v, errors = scene.initial_positions(), np.zeros_like(scene.mesh.vertices), []
        for k in range(1, 1001):
            x_next = step(scene, network, x, v, passes)
            x, v = x_next, (x_next - x) / DT
            if k % 200 == 0:
                errors.append(np.linalg.norm(x - x_fem, axis=1).max() / scale)
        print(f"{case.label[:40]:40} {args.model} passes {passes}: "
              + " ".join(f"{e:.2g}" for e in errors), flush=True)


if __name__ == "__main__":
    main()
