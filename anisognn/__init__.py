"""anisognn: a mesh graph network with directional encodings (and the MeshGraphNets baseline)
trained self-supervised on anisofem's incremental potential.

    model = anisognn.load("runs/cpu/model.pt")
    positions = anisognn.rollout(model, scene, steps=100)   # (101, n, 3)
    model = anisognn.pretrained("directional")               # or "meshgraphnets"
"""
from .checkpoint import load
from .graph import Graph, from_scene
from .model import GraphNet, ModelConfig
from .shipped import pretrained
from .rollout import rollout

__all__ = ["load", "Graph", "from_scene", "GraphNet", "ModelConfig", "pretrained", "rollout"]
