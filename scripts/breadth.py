"""How the breadth of the training distribution decides whether a model learns how the fiber
direction changes bending (docs/experiments.md).

    python scripts/breadth.py deflections      FEM tip deflection of the evaluation box beam
                                               under gravity (kappa = E) with the fiber along
                                               each axis, at 45 degrees, and quantiles over 40
                                               random directions
    python scripts/breadth.py learn [--dirs axes|random|curriculum] [--kappa-max K]
                                    [--loads gravity|random] [--aggregation sum]
                                    [--iterations N]
                                               train a fresh 32 x 6 model for N iterations
                                               (shipped loss, learning rate 1e-3 halved
                                               three times over the run, no own-rollout
                                               states) on the sampler restricted to the two
                                               evaluation beams, fibers along x or z (axes),
                                               uniform on the sphere (random), or spreading
                                               from the axes to uniform over the first two
                                               thirds of the run (curriculum), kappa = E (or
                                               uniform up to K E), body force along -z up to
                                               15 kN/m^3 (or the sampler's loads); every 500
                                               iterations print the tip z acceleration (m/s^2)
                                               of one step from rest at 0, 0.5 and 1 times the
                                               FEM deflection on the four evaluation
                                               cantilevers, next to the FEM's; at the end the
                                               tip deflection after 300 steps from rest

Run with OMP_NUM_THREADS=1; `learn` takes 5-10 minutes.
"""
import argparse

import numpy as np
import torch

import anisofem
from anisognn import evaluate
from anisognn import train as T
# scripts/ is on the path when run as a script
from at_rest import tip_accelerations, tip_deflections, tip_drop, train_step
from anisognn.model import GraphNet, ModelConfig
from anisognn.sampler import DENSITY, POISSON, YOUNG, Sampler, SamplerConfig

DT = 0.02
GRAVITY = (0.0, 0.0, -DENSITY * 9.81)
SHARES = (0.0, 0.5, 1.0)


def tip_deflection(direction):
    """FEM tip deflection (mm) of the evaluation box beam under gravity, fiber along direction."""
    scene = evaluate._scene(evaluate._beam("box"), direction, GRAVITY)
    return tip_drop(scene, anisofem.solve(scene).x)


def deflections():
    for label, d in (("x (along the beam)", (1, 0, 0)), ("y", (0, 1, 0)),
                     ("z (along gravity)", (0, 0, 1)), ("45 deg in x-z", (1, 0, 1)),
                     ("45 deg in x-y", (1, 1, 0))):
        print(f"fiber {label:20} {tip_deflection(d):6.2f} mm")
    rng = np.random.default_rng(0)
    random = [tip_deflection(d) for d in rng.normal(size=(40, 3))]
    q = np.quantile(random, [0.0, 0.1, 0.5, 0.9, 1.0])
    print("40 random directions: min, 10%, median, 90%, max " + " ".join(f"{v:.2f}" for v in q))


class Restricted(Sampler):
    """The training sampler on the two evaluation beams, with narrower fibers and loads."""

    def __init__(self, seed, config, dirs, kappa_max, loads, samples=1):
        super().__init__(seed, config)
        self.use_meshes([evaluate._beam("box"), evaluate._beam("cylinder")])
        self.dirs, self.kappa_max, self.loads = dirs, kappa_max, loads
        self.samples, self.spread = samples, 0.0

    def sample(self, index):
        # curriculum: the spread about the axis grows from 0 to 3 (about uniform) over the
        # first two thirds of the samples
        self.spread = 3.0 * min(1.0, 1.5 * index / self.samples)
        return super().sample(index)

    def _material(self, rng, mesh):
        if self.dirs == "random":
            d = rng.normal(size=3)
        else:
            d = np.eye(3)[(0, 2)[rng.integers(2)]]
            if self.dirs == "curriculum":
                d = d + self.spread * rng.normal(size=3)
        kappa = YOUNG if self.kappa_max == 0 else rng.uniform(0, self.kappa_max) * YOUNG
        return anisofem.Material(YOUNG, POISSON, DENSITY, d / np.linalg.norm(d), kappa)

    def _loads(self, rng, mesh, h):
        if self.loads == "random":
            return super()._loads(rng, mesh, h)
        return {"body_force": np.tile([0.0, 0.0, -rng.uniform(0, 15e3)], (mesh.n_tets, 1))}


def tip_table(run, cases, x_fem):
    """(4, 3) tip z accelerations (m/s^2) one step from rest at SHARES of the FEM deflection."""
    return np.round([tip_accelerations(run, c.scene, xf, SHARES)
                     for c, xf in zip(cases, x_fem)], 2).tolist()


def learn(args):
    config = SamplerConfig(equilibrium_probability=0.3)
    options = (args.dirs, args.kappa_max, args.loads)
    sampler = Restricted(0, config, *options, samples=8 * args.iterations)
    torch.manual_seed(0)
    model = GraphNet(ModelConfig(latent=32, hidden_layers=2, steps=6,
                                 aggregation=args.aggregation))
    T.fit_normalization(model, [Restricted(1, config, *options).sample(i) for i in range(128)])
    optimizer = torch.optim.Adam(model.parameters(), lr=1e-3)
    cases = evaluate.cases()[:4]
    x_fem = [anisofem.solve(c.scene).x for c in cases]
    print("rows: box parallel, box orthogonal, cylinder parallel, cylinder orthogonal; "
          f"columns: {SHARES} of the FEM deflection")
    print("fem", tip_table(evaluate.fem_rollout, cases, x_fem), flush=True)
    run = evaluate.model_rollout(model)
    for it in range(1, args.iterations + 1):
        for group in optimizer.param_groups:
            group["lr"] = 1e-3 * 0.5 ** (3 * it / args.iterations)  # halved 3 times per run
        samples = [sampler.sample(it * 8 + j) for j in range(8)]
        batch = T.make_batch(samples, DT, "cpu", weights=np.full(8, 1 / 8), normalize=True)
        train_step(model, optimizer, batch)
        if it % 500 == 0:
            model.eval()
            print(it, tip_table(run, cases, x_fem), flush=True)
            model.train()
    model.eval()
    print("tip deflection (mm) after 300 steps from rest, model / FEM:")
    for c, xf in zip(cases, x_fem):
        (model_tip,), _ = tip_deflections(run, c.scene, (300,))
        print(f"  {c.label:40} {model_tip:8.2f} {tip_drop(c.scene, xf):6.2f}", flush=True)


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    sub = p.add_subparsers(dest="command", required=True)
    sub.add_parser("deflections")
    q = sub.add_parser("learn")
    q.add_argument("--dirs", choices=("axes", "random", "curriculum"), default="axes")
    q.add_argument("--kappa-max", type=float, default=0.0)
    q.add_argument("--loads", choices=("gravity", "random"), default="gravity")
    q.add_argument("--aggregation", choices=("directional", "sum"), default="directional")
    q.add_argument("--iterations", type=int, default=3000)
    args = p.parse_args()
    torch.set_num_threads(1)
    if args.command == "deflections":
        deflections()
    else:
        learn(args)


if __name__ == "__main__":
    main()
