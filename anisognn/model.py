"""The graph network: encode, process (message passing with directional or plain-sum
aggregation), decode to end-of-step accelerations (paper section 3.1).

Inputs per vertex: Dirichlet flags (3, one per component, not normalized), velocity (3, m/s),
mass (1, kg), external force (3, N), and with ModelConfig.elastic_force the acceleration the
forces give at the inertial predictor, (f_elastic(x + dt v) + f_ext) / m (3, m/s^2); with
ModelConfig.force_only the flags, mass and that acceleration over its size only. Inputs
per directed edge (sender s -> receiver r): unit rest vector and rest length (4), unit current
vector x_s - x_r and current length (4), fiber feature (3, Pa), the edge's deformation (4), and
with ModelConfig.fiber_stress the fiber stress along the edge (1, Pa); without
ModelConfig.deformation_inputs the rest vector, rest length and fiber only. All but the flags are
normalized with statistics stored as buffers.

Processor step l (paper eq. 3):
    e <- e + f_e^l([e, v_s, v_r])
    v <- v + f_v^l([v, A(e)])
with A the aggregation over the edges each vertex receives:
    "directional": A = [sum_j w_x,j e_j, sum_j w_y,j e_j, sum_j w_z,j e_j] (paper eq. 4 weights),
    "sum":         A = sum_j e_j (MeshGraphNets).
The aggregation gathers each vertex's incoming edges from a padded table and contracts them
with their weights in one batched matmul: no scatter, so it exports to ONNX as Gather + MatMul,
which onnxruntime runs deterministically (scatter-add with repeated indices does not; see
export/README.md). f_e's first layer is split into an edge part and per-vertex sender and
receiver parts, computed once per vertex and then gathered (the same function as one layer on
the concatenation, with about a third fewer FLOPs).
"""
from dataclasses import asdict, dataclass, replace

import torch
from torch import nn

from .elastic import elastic_force
from .galerkin import galerkin_acceleration

AGGREGATIONS = ("directional", "sum")
VERTEX_FLAGS = 3   # Dirichlet flags per component
VERTEX_REAL = 7    # velocity 3, mass 1, external force 3 (+ 3 force accelerations)
EDGE_FEATURES = 15  # rest unit 3 + length 1, current unit 3 + length 1, fiber 3, strain 4
DEFORMATION_FEATURES = 8  # of those: current unit 3 + length 1, strain 4
FORCE_SATURATION = 100.0  # force_only: output scale bound, in units of the acceleration scale


@dataclass
class ModelConfig:
    """Network shape. Paper defaults: latent 128, 2 hidden layers, 15 steps, SiLU, LayerNorm
    on every MLP but the decoder. dt (s) is the time step the model is trained for.
    fiber_stress (not in the paper) adds the edge channel kappa (d . n)^2 (l^2 / L^2 - 1) / 2:
    the fiber stress along the edge (Pa), a product of three inputs an MLP forms only slowly.
    elastic_force (not in the paper) adds the vertex input (f_elastic(x + dt v) + f_ext) / m
    (m/s^2, 0 on held components; anisognn.elastic): the explicit acceleration at the point
    where a backward-Euler step's Newton iteration starts, which the network then corrects.
    force_scale (m/s^2, not in the paper; needs elastic_force) feeds that input as
    sign(a) log(1 + |a| / force_scale): linear below force_scale, logarithmic above, so that
    the small forces of near-equilibrium states stay readable beside the large ones of state
    noise in the stiff modes (0: the acceleration itself).
    anchored (not in the paper; needs elastic_force) subtracts from the output the network's
    own output for the same positions with zero velocity and zero force acceleration: the
    prediction vanishes wherever anisofem's forces balance at rest, so the FEM's equilibrium
    is always a state the model holds still (not necessarily the only one: where the network
    ignores the force input, it holds others too). Costs a second pass of the processor.
    deformation_inputs = false (not in the paper; needs elastic_force, excludes fiber_stress)
    drops the current edge vector, length and strain channels: the network sees the
    deformation only through the force input, so it cannot learn an elastic response of its
    own beside anisofem's.
    force_only (not in the paper; needs elastic_force and deformation_inputs = false, excludes
    anchored and force_scale) makes the step a function of the force acceleration g at the
    inertial predictor alone, as backward Euler's is: vertex inputs mass and g / s, where s
    (m/s^2) is the rms of |g| smoothed over `steps` hops; the output is
    s C / (s + C) (P(g / s) - P(-g / s)) / 2 for the network P, with C = FORCE_SATURATION
    times the acceleration scale: odd in g, proportional to it while s << C (gravity-sized
    forces) and bounded beyond (the stiff-mode forces of noisy or dynamic states, 1e4 m/s^2
    and more, which with an unbounded scale made training diverge). Velocity and external
    force enter only through g; the output is zero wherever the forces balance. Costs a
    second pass of the processor.
    galerkin (not in the paper; with any of the above) makes the network's acceleration one
    direction of the step: the step minimizes the second-order model of the backward-Euler
    potential at the predictor over it, the force acceleration there, the velocity and the
    displacement from rest (anisognn.galerkin), so a rollout rests only where anisofem's
    forces balance. Costs the elastic force and four products with its derivative per step.
    galerkin_passes = k > 1 solves k times per step, each from where the previous pass ended
    (k times that cost)."""
    latent: int = 128
    hidden_layers: int = 2
    steps: int = 15
    aggregation: str = "directional"
    dt: float = 0.02
    fiber_stress: bool = False
    elastic_force: bool = False
    force_scale: float = 0.0
    anchored: bool = False
    deformation_inputs: bool = True
    force_only: bool = False
    galerkin: bool = False
    galerkin_passes: int = 1

    def __post_init__(self):
        if self.aggregation not in AGGREGATIONS:
            raise ValueError(f"aggregation: expected one of {AGGREGATIONS}, got "
                             f"{self.aggregation!r}")
        for name in ("latent", "hidden_layers", "steps"):
            value = getattr(self, name)
            if not isinstance(value, int) or isinstance(value, bool) or value < 1:
                raise ValueError(f"{name}: expected a positive integer, got {value!r}")
        if not self.dt > 0:
            raise ValueError(f"dt: expected a time step > 0 s, got {self.dt!r}")
        for name in ("fiber_stress", "elastic_force", "anchored", "deformation_inputs",
                     "force_only", "galerkin"):
            if not isinstance(getattr(self, name), bool):
                raise ValueError(f"{name}: expected true or false, got {getattr(self, name)!r}")
        if not (isinstance(self.galerkin_passes, int) and not isinstance(self.galerkin_passes, bool)
                and self.galerkin_passes >= 1):
            raise ValueError(f"galerkin_passes: expected an integer >= 1, got "
                             f"{self.galerkin_passes!r}")
        if self.galerkin_passes > 1 and not self.galerkin:
            raise ValueError("galerkin_passes: repeats the Galerkin step, so more than 1 needs "
                             "galerkin = true")
        if not self.force_scale >= 0:
            raise ValueError(f"force_scale: expected an acceleration >= 0 m/s^2, got "
                             f"{self.force_scale!r}")
        if self.force_scale and not self.elastic_force:
            raise ValueError("force_scale: compresses the elastic-force input, so it needs "
                             "elastic_force = true")
        if self.anchored and not self.elastic_force:
            raise ValueError("anchored: zeroes the elastic-force input at the anchor, so it "
                             "needs elastic_force = true")
        if not self.deformation_inputs and not self.elastic_force:
            raise ValueError("deformation_inputs: without them only the elastic-force input "
                             "carries the deformation, so false needs elastic_force = true")
        if not self.deformation_inputs and self.fiber_stress:
            raise ValueError("deformation_inputs: false drops the strains fiber_stress is made "
                             "of; set fiber_stress = false")
        if self.force_only and (self.deformation_inputs or not self.elastic_force):
            raise ValueError("force_only: the step is a function of the elastic-force input "
                             "alone, so it needs elastic_force = true and deformation_inputs "
                             "= false")
        if self.force_only and (self.anchored or self.force_scale):
            raise ValueError("force_only: the output is already zero where the forces "
                             "balance and scales with them; set anchored = false and "
                             "force_scale = 0")

    @property
    def stepping(self):
        """How the model steps, in words: "K Galerkin pass(es)" or "no Galerkin step"."""
        if not self.galerkin:
            return "no Galerkin step"
        return f"{self.galerkin_passes} Galerkin pass{'es' * (self.galerkin_passes > 1)}"

    @property
    def edge_channels(self):
        """Number of raw edge features: 15, 16 with fiber_stress, 7 without deformation_inputs."""
        return (EDGE_FEATURES + int(self.fiber_stress)
                - DEFORMATION_FEATURES * int(not self.deformation_inputs))

    @property
    def vertex_channels(self):
        """Number of normalized vertex features: 7, 10 with elastic_force, 4 with force_only
        (mass and the scaled force input)."""
        if self.force_only:
            return 4
        return VERTEX_REAL + 3 * int(self.elastic_force)

    def to_dict(self):
        return asdict(self)


class Normalizer(nn.Module):
    """(x - mean) / std per channel; the statistics are buffers (saved with the model)."""

    def __init__(self, channels):
        super().__init__()
        self.register_buffer("mean", torch.zeros(channels))
        self.register_buffer("std", torch.ones(channels))

    def fit(self, samples, floor=1e-8):
        """Set the statistics from samples (k, channels); std floored at floor * max std."""
        samples = samples.to(self.mean)
        std = samples.std(dim=0)
        self.mean.copy_(samples.mean(dim=0))
        self.std.copy_(torch.clamp(std, min=floor * float(std.max()) + 1e-30))

    def forward(self, x):
        return (x - self.mean) / self.std


def mlp(inputs, width, outputs, hidden_layers, layer_norm):
    """Linear-SiLU stack with hidden_layers hidden layers of `width`, optional LayerNorm."""
    layers, size = [], inputs
    for _ in range(hidden_layers):
        layers += [nn.Linear(size, width), nn.SiLU()]
        size = width
    layers.append(nn.Linear(size, outputs))
    if layer_norm:
        layers.append(nn.LayerNorm(outputs))
    return nn.Sequential(*layers)


class EdgeUpdate(nn.Module):
    """f_e([e, v_s, v_r]) with the first layer split: W_e e + (W_s v + b)[s] + (W_r v)[r].

    The edge product is one addmm onto the gathered vertex terms (onnxruntime: a Gemm with
    its C input), so no edge-sized Add is left for the bias or the edge term."""

    def __init__(self, latent, hidden_layers):
        super().__init__()
        self.edge = nn.Linear(latent, latent)
        self.sender = nn.Linear(latent, latent, bias=False)
        self.receiver = nn.Linear(latent, latent, bias=False)
        self.rest = nn.Sequential(nn.SiLU(), mlp(latent, latent, latent, hidden_layers - 1,
                                                 layer_norm=True))

    def forward(self, e, v, senders, receivers):
        vertex_terms = (self.sender(v) + self.edge.bias)[senders] + self.receiver(v)[receivers]
        return self.rest(torch.addmm(vertex_terms, e, self.edge.weight.t()))


class GraphNet(nn.Module):
    """Encode-process-decode network mapping a state on a Graph to accelerations (n, 3) m/s^2."""

    def __init__(self, config=None):
        super().__init__()
        self.config = config or ModelConfig()
        c = self.config
        L, H = c.latent, c.hidden_layers
        self.vertex_norm = Normalizer(c.vertex_channels)
        self.edge_norm = Normalizer(c.edge_channels)
        self.register_buffer("accel_scale", torch.ones(()))
        self.vertex_encoder = mlp(VERTEX_FLAGS + c.vertex_channels, L, L, H, layer_norm=True)
        self.edge_encoder = mlp(c.edge_channels, L, L, H, layer_norm=True)
        channels = 3 if c.aggregation == "directional" else 1
        self.edge_updates = nn.ModuleList(EdgeUpdate(L, H) for _ in range(c.steps))
        self.vertex_updates = nn.ModuleList(
            mlp(L * (1 + channels), L, L, H, layer_norm=True) for _ in range(c.steps))
        self.decoder = mlp(L, L, 3, H, layer_norm=False)
        if not c.galerkin:
            # start from "no acceleration beyond what the inputs imply": a zero output layer
            # (with galerkin only the output's direction counts, and a zero one has none)
            nn.init.zeros_(self.decoder[-1].weight)
            nn.init.zeros_(self.decoder[-1].bias)

    def edge_features(self, x, graph):
        """(E, 15) raw edge inputs: rest unit + length (m), current unit + length (m), fiber,
        and the edge's deformation: stretch - 1 and (x_ij - X_ij) / |X_ij|; (E, 16) with the
        fiber stress along the edge (ModelConfig.fiber_stress); (E, 7) rest unit + length and
        fiber without ModelConfig.deformation_inputs.

        The deformation channels are not in the paper (which gives rest and current vectors
        only): strains of 1e-3 are the signal of the stiff modes, and recovering them as the
        difference of two normalized lengths costs the network most of its training."""
        if not self.config.deformation_inputs:
            return torch.cat([graph.rest, graph.fiber], dim=1)
        vec = x[graph.senders] - x[graph.receivers]
        length = torch.linalg.vector_norm(vec, dim=1, keepdim=True)
        unit = vec / torch.clamp(length, min=1e-12)
        rest_length = graph.rest[:, 3:]
        stretch = length / rest_length
        relative = (vec - graph.rest[:, :3] * rest_length) / rest_length
        features = [graph.rest, unit, length, graph.fiber, stretch - 1.0, relative]
        if self.config.fiber_stress:
            features.append(fiber_stress(graph.fiber, graph.rest[:, :3], stretch))
        return torch.cat(features, dim=1)

    def vertex_features(self, x, v, f_ext, graph):
        """(n, 7) raw vertex inputs: velocity, mass, external force; (n, 10) with the force
        acceleration g (ModelConfig.elastic_force; force_input), as sign(g) log(1 + |g| /
        force_scale) when force_scale > 0; (n, 4) mass and g / s with force_only
        (scaled_force)."""
        if self.config.force_only:
            return self.scaled_force(self.force_input(x, v, f_ext, graph), graph)[0]
        features = [v, graph.mass, f_ext]
        if self.config.elastic_force:
            accel = self.force_input(x, v, f_ext, graph)
            scale = self.config.force_scale
            features.append(signed_log(accel, scale) if scale else accel)
        return torch.cat(features, dim=1)

    def force_input(self, x, v, f_ext, graph):
        """(n, 3) m/s^2: (f_elastic(x + dt v) + f_ext) / m, 0 on held components: the
        acceleration the forces give at the inertial predictor."""
        force = elastic_force(x + self.config.dt * v, graph) + f_ext
        return force / graph.mass * (1.0 - graph.fixed)

    def scaled_force(self, g, graph):
        """((n, 4) raw force_only vertex inputs: mass, g / s; (n, 1) the output scale
        s C / (s + C), m/s^2) for the force input g (n, 3) m/s^2, with s its size
        (force_size) and C = FORCE_SATURATION times the acceleration scale."""
        size = self.force_size(g, graph)
        bound = FORCE_SATURATION * self.accel_scale
        return torch.cat([graph.mass, g / size], dim=1), size * bound / (size + bound)

    def force_size(self, g, graph, floor=1e-12):
        """(n, 1) m/s^2: the rms of |g| (n, 3) over each vertex's neighbourhood, averaged with
        its in-neighbours `steps` times (floored at floor m/s^2): positively homogeneous in g,
        and as far-reaching as the message passing."""
        incoming, valid = incoming_slots(graph)
        valid = valid.to(g.dtype)
        neighbours = graph.senders[incoming]  # (n, K)
        count = 1.0 + valid.sum(dim=1, keepdim=True)
        q = (g * g).sum(dim=1, keepdim=True)
        for _ in range(self.config.steps):
            q = (q + (q[neighbours, 0] * valid).sum(dim=1, keepdim=True)) / count
        return torch.sqrt(q) + floor

    def aggregation_weights(self, graph):
        """(n, K, C) weights of each vertex's incoming edges: C = 3 directional, 1 sum."""
        if self.config.aggregation == "directional":
            return graph.in_weights
        return incoming_slots(graph)[1].to(graph.in_weights.dtype).unsqueeze(-1)

    def forward(self, x, v, f_ext, graph):
        """Accelerations (n, 3) in m/s^2 for positions x (n, 3) m, velocities v (n, 3) m/s and
        external forces f_ext (n, 3) N on graph (anisognn.graph.Graph)."""
        a = self.network_acceleration(x, v, f_ext, graph)
        if self.config.galerkin:
            return galerkin_acceleration(a, x, v, f_ext, graph, self.config.dt,
                                         self.config.galerkin_passes)
        return a

    def network_acceleration(self, x, v, f_ext, graph):
        """(n, 3) m/s^2: the network's own acceleration (forward without galerkin)."""
        if self.config.force_only:
            vertex_in, scale = self.scaled_force(self.force_input(x, v, f_ext, graph), graph)
        else:
            vertex_in = self.vertex_features(x, v, f_ext, graph)
        edge = self.edge_encoder(self.edge_norm(self.edge_features(x, graph)))
        weights = self.aggregation_weights(graph).transpose(1, 2)  # (n, C, K)
        incoming = incoming_slots(graph)[0]
        if self.config.force_only:
            # odd in the force: the same network on the flipped force input, subtracted
            flipped = torch.cat([vertex_in[:, :1], -vertex_in[:, 1:]], dim=1)
            return 0.5 * scale * (self.process(vertex_in, edge, graph, weights, incoming)
                                  - self.process(flipped, edge, graph, weights, incoming))
        a = self.process(vertex_in, edge, graph, weights, incoming)
        if self.config.anchored:
            # the same positions at rest with balanced forces: velocity and force input zero
            at_rest = torch.cat([torch.zeros_like(vertex_in[:, :3]), vertex_in[:, 3:VERTEX_REAL],
                                 torch.zeros_like(vertex_in[:, VERTEX_REAL:])], dim=1)
            a = a - self.process(at_rest, edge, graph, weights, incoming)
        return a * self.accel_scale

    def process(self, vertex_in, edge, graph, weights, incoming):
        """(n, 3) decoded after message passing from raw vertex inputs (n, vertex_channels) and
        encoded edges (E, L), with the aggregation weights (n, C, K) and the incoming table
        (n, K) whose padding slots read edge 0: in units of accel_scale, or of the force_only
        output scale (scaled_force)."""
        vert = self.vertex_encoder(torch.cat([graph.fixed, self.vertex_norm(vertex_in)], dim=1))
        for edge_update, vertex_update in zip(self.edge_updates, self.vertex_updates):
            edge = edge + edge_update(edge, vert, graph.senders, graph.receivers)
            gathered = edge[incoming]  # (n, K, L)
            agg = torch.matmul(weights, gathered).flatten(1)  # (n, C L)
            vert = vert + vertex_update(torch.cat([vert, agg], dim=1))
        return self.decoder(vert)


def with_galerkin(model, galerkin=True, passes=None):
    """A copy of the GraphNet model (same weights, in eval mode) whose config has
    ModelConfig.galerkin = galerkin and galerkin_passes = passes (1 without the step; None:
    the model's own count if it takes the step, else 1): the trained network with or without
    the Galerkin step."""
    param = next(model.parameters())
    if passes is None:
        passes = model.config.galerkin_passes
    config = replace(model.config, galerkin=galerkin, galerkin_passes=passes if galerkin else 1)
    out = GraphNet(config).to(param.device, param.dtype)
    out.load_state_dict(model.state_dict())
    return out.eval()


def incoming_slots(graph):
    """((n, K) int64 incoming edge per slot, (n, K) bool whether the slot holds one) of
    graph's padded incoming table: padding slots (index E) read edge 0 instead, and their
    weights are 0, so no pad row is concatenated to the edges at every step."""
    valid = graph.incoming < graph.n_edges
    return torch.where(valid, graph.incoming, 0), valid


def fiber_stress(fiber, rest_unit, stretch):
    """(E, 1) Pa: kappa (d . n)^2 (stretch^2 - 1) / 2 for fiber features kappa d (E, 3), unit
    rest vectors n (E, 3) and stretches l / L (E, 1): the fiber term's stress along an edge
    aligned with the fiber, weighted by how well the edge is aligned (0 without a fiber)."""
    kappa = torch.linalg.vector_norm(fiber, dim=1, keepdim=True)
    along = (fiber * rest_unit).sum(dim=1, keepdim=True)
    return along * along / torch.clamp(kappa, min=1e-30) * 0.5 * (stretch * stretch - 1.0)


def signed_log(a, scale):
    """sign(a) log(1 + |a| / scale), elementwise: a / scale for |a| << scale, logarithmic
    beyond (ONNX: Sign, Abs, Log; unlike asinh, exportable at opset 17)."""
    return torch.sign(a) * torch.log1p(torch.abs(a) / scale)


def integrate(x, v, a, dt, graph):
    """Backward-Euler update with the predicted end-of-step acceleration a (n, 3):
    x' = x + dt v + dt^2 a, held components at graph.fixed_positions, v' = (x' - x) / dt."""
    free = x + dt * v + (dt * dt) * a
    x_next = torch.where(graph.fixed > 0, graph.fixed_positions, free)
    return x_next, (x_next - x) / dt
