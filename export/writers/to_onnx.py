"""Export a trained anisognn model to ONNX: one backward-Euler step of the network, with the
input normalization inside the graph and dynamic numbers of vertices, edges and in-degree.

The graph's inputs and outputs, their shapes and dtypes, are export/runtime.py's INPUTS and
OUTPUTS (documented in export/README.md); the runtime builds the mesh tensors and steps the
model with numpy and onnxruntime only.

The exporter is torch's TorchScript-based one (torch.onnx.export(dynamo=False)): the
torch.export-based exporter needs the onnxscript package, which is not among this project's
dependencies, and the network is a static graph of Gather, MatMul, LayerNorm and elementwise
ops that the TorchScript exporter handles completely.
"""
import json
import warnings

import numpy as np
import onnx
import torch
from torch import nn

from anisofem.io.output import atomic_path

from anisognn.graph import Graph
from anisognn.model import GraphNet, integrate
from anisognn.sampler import DENSITY, POISSON, YOUNG

from ..runtime import FORMAT, INPUTS, OUTPUTS, STATE, mesh_tensors

#: names of the constant mesh inputs, in INPUTS order
CONSTANTS = tuple(name for name, _, _ in INPUTS if name not in STATE)

#: opset of the exported graph (LayerNormalization needs 17)
OPSET = 17
UNITS = ("SI: positions m, velocities m/s, external_force N per vertex, mass kg, rest lengths m, "
         "fiber features Pa, acceleration m/s^2")


class Step(nn.Module):
    """One step of a GraphNet as a module of plain tensors (the exported graph).

    The network runs in float32 on float32 casts of the state (the positions as displacements
    from rest_positions, subtracted in float64: GraphNet.forward); the integration
    x' = x + dt v + dt^2 a (held components at fixed_positions), v' = (x' - x) / dt runs in
    float64, as anisognn.rollout does, so that long rollouts do not drift by rounding."""

    def __init__(self, net):
        super().__init__()
        if not isinstance(net, GraphNet):
            raise TypeError(f"net: expected an anisognn GraphNet, got {type(net).__name__}")
        self.net = net
        self.dt = float(net.config.dt)

    def forward(self, positions, velocities, external_force, *constants):
        """The OUTPUTS from the state and the constant mesh tensors, in INPUTS order."""
        graph = Graph.from_inputs(dict(zip(CONSTANTS, constants)))
        a = self.net(positions, velocities.float(), external_force.float(), graph)
        return (a,) + integrate(positions, velocities, a.double(), self.dt, graph)


def example_inputs():
    """Tracing inputs: two tets sharing a face, deformed and moving (the sizes are dynamic in
    the export)."""
    gen = np.random.default_rng(0)
    vertices = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1]], float) * 0.01
    tets = np.array([[0, 1, 2, 3], [1, 2, 3, 4]])
    fixed = np.zeros((5, 3), bool)
    fixed[0] = True
    fiber = np.tile([1.0, 0.0, 0.0], (2, 1))
    values = mesh_tensors(vertices, tets, np.full(5, 1e-3), fixed, vertices, fiber,
                          np.full(2, 1e5), np.full(2, 3e4), np.full(2, 8e5))
    values["positions"] = vertices + gen.normal(scale=1e-4, size=vertices.shape)
    values["velocities"] = gen.normal(scale=1e-2, size=vertices.shape)
    values["external_force"] = gen.normal(scale=1e-2, size=vertices.shape)
    dtypes = {"float64": torch.float64, "float32": torch.float32, "int64": torch.int64}
    return tuple(torch.tensor(values[name], dtype=dtypes[dtype]) for name, dtype, _ in INPUTS)


def metadata(net, version):
    """The ONNX file's metadata_props: what a runtime needs to check and step the model."""
    return {"format": FORMAT, "config": json.dumps(net.config.to_dict()),
            "aggregation": net.config.aggregation, "dt": repr(float(net.config.dt)),
            "units": UNITS, "version": version,
            "trained_material": json.dumps({"young": YOUNG, "poisson": POISSON,
                                            "density": DENSITY}),
            "inputs": json.dumps([list(i) for i in INPUTS]),
            "outputs": json.dumps([list(o) for o in OUTPUTS])}


def export(net, path, version=None):
    """Write the ONNX graph of one step of net (a GraphNet) to path atomically; returns path."""
    version = version or _version()
    step = Step(net.to("cpu", torch.float32).eval())
    names = [name for name, _, _ in INPUTS]
    dynamic = {name: {i: d for i, d in enumerate(shape) if isinstance(d, str)}
               for name, _, shape in INPUTS + OUTPUTS}
    with atomic_path(path, ".onnx") as tmp:
        with warnings.catch_warnings(), torch.no_grad():
            warnings.simplefilter("ignore", DeprecationWarning)
            torch.onnx.export(step, example_inputs(), tmp, dynamo=False, opset_version=OPSET,
                              input_names=names, output_names=[o for o, _, _ in OUTPUTS],
                              dynamic_axes=dynamic)
        model = onnx.load(tmp)
        onnx.helper.set_model_props(model, metadata(net, version))
        onnx.checker.check_model(model)
        onnx.save(model, tmp)
    return path


def _version():
    """The version of the installed distribution (setup.cfg: anisofem, which ships anisognn)."""
    from importlib.metadata import PackageNotFoundError, version
    try:
        return version("anisofem")
    except PackageNotFoundError:
        return "unknown"
