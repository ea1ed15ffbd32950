"""The network's rungs of the speed/accuracy ladder (anisofem.trade finds surrogate_rungs through
the "anisofem.rungs" entry point): the shipped networks alone, with their Galerkin passes,
followed by conjugate-gradient iterations, and as the warm start of one Newton iteration; and,
side by side, the same Galerkin passes and iterations with the previous step's acceleration in
the network's place (what the network's direction buys)."""
import numpy as np
import torch

from anisofem import Material
from anisofem.solvers.solve import Stepper
from anisofem.studies.rungs import Rung

from .galerkin import galerkin_acceleration
from .graph import from_scene
from .krylov import refine
from .model import with_galerkin
from .rollout import network_step, torch_threads
from .sampler import DENSITY, POISSON, YOUNG
from .shipped import NAMES, pretrained

#: CG iterations after the step on the ladder, each with the network and without it
CG_ITERATIONS = (10, 40)


def _network_step(model, scene):
    """advance(x, v) -> (x, v, info) of the model on scene for ladder.Rung, with the model's
    acceleration in info["acceleration"]."""
    step = network_step(model, scene)

    def advance(x, v):
        x_next, v_next, a = step(x, v)
        return x_next, v_next, {"failed": not bool(np.isfinite(x_next).all()), "acceleration": a}
    return advance


def network_rung(name, model):
    """The model stepping alone (its Galerkin passes, if any, included)."""
    return Rung(name, "surrogate", lambda scene, dt: _network_step(model, scene))


def previous_acceleration_rung(name, passes, iterations):
    """The shipped step without its network: `passes` Galerkin passes with the previous step's
    acceleration (zero at the first) as the first direction, then `iterations` CG iterations,
    all in float64 (anisognn.galerkin, anisognn.krylov)."""
    def make(scene, dt):
        graph = from_scene(scene, torch.float64)
        rest = scene.mesh.vertices
        f_ext = torch.tensor(scene.external_force)
        held = scene.fixed_mask
        previous = [torch.zeros(rest.shape, dtype=torch.float64)]

        def advance(x, v):
            torch_threads()
            u, v_t = torch.tensor(x - rest), torch.tensor(v)
            with torch.no_grad():
                a = galerkin_acceleration(previous[0], u, v_t, f_ext, graph, dt, passes)
                step = refine(a * (dt * dt), u + dt * v_t, f_ext, graph, dt, iterations)
            x_next = x + dt * v + step.numpy()
            x_next[held] = scene.fixed_positions[held]
            previous[0] = torch.tensor((x_next - x - dt * v) / (dt * dt))
            return x_next, (x_next - x) / dt, {"failed": not bool(np.isfinite(x_next).all())}
        return advance
    return Rung(name, "surrogate", make)


def warm_start_rung(name, model, iterations=1):
    """The model's acceleration as the start of `iterations` Newton iterations."""
    def make(scene, dt):
        predict = _network_step(model, scene)
        stepper = Stepper(scene, dt, "newton", iterations=iterations)

        def advance(x, v):
            guess = predict(x, v)[2]["acceleration"]
            res = stepper(x, v, guess)
            n = res.newton
            return res.x, res.v, {"failed": n.failed, "iterations": n.iterations,
                                  "factorizations": n.factorizations}
        return advance
    return Rung(name, "surrogate", make)


def _trained_material(scene):
    """True when every tet has the material the shipped models were trained on."""
    p = scene.material.per_element(scene.mesh.n_tets)
    trained = Material(YOUNG, POISSON, DENSITY).per_element(1)
    return all(np.allclose(p[k], trained[k][0]) for k in ("mu", "lam", "density"))


def surrogate_rungs(scene, dt, notes):
    """The shipped models' rungs for scene (an anisofem.Scene) at dt (s); what cannot run is
    said in notes."""
    try:
        models = {name: pretrained(name) for name in NAMES}
    except FileNotFoundError as err:
        notes.append(f"surrogate rungs skipped: {err}")
        return []
    trained_dt = models["directional"].config.dt
    if not np.isclose(dt, trained_dt, rtol=1e-9, atol=0):
        notes.append(f"surrogate rungs skipped: the shipped models step dt = {trained_dt} s, "
                     f"the trade runs dt = {dt} s")
        return []
    if scene.mesh.order != 1:
        notes.append(f"surrogate rungs skipped: the shipped models step linear tets, and this "
                     f"mesh has quadratic ones (order {scene.mesh.order})")
        return []
    if scene.neohookean.any():
        notes.append("surrogate rungs skipped: the shipped models were trained on the StVK "
                     "base material, and this scene uses Neo-Hookean elements")
        return []
    if not _trained_material(scene):
        notes.append("the shipped models were trained on E = 100 kPa, nu = 0.48, 1000 kg/m^3; "
                     "this scene's material differs (their rungs show what that costs)")
    directional = models["directional"]
    rungs = [network_rung("directional, no pass", with_galerkin(directional, False)),
             network_rung("directional, 1 pass", with_galerkin(directional, True, 1)),
             network_rung("directional (shipped)", directional),
             network_rung("meshgraphnets (shipped)", models["meshgraphnets"]),
             warm_start_rung("directional + newton x1", directional)]
    passes = directional.config.galerkin_passes
    for k in CG_ITERATIONS:
        rungs += [network_rung(f"directional + cg x{k}", with_galerkin(directional, True, None, k)),
                  previous_acceleration_rung(f"no network + cg x{k}", passes, k)]
    return rungs
