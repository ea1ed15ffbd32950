"""The graph network: encode, process (message passing with directional or plain-sum
aggregation), decode to end-of-step accelerations (paper section 3.1).

Inputs per vertex: Dirichlet flags (3, one per component, not normalized), velocity (3, m/s),
mass (1, kg), external force (3, N). Inputs per directed edge (sender s -> receiver r): unit
rest vector and rest length (4), unit current vector x_s - x_r and current length (4), fiber
feature (3, Pa) and the edge's deformation (4). All but the flags are normalized with
statistics stored as buffers.

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

from .galerkin import galerkin_acceleration
from .krylov import refine

AGGREGATIONS = ("directional", "sum")
VERTEX_FLAGS = 3   # Dirichlet flags per component
VERTEX_REAL = 7    # velocity 3, mass 1, external force 3
EDGE_FEATURES = 15  # rest unit 3 + length 1, current unit 3 + length 1, fiber 3, strain 4


@dataclass
class ModelConfig:
    """Network shape. Paper defaults: latent 128, 2 hidden layers, 15 steps, SiLU, LayerNorm
    on every MLP but the decoder. dt (s) is the time step the model is trained for.
    galerkin (not in the paper) makes the network's acceleration one direction of the step:
    the step minimizes the second-order model of the backward-Euler potential at the
    predictor over it, the force acceleration there, the velocity and the displacement from
    rest (anisognn.galerkin), so a rollout rests only where anisofem's forces balance. Costs
    the elastic force and four products with its derivative per step. galerkin_passes = k > 1
    solves k times per step, each from where the previous pass ended (k times that cost).
    cg_iterations = k > 0 (not in the paper) follows the step with k conjugate-gradient
    iterations in float64 on the backward-Euler Newton system linearized at its end
    (anisognn.krylov): an accuracy knob a user turns at inference, each iteration one Hessian
    product; trained weights do not depend on it."""
    latent: int = 128
    hidden_layers: int = 2
    steps: int = 15
    aggregation: str = "directional"
    dt: float = 0.02
    galerkin: bool = False
    galerkin_passes: int = 1
    cg_iterations: int = 0

    def __post_init__(self):
        if self.aggregation not in AGGREGATIONS:
            raise ValueError(f"aggregation: expected one of {AGGREGATIONS}, got "
                             f"{self.aggregation!r}")
        for name in ("latent", "hidden_layers", "steps", "galerkin_passes"):
            check_integer(self, name, 1)
        check_integer(self, "cg_iterations", 0)
        if not self.dt > 0:
            raise ValueError(f"dt: expected a time step > 0 s, got {self.dt!r}")
        if not isinstance(self.galerkin, bool):
            raise ValueError(f"galerkin: expected true or false, got {self.galerkin!r}")
        if self.galerkin_passes > 1 and not self.galerkin:
            raise ValueError("galerkin_passes: repeats the Galerkin step, so more than 1 needs "
                             "galerkin = true")

    @property
    def stepping(self):
        """How the model steps, in words: "K Galerkin pass(es)" or "no Galerkin step", and
        ", J CG iterations" when it takes them."""
        if not self.galerkin:
            words = "no Galerkin step"
        else:
            words = f"{self.galerkin_passes} Galerkin pass{'es' * (self.galerkin_passes > 1)}"
        if self.cg_iterations:
            words += f", {self.cg_iterations} CG iteration{'s' * (self.cg_iterations > 1)}"
        return words

    def to_dict(self):
        return asdict(self)


def check_integer(config, name, minimum, section=""):
    """ValueError naming the field (in its config section) unless config.name is an integer
    (not a bool) >= minimum."""
    value = getattr(config, name)
    if isinstance(value, bool) or not isinstance(value, int) or value < minimum:
        raise ValueError(f"{section}{name}: must be an integer >= {minimum}, got {value!r}")


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
        self.vertex_norm = Normalizer(VERTEX_REAL)
        self.edge_norm = Normalizer(EDGE_FEATURES)
        self.register_buffer("accel_scale", torch.ones(()))
        self.vertex_encoder = mlp(VERTEX_FLAGS + VERTEX_REAL, L, L, H, layer_norm=True)
        self.edge_encoder = mlp(EDGE_FEATURES, L, L, H, layer_norm=True)
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

    def edge_features(self, u, graph):
        """(E, 15) raw edge inputs at displacements u (n, 3) m: rest unit + length (m), current
        unit + length (m), fiber, and the edge's deformation: stretch - 1 and (u_s - u_r) /
        |X_sr|.

        The deformation channels are not in the paper (which gives rest and current vectors
        only): strains of 1e-3 are the signal of the stiff modes, and recovering them as the
        difference of two normalized lengths costs the network most of its training. Both are
        formed from the displacement difference du, stretch - 1 as (2 X_sr . du + du . du) /
        (L (l + L)), so float32 keeps their digits."""
        rest_length = graph.rest[:, 3:]
        rest_vec = graph.rest[:, :3] * rest_length
        du = u[graph.senders] - u[graph.receivers]
        vec = rest_vec + du
        length = torch.linalg.vector_norm(vec, dim=1, keepdim=True)
        unit = vec / torch.clamp(length, min=1e-12)
        grown = (2.0 * rest_vec + du).mul(du).sum(dim=1, keepdim=True)  # l^2 - L^2
        stretch = grown / (rest_length * (length + rest_length))
        return torch.cat([graph.rest, unit, length, graph.fiber, stretch, du / rest_length],
                         dim=1)

    def vertex_features(self, v, f_ext, graph):
        """(n, 7) raw vertex inputs: velocity, mass, external force."""
        return torch.cat([v, graph.mass, f_ext], dim=1)

    def aggregation_weights(self, graph):
        """(n, K, C) weights of each vertex's incoming edges: C = 3 directional, 1 sum."""
        if self.config.aggregation == "directional":
            return graph.in_weights
        return incoming_slots(graph)[1].to(graph.in_weights.dtype).unsqueeze(-1)

    def forward(self, x, v, f_ext, graph):
        """Accelerations (n, 3) in m/s^2 for positions x (n, 3) m, velocities v (n, 3) m/s and
        external forces f_ext (n, 3) N on graph (anisognn.graph.Graph). The network reads the
        displacement x - rest in the graph's dtype, subtracted in float64: give x in float64
        and a float32 model keeps the strains' digits (Graph.displacement)."""
        c = self.config
        u = graph.displacement(x, graph.mass.dtype)
        a = self.network_acceleration(u, v, f_ext, graph)
        if c.galerkin:
            a = galerkin_acceleration(a, u, v, f_ext, graph, c.dt, c.galerkin_passes)
        if c.cg_iterations:
            u_hat = graph.displacement(x, torch.float64) + c.dt * v.double()
            step = refine(a * (c.dt * c.dt), u_hat, f_ext, graph, c.dt, c.cg_iterations)
            a = (step / (c.dt * c.dt)).to(a.dtype)
        return a

    def network_acceleration(self, u, v, f_ext, graph):
        """(n, 3) m/s^2: the network's own acceleration (forward without galerkin) at
        displacements u (n, 3) m."""
        vertex_in = self.vertex_norm(self.vertex_features(v, f_ext, graph))
        edge = self.edge_encoder(self.edge_norm(self.edge_features(u, graph)))
        weights = self.aggregation_weights(graph).transpose(1, 2)  # (n, C, K)
        incoming = incoming_slots(graph)[0]
        vert = self.vertex_encoder(torch.cat([graph.fixed, vertex_in], dim=1))
        for edge_update, vertex_update in zip(self.edge_updates, self.vertex_updates):
            edge = edge + edge_update(edge, vert, graph.senders, graph.receivers)
            gathered = edge[incoming]  # (n, K, L)
            agg = torch.matmul(weights, gathered).flatten(1)  # (n, C L)
            vert = vert + vertex_update(torch.cat([vert, agg], dim=1))
        return self.decoder(vert) * self.accel_scale


def with_galerkin(model, galerkin=True, passes=None, cg_iterations=None):
    """A copy of the GraphNet model (same weights, in eval mode) whose config has
    ModelConfig.galerkin = galerkin and galerkin_passes = passes (1 without the step; None:
    the model's own count if it takes the step, else 1) and cg_iterations (None: the model's
    own): the trained network with or without the Galerkin step and the CG iterations."""
    param = next(model.parameters())
    if passes is None:
        passes = model.config.galerkin_passes
    if cg_iterations is None:
        cg_iterations = model.config.cg_iterations
    config = replace(model.config, galerkin=galerkin, galerkin_passes=passes if galerkin else 1,
                     cg_iterations=cg_iterations)
    out = GraphNet(config).to(param.device, param.dtype)
    out.load_state_dict(model.state_dict())
    return out.eval()


def incoming_slots(graph):
    """((n, K) int64 incoming edge per slot, (n, K) bool whether the slot holds one) of
    graph's padded incoming table: padding slots (index E) read edge 0 instead, and their
    weights are 0, so no pad row is concatenated to the edges at every step."""
    valid = graph.incoming < graph.n_edges
    return torch.where(valid, graph.incoming, 0), valid


def integrate(x, v, a, dt, graph):
    """Backward-Euler update with the predicted end-of-step acceleration a (n, 3):
    x' = x + dt v + dt^2 a, held components at graph.fixed_positions, v' = (x' - x) / dt."""
    free = x + dt * v + (dt * dt) * a
    x_next = torch.where(graph.fixed > 0, graph.fixed_positions, free)
    return x_next, (x_next - x) / dt
