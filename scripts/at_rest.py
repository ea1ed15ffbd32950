"""Diagnostics of how a model treats still, deformed states (docs/experiments.md).

    python scripts/at_rest.py taken MODEL...   share of anisofem's step a model takes from 40
                                               noise-free at-rest training samples
    python scripts/at_rest.py probe MODEL...   tip z acceleration (m/s^2) of one step from rest at
                                               0-1.5 times the FEM deflection, four cantilevers
    python scripts/at_rest.py settle MODEL... [--steps N...] [--network on|zero|alone]
                                               tip deflection (mm) of the four cantilevers after
                                               N steps from rest (100, 300 and 1,000), and how
                                               far it still moves over the last 100, next to the
                                               FEM's; a galerkin model with its network's
                                               direction zeroed, or its network alone
    python scripts/at_rest.py learn [--iterations N] [--energy-weight W]
                                    [--no-normalize] [--fixed]
                                               train a fresh 32 x 6 directional model on at-rest
                                               samples only (fresh each iteration, or one fixed
                                               batch of 8) and print its held-out taken share
    python scripts/at_rest.py noise            the normalizer's noisy over noise-free value, and
                                               how much of the elastic-force input is noise

MODEL: a shipped name or a model.pt / checkpoint.pt path. Run with OMP_NUM_THREADS=1.
"""
import argparse

import numpy as np
import torch

import anisofem
from anisofem.physics.potential import Potential
from anisognn import evaluate, shipped
from anisognn import train as T
from anisognn.elastic import elastic_force
from anisognn.graph import from_scene
from anisognn.loss import optimal_decrease
from anisognn.model import GraphNet, ModelConfig, with_galerkin
from anisognn.sampler import Sampler, SamplerConfig

DT = 0.02
AT_REST = SamplerConfig(equilibrium_probability=1.0, noise_position=0.0, noise_velocity=0.0)
SHARES = (0.0, 0.25, 0.5, 0.75, 1.0, 1.25, 1.5)


def taken_shares(run, samples, fem_steps):
    """(k,) the model's one-step displacement projected on anisofem's, in the mass norm."""
    out = []
    with torch.no_grad():
        for s, d in zip(samples, fem_steps):
            m = s.scene.masses[:, None]
            step = run(s.scene, 1, s.x)[1] - s.x
            out.append((m * step * d).sum() / (m * d * d).sum())
    return np.array(out)


def fem_steps(samples):
    return [anisofem.simulate(s.scene, 1, dt=DT, x0=s.x, warn=False).positions[1] - s.x
            for s in samples]


def taken(models):
    samples = [Sampler(123, AT_REST).sample(i) for i in range(40)]
    steps = fem_steps(samples)
    for name in models:
        shares = taken_shares(evaluate.model_rollout(shipped.model(name)), samples, steps)
        print(f"{name}: median share of anisofem's step taken {np.median(shares):.2f}")


def tip_accelerations(run, scene, x_fem, shares=SHARES):
    """[mean tip z acceleration (m/s^2) of one step of run(scene, steps, x0) from rest at each
    share of the displacement x_fem (n, 3) m]; the tip is the vertices at the largest x."""
    X = scene.mesh.vertices
    tip = X[:, 0] >= X[:, 0].max() - 1e-9
    out = []
    for s in shares:
        x0 = X + s * (x_fem - X)
        with torch.no_grad():
            out.append(float((run(scene, 1, x0)[1] - x0)[tip, 2].mean() / DT ** 2))
    return out


def tip_drop(scene, positions):
    """Mean tip deflection along -z (mm) of positions (..., n, 3) m of scene; the tip is the
    vertices at the largest x."""
    X = scene.mesh.vertices
    tip = X[:, 0] >= X[:, 0].max() - 1e-9
    return -1e3 * (positions[..., tip, 2] - X[tip, 2]).mean(axis=-1)


def tip_deflections(run, scene, steps):
    """([tip_drop (mm) after each of steps from rest], swing): swing (mm) is the largest tip
    excursion from the final state over the last 100 steps; nan where the rollout of
    run(scene, steps, x0) is not finite."""
    with torch.no_grad():
        positions = evaluate._rollout(run, scene, max(steps))
    if positions is None or not np.isfinite(positions).all():
        return [np.nan] * len(steps), np.nan
    drop = tip_drop(scene, positions)
    return [float(drop[k]) for k in steps], float(np.abs(drop[-100:] - drop[-1]).max())


def settle(models, steps=(100, 300, 1000), network="on"):
    """network: "on"; "zero" takes the Galerkin step of a galerkin model without the
    network's direction (force, velocity, displacement only); "alone" the network's own
    acceleration without the Galerkin step."""
    sims = [(name, evaluate.model_rollout(with_network(shipped.model(name), network)))
            for name in models]
    for case in evaluate.cases()[:4]:
        fem = tip_drop(case.scene, anisofem.solve(case.scene).x)
        print(f"{case.label}; FEM {fem:.2f} mm; after {', '.join(map(str, steps))} steps, "
              "last-100 swing")
        for name, run in sims:
            drops, swing = tip_deflections(run, case.scene, steps)
            print(f"  {name[-40:]:40}" + "".join(f"{d:9.2f}" for d in drops) + f"{swing:9.3f}")


def with_network(model, network):
    """model as settle's network option asks (module docstring)."""
    if network == "on":
        return model
    if not model.config.galerkin:
        raise SystemExit(f"--network {network}: the model has no Galerkin step")
    if network == "zero":
        model.network_acceleration = lambda x, v, f_ext, graph: torch.zeros_like(x)
        return model
    return with_galerkin(model, False)


def train_step(model, optimizer, batch, energy_weight=1.0):
    """One optimizer step of the shipped loss (Newton weight 1000) on batch, gradient norm
    clipped to 1."""
    loss, _ = T.batch_loss(model, batch, DT, 1000.0, energy_weight)
    optimizer.zero_grad()
    loss.backward()
    torch.nn.utils.clip_grad_norm_(model.parameters(), 1.0)
    optimizer.step()


def probe(models):
    sims = [("fem", evaluate.fem_rollout)] + [(n, evaluate.model_rollout(shipped.model(n)))
                                              for n in models]
    for case in evaluate.cases()[:4]:
        x_fem = anisofem.solve(case.scene).x
        print(f"{case.label}; deflection shares {SHARES}")
        for name, run in sims:
            acc = tip_accelerations(run, case.scene, x_fem)
            print(f"  {name[-40:]:40}" + "".join(f"{a:8.3f}" for a in acc))


def learn(iterations, energy_weight, normalize, fixed):
    torch.manual_seed(0)
    sampler = Sampler(7, AT_REST)
    held = [Sampler(99, AT_REST).sample(i) for i in range(24)]
    steps = fem_steps(held)
    model = GraphNet(ModelConfig(latent=32, hidden_layers=2, steps=6, aggregation="directional"))
    T.fit_normalization(model, [Sampler(0, SamplerConfig(equilibrium_probability=0.6)).sample(i)
                                for i in range(64)])
    optimizer = torch.optim.Adam(model.parameters(), lr=1e-3)
    run = evaluate.model_rollout(model)
    batch = None
    for it in range(1, iterations + 1):
        if batch is None or not fixed:
            samples = [sampler.sample(it * 8 + j) for j in range(8)]
            batch = T.make_batch(samples, DT, "cpu", weights=np.full(8, 1 / 8),
                                 normalize=normalize)
        train_step(model, optimizer, batch, energy_weight)
        if it % 200 == 0:
            model.eval()
            q = np.quantile(taken_shares(run, held, steps), [0.25, 0.5, 0.75])
            line = f"{it}: held-out taken share quartiles {np.round(q, 2)}"
            if fixed:
                own = taken_shares(run, samples, fem_steps(samples))
                line += f"; on the fixed batch {np.round(np.quantile(own, [0.25, 0.5, 0.75]), 2)}"
            print(line, flush=True)
            model.train()


def noise():
    noisy = Sampler(0, SamplerConfig(equilibrium_probability=0.6))
    clean = Sampler(0, SamplerConfig(equilibrium_probability=0.6, noise_position=0.0,
                                     noise_velocity=0.0))
    rows = []
    for i in range(120):
        a, b = noisy.sample(i), clean.sample(i)  # same scene and state, noise aside
        rows.append((bool(np.allclose(b.v, 0)),
                     optimal_decrease(Potential(a.scene, a.x + DT * a.v, DT))
                     / optimal_decrease(Potential(b.scene, b.x + DT * b.v, DT))))
    rows = np.array(rows)
    for flag, label in ((1, "at rest"), (0, "moving")):
        print(f"{label}: median noisy / noise-free optimal decrease "
              f"{np.median(rows[rows[:, 0] == flag, 1]):.1f}")
    for scale in (1.0, 0.1, 0.01, 1e-3, 1e-4, 0.0):
        force, external = force_channel(scale)
        print(f"noise x {scale:g}: rms of the elastic-force input (f_elastic(x + dt v) + f_ext)/m "
              f"{force:.3g} m/s^2 (external force alone {external:.3g})")


def force_channel(scale, count=64):
    """(rms of (f_elastic(x + dt v) + f_ext) / m, rms external force / m) in m/s^2 over the
    free components of count training samples whose state noise is scale times the default."""
    defaults = SamplerConfig()
    sampler = Sampler(0, SamplerConfig(equilibrium_probability=0.6,
                                       noise_position=scale * defaults.noise_position,
                                       noise_velocity=scale * defaults.noise_velocity))
    force, external = [], []
    for i in range(count):
        s = sampler.sample(i)
        graph = from_scene(s.scene, torch.float64)
        f = torch.tensor(s.scene.external_force)
        predictor = torch.tensor(s.x + DT * s.v)
        channel = (elastic_force(graph.displacement(predictor, torch.float64), graph) + f) \
            / graph.mass
        free = ~s.scene.fixed_mask
        force.append(channel.numpy()[free])
        external.append((s.scene.external_force / s.scene.masses[:, None])[free])
    rms = [float(np.sqrt(np.mean(np.concatenate(v) ** 2))) for v in (force, external)]
    return tuple(rms)


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    sub = p.add_subparsers(dest="command", required=True)
    for name in ("taken", "probe", "settle"):
        sub.add_parser(name).add_argument("models", nargs="+")
    sub.choices["settle"].add_argument("--steps", type=int, nargs="+", default=[100, 300, 1000])
    sub.choices["settle"].add_argument("--network", choices=("on", "zero", "alone"),
                                       default="on")
    q = sub.add_parser("learn")
    q.add_argument("--iterations", type=int, default=1200)
    q.add_argument("--energy-weight", type=float, default=1.0)
    q.add_argument("--no-normalize", action="store_true")
    q.add_argument("--fixed", action="store_true")
    sub.add_parser("noise")
    args = p.parse_args()
    torch.set_num_threads(1)
    if args.command == "taken":
        taken(args.models)
    elif args.command == "probe":
        probe(args.models)
    elif args.command == "settle":
        settle(args.models, args.steps, args.network)
    elif args.command == "learn":
        learn(args.iterations, args.energy_weight, not args.no_normalize, args.fixed)
    else:
        noise()


if __name__ == "__main__":
    main()
