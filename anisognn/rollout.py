"""Inference: roll a trained model forward on an anisofem.Scene."""
import numpy as np
import torch

from anisofem import Scene, threads
from anisofem._validate import as_float_array, as_scalar

from .graph import from_scene
from .model import GraphNet


def check_dt(model, dt):
    """The model's trained dt (s); a different dt is an error (the network learned one step
    length)."""
    trained = model.config.dt
    if dt is None:
        return trained
    dt = as_scalar(dt, "dt")
    if not np.isclose(dt, trained, rtol=1e-9, atol=0):
        raise ValueError(f"dt: this model was trained for dt = {trained} s and cannot step "
                         f"dt = {dt} s")
    return trained


def rollout(model, scene, steps, dt=None, x0=None, v0=None):
    """Positions of every step, (steps + 1, n, 3) float64 in m, starting at x0 (default rest)
    with velocities v0 (default 0), under the scene's loads. Held (Dirichlet) components stay at
    the scene's fixed positions. dt defaults to the model's and must equal it."""
    if not isinstance(model, GraphNet):
        raise TypeError(f"model: expected an anisognn GraphNet, got {type(model).__name__}")
    if not isinstance(scene, Scene):
        raise TypeError(f"scene: expected an anisofem.Scene, got {type(scene).__name__}")
    dt = check_dt(model, dt)
    steps = int(steps)
    if steps < 0:
        raise ValueError(f"steps: must be >= 0, got {steps}")
    n = scene.mesh.n_vertices
    x = scene.initial_positions() if x0 is None else scene.with_fixed(
        as_float_array(x0, "x0", (n, 3)))
    v = np.zeros((n, 3)) if v0 is None else as_float_array(v0, "v0", (n, 3))
    advance = network_step(model, scene)
    out = np.empty((steps + 1, n, 3))
    out[0] = x
    for k in range(steps):
        x_next, v, _ = advance(x, v)
        if not np.isfinite(x_next).all():
            raise FloatingPointError(f"rollout: the predicted state is not finite at step "
                                     f"{k + 1}")
        x = out[k + 1] = x_next
    return out


_TORCH = {"set": None, "most": None}


def torch_threads():
    """Set torch's intra-op thread count for the inference about to run on the CPU: the
    count torch had when a caller last chose one (torch's default: the cores), lowered to
    anisofem.threads.available() while other processes keep cores busy. torch's OpenMP threads
    wait at each operation's end for the slowest, and a descheduled one holds them all: a
    200-tet step of the shipped network took 580 ms beside 2 busy processes on 2 threads, 7 ms
    idle (docs/network.md)."""
    now = torch.get_num_threads()
    if now != _TORCH["set"]:  # chosen by the caller (or torch's default), not by this function
        _TORCH["most"] = now
    n = min(_TORCH["most"], threads.available())
    if n != now:
        torch.set_num_threads(n)
    _TORCH["set"] = n


def network_step(model, scene):
    """advance(x, v) -> (x_next, v_next, a): one step of the model's dt on scene, the network
    in its own dtype and device (given the positions in float64: GraphNet.forward), the state
    (n, 3) in float64 m and m/s; a (n, 3) m/s^2 is the model's acceleration; held components
    stay at the scene's fixed positions."""
    param = next(model.parameters())
    graph = from_scene(scene).to(param.device, param.dtype)
    f_ext = torch.tensor(scene.external_force, dtype=param.dtype, device=param.device)
    held, dt = scene.fixed_mask, model.config.dt

    def advance(x, v):
        if param.device.type == "cpu":
            torch_threads()
        with torch.no_grad():
            a = model(torch.as_tensor(x, dtype=torch.float64, device=param.device),
                      torch.as_tensor(v, dtype=param.dtype, device=param.device), f_ext, graph)
        a = a.to("cpu", torch.float64).numpy()
        x_next = x + dt * v + dt * dt * a
        x_next[held] = scene.fixed_positions[held]
        return x_next, (x_next - x) / dt, a
    return advance
