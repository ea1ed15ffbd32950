"""Self-supervised training on the incremental potential (`python -m anisognn train`).

A run is described by a TOML file with sections [model] (ModelConfig), [sampler]
(SamplerConfig) and [train] (TrainConfig); see configs/. It writes into `out`:
- checkpoint.pt: model, optimizer and iteration, written atomically every checkpoint_every
  iterations and at the end; a run started again with the same out resumes from it exactly
  (samples depend only on (seed, index), the learning rate only on the iteration), also
  with more iterations (a finished run extends to the longer run) or from a copied folder;
- log.jsonl: one JSON object per logged iteration and per evaluation; on resume the lines
  after the checkpoint are dropped, so the log reads like an uninterrupted run's;
- model.pt: the final model (anisognn.load reads it).
A non-finite loss or gradient stops the run with TrainingDiverged; the last good checkpoint is
kept. Under torchrun (WORLD_SIZE > 1) the run is data parallel with DistributedDataParallel
(gloo on the CPU, nccl on GPUs); rank r draws samples (i B W + r B + j) at iteration i, and only
rank 0 writes files.
"""
import contextlib
import dataclasses
import hashlib
import importlib
import json
import math
import os
import sys
import time
import tomllib
from dataclasses import dataclass

import numpy as np
import torch
import torch.distributed as dist

import anisofem
from anisofem.io.output import atomic_path

from . import checkpoint
from .graph import batch as batch_graphs
from .graph import from_scene
from .loss import BatchPotential, potential_loss
from .model import GraphNet, ModelConfig, check_integer, integrate
from .sampler import Sample, Sampler, SamplerConfig

#: sample streams of a seed: training uses the seed itself, these offsets the others
NORMALIZATION_STREAM = 1_000_003
EVALUATION_STREAM = 2_000_003
ROLLOUT_STREAM = 3_000_017


class TrainingDiverged(RuntimeError):
    """The loss or the gradient became NaN or infinite."""


@dataclass
class TrainConfig:
    """Optimization and bookkeeping. energy_weight, newton_weight: weights of the energy and
    of the Newton-preconditioned term of the loss (1, 0: the paper's plain energy loss);
    normalize: divide each sample's loss by its optimal decrease (see anisognn.loss).
    rollout_probability, rollout_steps: with that probability an iteration's batch is first
    advanced 1..rollout_steps steps by the model itself (no gradient), so that it trains on the
    states its own rollouts visit (a state that leaves the bounds of own_rollout keeps its
    sampled start). learning_rate
    decays by lr_decay every decay_every iterations (continuously); grad_clip bounds the global
    gradient norm (0: off).
    through_galerkin (for a model with ModelConfig.galerkin): true trains the network through
    the Galerkin step (the loss, the own-rollout states and the held-out evaluation see the
    model's step); false trains its own acceleration exactly as without galerkin (same
    initialization, same arithmetic), and the projection acts only in the finished model."""
    newton_weight: float = 0.0
    energy_weight: float = 1.0
    normalize: bool = False
    rollout_probability: float = 0.0
    rollout_steps: int = 10
    iterations: int = 1000
    batch_size: int = 8
    learning_rate: float = 1e-3
    lr_decay: float = 0.5
    decay_every: int = 10000
    grad_clip: float = 1.0
    seed: int = 0
    device: str = "auto"
    log_every: int = 10
    eval_every: int = 200
    eval_samples: int = 16
    checkpoint_every: int = 100
    normalization_samples: int = 64
    out: str = "runs/default"
    through_galerkin: bool = True

    def __post_init__(self):
        for name in ("newton_weight", "energy_weight"):
            if not getattr(self, name) >= 0:
                raise ValueError(f"[train] {name}: must be >= 0, got {getattr(self, name)}")
        if not 0 <= self.rollout_probability <= 1:
            raise ValueError("[train] rollout_probability: must be in [0, 1], got "
                             f"{self.rollout_probability}")
        check_integer(self, "rollout_steps", 1, "[train] ")
        if not isinstance(self.through_galerkin, bool):
            raise ValueError(f"[train] through_galerkin: expected true or false, got "
                             f"{self.through_galerkin!r}")
        if self.newton_weight == 0 and self.energy_weight == 0:
            raise ValueError("[train] newton_weight, energy_weight: at least one must be > 0")


@dataclass
class RunConfig:
    model: ModelConfig
    sampler: SamplerConfig
    train: TrainConfig

    def to_dict(self):
        return dataclasses.asdict(self)


def load_config(path, **overrides):
    """RunConfig from a TOML file; overrides set [train] fields (e.g. out=...)."""
    with open(path, "rb") as f:
        try:
            raw = tomllib.load(f)
        except tomllib.TOMLDecodeError as err:
            raise ValueError(f"config {path}: not valid TOML: {err}") from None
    return make_config(raw, source=str(path), **overrides)


def make_config(raw, source="config", **overrides):
    """RunConfig from a dict {"model": {...}, "sampler": {...}, "train": {...}}."""
    unknown = set(raw) - {"model", "sampler", "train"}
    if unknown:
        raise ValueError(f"{source}: unknown sections {sorted(unknown)}; expected model, "
                         "sampler, train")
    parts = {}
    for name, cls in (("model", ModelConfig), ("sampler", SamplerConfig),
                      ("train", TrainConfig)):
        values = dict(raw.get(name, {}))
        if name == "train":
            values.update(overrides)
        known = {f.name for f in dataclasses.fields(cls)}
        bad = set(values) - known
        if bad:
            raise ValueError(f"{source}: [{name}] has unknown keys {sorted(bad)}; known: "
                             f"{sorted(known)}")
        parts[name] = cls(**values)
    if not math.isclose(parts["model"].dt, parts["sampler"].dt):
        raise ValueError(f"{source}: model.dt = {parts['model'].dt} s and sampler.dt = "
                         f"{parts['sampler'].dt} s must be equal")
    return RunConfig(**parts)


@dataclass
class Batch:
    """Network inputs of a batch of samples (tensors on the model's device; x in float64,
    v and f_ext in the model's dtype) and its loss."""
    graph: object
    x: torch.Tensor
    v: torch.Tensor
    f_ext: torch.Tensor
    potential: BatchPotential


def batch_graph(samples, device, dtype=torch.float32):
    """The disjoint union of the samples' graphs, on device, floating tensors in dtype."""
    return batch_graphs([from_scene(s.scene, dtype) for s in samples]).to(device)


def make_batch(samples, dt, device, dtype=torch.float32, weights=None, normalize=False,
               graph=None):
    """Batch of anisognn.sampler.Samples: one disjoint graph (graph, when the caller already
    built batch_graph(samples, device, dtype)), stacked states, and the incremental potentials
    of one step of dt from each sample's state (weights, normalize: see
    BatchPotential.backward_euler)."""
    if graph is None:
        graph = batch_graph(samples, device, dtype)
    x = np.concatenate([s.x for s in samples])
    v = np.concatenate([s.v for s in samples])
    f = np.concatenate([s.scene.external_force for s in samples])
    pot = BatchPotential.backward_euler([s.scene for s in samples], x, v, dt, weights,
                                        normalize)
    # positions stay float64: the model subtracts the rest shape before its own cast
    return Batch(graph, torch.as_tensor(x, dtype=torch.float64, device=device),
                 *(torch.as_tensor(a, dtype=dtype, device=device) for a in (v, f)), pot)


def own_rollout(model, samples, graph, steps, dt):
    """The samples advanced `steps` backward-Euler steps of dt by the model (no gradient), as
    new Samples with the same scenes; graph: their batch_graph in the model's dtype and on its
    device. Positions and velocities are integrated in float64. A sample whose rollout turns
    non-finite or moves a vertex farther than the mesh's bounding-box diagonal keeps its start.
    Returns (samples, number advanced)."""
    dtype, device = graph.mass.dtype, graph.mass.device
    x = torch.as_tensor(np.concatenate([s.x for s in samples]), device=device)
    v = torch.as_tensor(np.concatenate([s.v for s in samples]), device=device)
    f = torch.as_tensor(np.concatenate([s.scene.external_force for s in samples]),
                        dtype=dtype, device=device)
    held = dataclasses.replace(graph, fixed_positions=torch.as_tensor(
        np.concatenate([s.scene.fixed_positions for s in samples]), device=device))
    with torch.no_grad():
        for _ in range(steps):
            a = model(x, v.to(dtype), f, graph)
            x, v = integrate(x, v, a.double(), dt, held)
    x, v = x.cpu().numpy(), v.cpu().numpy()
    out, advanced, lo = [], 0, 0
    for s in samples:
        hi = lo + s.scene.mesh.n_vertices
        xs, vs = x[lo:hi], v[lo:hi]
        ok = np.isfinite(xs).all() and np.isfinite(vs).all() and \
            np.linalg.norm(xs - s.scene.mesh.vertices, axis=1).max() < s.scene.mesh.size
        out.append(Sample(s.scene, xs.copy(), vs.copy()) if ok else s)
        advanced += int(ok)
        lo = hi
    return out, advanced


def batch_loss(net, batch, dt, newton_weight=0.0, energy_weight=1.0):
    """(loss tensor, x_next) of the network net (a GraphNet, possibly wrapped by DDP) on a
    Batch at x_next = x + dt v + dt^2 net(...): anisognn.loss.potential_loss with these
    weights (the defaults: sum_i w_i G_i(x_next))."""
    a = net(batch.x, batch.v, batch.f_ext, batch.graph)
    x_next, _ = integrate(batch.x, batch.v, a, dt, batch.graph)
    loss = potential_loss(x_next, batch.potential, newton_weight, energy_weight)
    return loss, x_next


def fit_normalization(model, samples):
    """Set the model's input statistics and acceleration scale from samples (in place)."""
    g = batch_graph(samples, "cpu", torch.float64)
    x = torch.as_tensor(np.concatenate([s.x for s in samples]))
    v = torch.as_tensor(np.concatenate([s.v for s in samples]))
    f = torch.as_tensor(np.concatenate([s.scene.external_force for s in samples]))
    model.vertex_norm.fit(model.vertex_features(v, f, g))
    model.edge_norm.fit(model.edge_features(g.displacement(x, torch.float64), g))
    accel = f / g.mass
    model.accel_scale.fill_(float(torch.sqrt((accel ** 2).sum(dim=1).mean())))


class Evaluation:
    """Fixed evaluation samples scored against anisofem's backward-Euler step x* from the
    same state, with start = x + dt v (zero acceleration):

    - share_of_optimal_decrease = (G(start) - G(net)) / (G(start) - G(x*)): 1 is optimal, 0 no
      better than not accelerating. G weighs errors by H, so the stiff volumetric modes rule it.
    - force_error = |x_net - x*|_M / |start - x*|_M: the mass-weighted acceleration error
      relative to the optimal acceleration's; 0 is optimal. At rest it is the imbalanced force
      the network leaves relative to the load, which the soft bending modes rule.
    Means and medians over the samples."""

    def __init__(self, samples, dt, device):
        self.dt = dt
        self.batch = make_batch(samples, dt, device)  # built once: the samples are fixed
        self.start, self.best, self.energies, self.masses = [], [], [], []
        for s, pot in zip(samples, self.batch.potential.potentials):
            start = s.scene.with_fixed(s.x + dt * s.v)
            best = anisofem.step(s.scene, s.x, s.v, dt, warn=False)
            self.start.append(start)
            self.best.append(best.x)
            self.energies.append((pot.energy_gradient(start)[0], best.newton.energy))
            self.masses.append(s.scene.masses[:, None])

    def __call__(self, model):
        model.eval()
        with torch.no_grad():
            _, x_next = batch_loss(model, self.batch, self.dt)
        model.train()
        x64 = x_next.to("cpu", torch.float64).numpy()
        shares, errors = [], []
        bp = self.batch.potential
        for pot, lo, hi, start, best, (g0, gbest), m in zip(
                bp.potentials, bp.offsets, bp.offsets[1:], self.start, self.best,
                self.energies, self.masses):
            x = x64[lo:hi]
            g = pot.energy_gradient(x)[0]
            shares.append((g0 - g) / (g0 - gbest) if g0 > gbest else 1.0)
            errors.append(np.sqrt((m * (x - best) ** 2).sum() / (m * (start - best) ** 2).sum()))
        return {"share_of_optimal_decrease": float(np.mean(shares)),
                "share_median": float(np.median(shares)),
                "force_error": float(np.mean(errors)), "force_error_median": float(np.median(errors))}


def _device(name):
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    return torch.device(name)


@contextlib.contextmanager
def _distributed(device):
    """Yields (rank, world size, this process's device). Under torchrun (WORLD_SIZE > 1) it
    initializes the process group (nccl on GPUs, one per process; gloo on the CPU) unless the
    caller already did, and destroys the group it made on the way out: a gloo group that lives
    to interpreter exit aborts the process now and then ("terminate called without an active
    exception": a worker thread releases a finished collective's tensors after the interpreter
    began to shut down). torch._dynamo is imported first because importing it later (the first
    optimizer or DistributedDataParallel does) keeps references to the live group in torch 2.13,
    so that destroy_process_group could not free it."""
    world = int(os.environ.get("WORLD_SIZE", "1"))
    if world == 1:
        yield 0, 1, device
        return
    if device.type == "cuda":
        local = int(os.environ.get("LOCAL_RANK", "0"))
        if local >= torch.cuda.device_count():
            raise ValueError(f"[train] device: torchrun process {local} has no GPU of its own "
                             f"({torch.cuda.device_count()} found); start one process per "
                             "GPU, or set device = \"cpu\"")
        device = torch.device("cuda", local)
    owned = not dist.is_initialized()
    if owned:
        importlib.import_module("torch._dynamo")  # see the docstring
        dist.init_process_group("nccl" if device.type == "cuda" else "gloo")
    try:
        yield dist.get_rank(), world, device
    finally:
        if owned:
            dist.destroy_process_group()


def parameter_digest(model):
    """SHA-256 of the model's parameters and buffers (bitwise identity check)."""
    h = hashlib.sha256()
    for name, t in sorted(model.state_dict().items()):
        h.update(name.encode())
        h.update(t.detach().to("cpu").contiguous().numpy().tobytes())
    return h.hexdigest()


class _Log:
    """log.jsonl of rank 0: lines appended and flushed; truncated to an iteration on resume."""

    def __init__(self, path, enabled):
        self.path, self.enabled = path, enabled

    def truncate(self, iteration):
        if not (self.enabled and os.path.exists(self.path)):
            return
        with open(self.path) as f:
            keep = [line for line in f if line.strip()
                    and json.loads(line).get("iteration", 0) <= iteration]
        with atomic_path(self.path) as tmp, open(tmp, "w") as f:
            f.writelines(keep)

    def write(self, record):
        if self.enabled:
            with open(self.path, "a") as f:
                f.write(json.dumps(record) + "\n")


def train(config, progress=True):
    """Run (or resume) the training described by config (a RunConfig). Returns the model
    (unwrapped, on its device) and a summary dict (with "rank": only rank 0 writes files)."""
    with _distributed(_device(config.train.device)) as (rank, world, device):
        return _train(config, progress, rank, world, device)


def _same_run(run):
    """The parts of a run's configuration (a RunConfig dict) that a resume must match: all but
    train.iterations and train.out."""
    train = {k: v for k, v in run["train"].items() if k not in ("iterations", "out")}
    return {**run, "train": train}


def _check_resumable(payload, config, path):
    """Raise ValueError unless the checkpoint payload continues config: the same run, at an
    iteration not past config.train.iterations. A finished run extends exactly when its
    iterations grow (samples and learning rate depend only on the iteration), and a copied
    folder resumes under its new out. Fields added since the checkpoint was written take
    their defaults, which keep earlier runs' behavior."""
    run = payload.get("run")
    try:
        run = make_config(run, source=path).to_dict()
    except (TypeError, ValueError, AttributeError):
        run = None
    if run is None or _same_run(run) != _same_run(config.to_dict()):
        raise ValueError(f"{path}: was written by a different configuration; use another out "
                         "folder or delete it to start over")
    if payload["iteration"] > config.train.iterations:
        raise ValueError(f"{path}: is at iteration {payload['iteration']}, past [train] "
                         f"iterations = {config.train.iterations}")


def trained_config(config):
    """The ModelConfig of the network a RunConfig trains: its model's, without galerkin and CG
    iterations when [train] through_galerkin = false."""
    c = config.model
    if (c.galerkin or c.cg_iterations) and not config.train.through_galerkin:
        return dataclasses.replace(c, galerkin=False, galerkin_passes=1, cg_iterations=0)
    return config.model


def _train(config, progress, rank, world, device):
    tc = config.train
    out = tc.out
    ckpt_path = os.path.join(out, "checkpoint.pt")
    log = _Log(os.path.join(out, "log.jsonl"), enabled=rank == 0)
    if rank == 0:
        os.makedirs(out, exist_ok=True)
    torch.manual_seed(tc.seed)
    model = GraphNet(trained_config(config))
    sampler = Sampler(tc.seed, config.sampler)
    payload = checkpoint.read(ckpt_path) if os.path.exists(ckpt_path) else None
    if payload is None:
        norm = Sampler(tc.seed + NORMALIZATION_STREAM, config.sampler)
        fit_normalization(model, [norm.sample(i) for i in range(tc.normalization_samples)])
    else:
        _check_resumable(payload, config, ckpt_path)
        model.load_state_dict(payload["model"])
    # on the device before the optimizer loads its state, which it puts on its parameters' device
    model.to(device)
    optimizer = torch.optim.Adam(model.parameters(), lr=tc.learning_rate)
    start = 0
    if payload is not None:
        optimizer.load_state_dict(payload["optimizer"])
        start = int(payload["iteration"])
    log.truncate(start)  # a fresh start drops a stale log left in out
    net = model
    if world > 1:
        net = torch.nn.parallel.DistributedDataParallel(model)
    evaluation = None
    if rank == 0 and tc.eval_every > 0:
        ev = Sampler(tc.seed + EVALUATION_STREAM, config.sampler)
        evaluation = Evaluation([ev.sample(i) for i in range(tc.eval_samples)], config.model.dt,
                                device)

    def save(iteration):
        if rank == 0:
            checkpoint.save(ckpt_path, model, optimizer=optimizer.state_dict(),
                            iteration=iteration, run=config.to_dict())

    progress_display = _Progress(start, tc.iterations, enabled=progress and rank == 0)
    t0 = time.perf_counter()
    loss_value = float("nan")
    for it in range(start, tc.iterations):
        lr = tc.learning_rate * tc.lr_decay ** (it / tc.decay_every)
        for group in optimizer.param_groups:
            group["lr"] = lr
        first = (it * world + rank) * tc.batch_size
        samples = [sampler.sample(first + j) for j in range(tc.batch_size)]
        graph = batch_graph(samples, device)
        rng = np.random.default_rng([tc.seed, ROLLOUT_STREAM, it])
        advanced = 0
        if rng.random() < tc.rollout_probability:
            samples, advanced = own_rollout(model, samples, graph,
                                            int(rng.integers(1, tc.rollout_steps + 1)),
                                            config.model.dt)
        batch = make_batch(samples, config.model.dt, device,
                           weights=np.full(tc.batch_size, 1.0 / tc.batch_size),
                           normalize=tc.normalize, graph=graph)
        loss, _ = batch_loss(net, batch, config.model.dt, tc.newton_weight, tc.energy_weight)
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        grad_norm = torch.nn.utils.clip_grad_norm_(
            model.parameters(), tc.grad_clip if tc.grad_clip > 0 else float("inf"))
        loss_value = float(loss.detach())
        if not (math.isfinite(loss_value) and math.isfinite(float(grad_norm))):
            log.write({"iteration": it + 1, "event": "diverged", "loss": loss_value,
                       "grad_norm": float(grad_norm)})
            raise TrainingDiverged(
                f"iteration {it + 1}: loss {loss_value}, gradient norm {float(grad_norm)}; "
                f"stopped. The last good checkpoint is kept: {ckpt_path} (resume from it with "
                "a smaller learning_rate or grad_clip)")
        optimizer.step()
        done = it + 1
        if done % tc.log_every == 0 or done == tc.iterations:
            log.write({"iteration": done, "loss": loss_value, "lr": lr,
                       "grad_norm": float(grad_norm), "advanced": advanced,
                       "seconds": time.perf_counter() - t0})
        if evaluation is not None and (done % tc.eval_every == 0 or done == tc.iterations):
            log.write({"iteration": done, "event": "eval", **evaluation(model)})
        if done % tc.checkpoint_every == 0 or done == tc.iterations:
            save(done)
        progress_display.update(loss_value)
    progress_display.close()
    summary = {"rank": rank, "iterations": tc.iterations, "resumed_from": start, "final_loss": loss_value,
               "digest": parameter_digest(model)}
    if world > 1:
        digests = [None] * world
        dist.all_gather_object(digests, summary["digest"])
        summary["rank_digests"] = digests
    if rank == 0:
        finished = GraphNet(config.model)  # with galerkin, whatever through_galerkin said
        finished.load_state_dict(model.state_dict())
        checkpoint.save(os.path.join(out, "model.pt"), finished)
        log.write({"iteration": tc.iterations, "event": "done", **summary})
    return model, summary


class _Progress:
    """tqdm progress display when tqdm is installed and enabled, else silent."""

    def __init__(self, start, total, enabled):
        self.display = None
        if enabled:
            try:
                from tqdm import tqdm
            except ImportError:
                tqdm = None
            if tqdm is not None:
                self.display = tqdm(total=total, initial=start, file=sys.stderr, unit="it")

    def update(self, loss):
        if self.display is not None:
            self.display.set_postfix(loss=f"{loss:.4g}", refresh=False)
            self.display.update(1)

    def close(self):
        if self.display is not None:
            self.display.close()
