"""The deployed model's rung of the speed/accuracy ladder (anisofem.trade finds onnx_rungs
through the "anisofem.rungs" entry point): the shipped directional.onnx stepped by runtime.py,
numpy and onnxruntime only."""
import json
import os

import numpy as np
import onnxruntime

from anisofem.studies.rungs import Rung

from . import model_path
from .runtime import OnnxSimulator, _lame


def onnx_rung(name, path):
    """The exported model at path stepped by export/runtime.py."""
    def make(scene, dt):
        el = scene.elements
        sim = OnnxSimulator(path, scene.mesh.vertices, scene.mesh.tets, fixed=scene.fixed_mask,
                            density=scene.material.per_element(scene.mesh.n_tets)["density"],
                            fiber_direction=el.fiber, fiber_stiffness=el.kappa)
        f = scene.external_force

        def advance(x, v):
            try:
                x, v = sim.step(x, v, f)
            except FloatingPointError:
                return x, v, {"failed": True}
            return x.astype(np.float64), v.astype(np.float64), {"failed": False}
        return advance
    return Rung(name, "surrogate", make)


def _unlike_runtime(scene, dt, metadata):
    """Why the runtime of a model with this ONNX metadata cannot step scene at dt (s): its dt,
    the trained StVK material, held vertices at rest; None when it can."""
    trained_dt = float(metadata["dt"])
    if scene.mesh.order != 1:
        return (f"the model steps linear tets, and this mesh has quadratic ones (order "
                f"{scene.mesh.order})")
    if not np.isclose(dt, trained_dt, rtol=1e-9, atol=0):
        return f"the model steps dt = {trained_dt} s, the trade runs dt = {dt} s"
    trained = json.loads(metadata["trained_material"])
    mu, lam = _lame(trained)
    p = scene.material.per_element(scene.mesh.n_tets)
    if (scene.neohookean.any() or not np.allclose(p["mu"], mu)
            or not np.allclose(p["lam"], lam)):
        return (f"runtime.py steps the trained material (StVK, E = {trained['young']:g} Pa, "
                f"nu = {trained['poisson']:g}), and this scene's differs")
    if not np.array_equal(scene.fixed_positions, scene.mesh.vertices):
        return "runtime.py holds vertices at rest, and this scene moves them"
    return None


def onnx_rungs(scene, dt, notes):
    """The shipped directional.onnx's rung for scene at dt (s); what cannot run is said in
    notes."""
    path = model_path("directional")
    if not os.path.isfile(path):
        notes.append(f"ONNX rung skipped: {path} is missing")
        return []
    session = onnxruntime.InferenceSession(path, providers=["CPUExecutionProvider"])
    reason = _unlike_runtime(scene, dt, session.get_modelmeta().custom_metadata_map)
    if reason:
        notes.append(f"ONNX rung skipped: {reason}")
        return []
    return [onnx_rung("directional.onnx (shipped)", path)]
