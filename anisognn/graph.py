"""The graph the network reads, built from an anisofem.Scene (constant per scene), and the
disjoint union of several graphs (a training batch).

The constant tensors are defined in export/runtime.py (torch-free, shared with the deployed
runtime); see its docstring for the edge order, the sign conventions and the padding.
"""
from dataclasses import dataclass, fields

import numpy as np
import torch

from anisofem import Scene
from export import runtime


@dataclass
class Graph:
    """Constant tensors of one mesh, or of a batch of meshes (disjoint union).

    senders, receivers: (E,) int64. rest: (E, 4) unit rest vector and rest length (m).
    fiber: (E, 3) fiber features (Pa). incoming: (n, K) int64 incoming edges, padded with E.
    in_weights: (n, K, 3) directional weights of the incoming edges (0 at padding).
    mass: (n, 1) kg. fixed: (n, 3) 1.0 where a component is held (Dirichlet), else 0.0.
    fixed_positions: (n, 3) m, where held components are held.
    """
    senders: torch.Tensor
    receivers: torch.Tensor
    rest: torch.Tensor
    fiber: torch.Tensor
    incoming: torch.Tensor
    in_weights: torch.Tensor
    mass: torch.Tensor
    fixed: torch.Tensor
    fixed_positions: torch.Tensor

    @property
    def n_vertices(self):
        return self.mass.shape[0]

    @property
    def n_edges(self):
        return self.senders.shape[0]

    def to(self, device=None, dtype=None):
        """A copy on device; floating tensors cast to dtype (if given)."""
        out = {}
        for f in fields(self):
            t = getattr(self, f.name)
            out[f.name] = t.to(device=device, dtype=dtype if t.is_floating_point() else None)
        return Graph(**out)


def from_scene(scene, dtype=torch.float32):
    """The Graph of an anisofem.Scene: its mesh, fibers, masses and Dirichlet conditions."""
    if not isinstance(scene, Scene):
        raise TypeError(f"scene: expected an anisofem.Scene, got {type(scene).__name__}")
    mesh, el = scene.mesh, scene.elements
    t = runtime.mesh_tensors(mesh.vertices, mesh.tets, scene.masses, scene.fixed_mask,
                             scene.fixed_positions, el.fiber, el.kappa)
    return Graph(senders=torch.as_tensor(t["senders"]), receivers=torch.as_tensor(t["receivers"]),
                 rest=_real(t["rest"], dtype), fiber=_real(t["fiber"], dtype),
                 incoming=torch.as_tensor(t["incoming"]),
                 in_weights=_real(t["incoming_weights"], dtype), mass=_real(t["mass"], dtype),
                 fixed=_real(t["fixed"], dtype),
                 fixed_positions=_real(t["fixed_positions"], dtype))


def _real(array, dtype):
    return torch.tensor(np.asarray(array), dtype=dtype)


def batch(graphs):
    """Disjoint union of graphs: vertices and edges concatenated, indices offset, incoming
    tables padded to the widest one (padding index = total edge count)."""
    graphs = list(graphs)
    n_edges = sum(g.n_edges for g in graphs)
    width = max(g.incoming.shape[1] for g in graphs)
    v_off = e_off = 0
    senders, receivers, incoming, in_weights = [], [], [], []
    for g in graphs:
        senders.append(g.senders + v_off)
        receivers.append(g.receivers + v_off)
        table = torch.where(g.incoming == g.n_edges, n_edges, g.incoming + e_off)
        pad = width - table.shape[1]
        incoming.append(torch.nn.functional.pad(table, (0, pad), value=n_edges))
        in_weights.append(torch.nn.functional.pad(g.in_weights, (0, 0, 0, pad)))
        v_off += g.n_vertices
        e_off += g.n_edges
    joined = {name: torch.cat([getattr(g, name) for g in graphs])
              for name in ("rest", "fiber", "mass", "fixed", "fixed_positions")}
    return Graph(senders=torch.cat(senders), receivers=torch.cat(receivers),
                 incoming=torch.cat(incoming), in_weights=torch.cat(in_weights), **joined)
