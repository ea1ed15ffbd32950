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
    rest_positions: (n, 3) m, the rest shape, always float64 (displacement: the state the
    network and the elastic force read).
    tets (m, 4) int64, tet_gradients (m, 4, 3) 1/m, tet_material (m, 4) volume m^3 and mu, lam,
    kappa Pa, tet_fiber (m, 3) unit, corners (n, C) int64 corner slots padded with 4 m: the
    per-tet constants of the elastic force (export/runtime.py).
    sample: (n,) int64 the batch member of each vertex (set by batch; None for one mesh): the
    Galerkin step (anisognn.galerkin) solves one small system per member.
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
    rest_positions: torch.Tensor
    tets: torch.Tensor
    tet_gradients: torch.Tensor
    tet_material: torch.Tensor
    tet_fiber: torch.Tensor
    corners: torch.Tensor
    sample: torch.Tensor = None

    @classmethod
    def from_inputs(cls, tensors):
        """The Graph of the constant model inputs, a dict of tensors keyed by
        export/runtime.py's INPUTS names (its incoming_weights is this class's in_weights)."""
        named = dict(tensors)
        named["in_weights"] = named.pop("incoming_weights")
        return cls(**named)

    @property
    def n_vertices(self):
        return self.mass.shape[0]

    @property
    def n_edges(self):
        return self.senders.shape[0]

    def to(self, device=None, dtype=None):
        """A copy on device; floating tensors cast to dtype (if given), rest_positions kept in
        float64."""
        out = {}
        for f in fields(self):
            t = getattr(self, f.name)
            if t is None:
                continue
            cast = dtype if t.is_floating_point() and f.name != "rest_positions" else None
            out[f.name] = t.to(device=device, dtype=cast)
        return Graph(**out)

    def displacement(self, x, dtype):
        """(n, 3) m in dtype: positions x (n, 3) minus the rest shape, subtracted in float64
        (pass x in float64: what the cast to dtype rounds is then the displacement, not the
        position)."""
        return (x.to(torch.float64) - self.rest_positions).to(dtype)


def from_scene(scene, dtype=torch.float32):
    """The Graph of an anisofem.Scene: its mesh, fibers, material, masses and Dirichlet
    conditions."""
    if not isinstance(scene, Scene):
        raise TypeError(f"scene: expected an anisofem.Scene, got {type(scene).__name__}")
    if scene.mesh.order != 1:
        raise ValueError(f"scene: the network steps linear tets (the paper's setting); this "
                         f"mesh has quadratic tets (order {scene.mesh.order})")
    if scene.pressures or scene.cables:
        raise ValueError(f"scene: the network takes nodal forces; this scene has "
                         f"{'pressure loads' if scene.pressures else 'cables'}")
    if scene.contact is not None:
        raise ValueError("scene: the network takes no contact (step it with anisofem.step)")
    if (scene.elements.rest2 != 1.0).any():
        raise ValueError("scene: the network was trained on passive fibers; this scene activates "
                         "some (Material's activation)")
    mesh, el = scene.mesh, scene.elements
    t = runtime.mesh_tensors(mesh.vertices, mesh.tets, scene.masses, scene.fixed_mask,
                             scene.fixed_positions, el.fiber, el.kappa, el.mu, el.lam)
    return Graph.from_inputs({name: torch.tensor(value, dtype=torch.int64)
                              if np.issubdtype(value.dtype, np.integer) else
                              _real(value, torch.float64 if name == "rest_positions" else dtype)
                              for name, value in t.items()})


def _real(array, dtype):
    return torch.tensor(np.asarray(array), dtype=dtype)


def batch(graphs):
    """Disjoint union of graphs: vertices and edges concatenated, indices offset, incoming
    tables padded to the widest one (padding index = total edge count)."""
    graphs = list(graphs)
    n_edges = sum(g.n_edges for g in graphs)
    width = max(g.incoming.shape[1] for g in graphs)
    n_slots = 4 * sum(g.tets.shape[0] for g in graphs)
    corner_width = max(g.corners.shape[1] for g in graphs)
    v_off = e_off = s_off = 0
    senders, receivers, incoming, in_weights, tets, corners = [], [], [], [], [], []
    for g in graphs:
        senders.append(g.senders + v_off)
        receivers.append(g.receivers + v_off)
        tets.append(g.tets + v_off)
        incoming.append(_offset_table(g.incoming, g.n_edges, e_off, n_edges, width))
        corners.append(_offset_table(g.corners, 4 * g.tets.shape[0], s_off, n_slots,
                                     corner_width))
        pad = width - g.incoming.shape[1]
        in_weights.append(torch.nn.functional.pad(g.in_weights, (0, 0, 0, pad)))
        v_off += g.n_vertices
        e_off += g.n_edges
        s_off += 4 * g.tets.shape[0]
    joined = {name: torch.cat([getattr(g, name) for g in graphs])
              for name in ("rest", "fiber", "mass", "fixed", "fixed_positions", "rest_positions",
                           "tet_gradients", "tet_material", "tet_fiber")}
    sample = torch.cat([torch.full((g.n_vertices,), k, dtype=torch.int64)
                        for k, g in enumerate(graphs)])
    return Graph(senders=torch.cat(senders), receivers=torch.cat(receivers),
                 incoming=torch.cat(incoming), in_weights=torch.cat(in_weights),
                 tets=torch.cat(tets), corners=torch.cat(corners), sample=sample, **joined)


def _offset_table(table, own_pad, offset, pad_index, width):
    """A padded index table (rows, k) of one graph in a batch: entries shifted by offset, its
    padding own_pad (the graph's own count of the indexed items) replaced by pad_index, and
    padded with pad_index to width columns."""
    shifted = torch.where(table == own_pad, pad_index, table + offset)
    return torch.nn.functional.pad(shifted, (0, width - table.shape[1]), value=pad_index)
