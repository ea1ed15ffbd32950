"""The conjugate-gradient iterations after the network's step (ModelConfig.cg_iterations,
anisognn.krylov), against anisofem's assembled backward-Euler Hessian and rollout."""
import numpy as np
import pytest
import torch

import anisofem as af
from anisognn import graph as G
from anisognn.krylov import refine
from anisognn.model import GraphNet, ModelConfig, with_galerkin
from anisognn.rollout import rollout

DT = 0.02


def scene_of(mesh, poisson=0.48, kappa=2e5):
    d = np.array([1.0, 1.0, 0.0]) / np.sqrt(2.0)
    material = af.Material(1e5, poisson, 1000.0, d, kappa)
    return af.Scene(mesh, material, fixed=mesh.vertices[:, 0] <= 1e-9, gravity=[0, 0, -9.81])


def state(scene, seed):
    """(x, v, s): a strained state (m), velocities (m/s) and a trial step (m), random."""
    rng = np.random.default_rng(seed)
    X = scene.mesh.vertices
    x = scene.with_fixed(X + rng.normal(0, 1e-6, X.shape))
    free = ~scene.fixed_mask
    return x, rng.normal(0, 1e-4, X.shape) * free, rng.normal(0, 1e-6, X.shape) * free


def linearized(scene, x, v, s):
    """(A, r) of anisofem: the backward-Euler Hessian at x_hat + s on the free components and
    the force there minus the inertia of s, flattened (free unknowns only), and the free
    mask (3 n,)."""
    x_hat = x + DT * v
    free = (~scene.fixed_mask).ravel()
    r = -af.gradient(scene, x_hat + s, x_hat, DT).ravel()[free]
    A = af.hessian(scene, x_hat + s, x_hat, DT)[free][:, free].toarray()
    return A, r, free


def refined(scene, x, v, s, iterations, dtype=torch.float64, graph=None):
    graph = graph or G.from_scene(scene, dtype)
    u_hat = x - scene.mesh.vertices + DT * v
    return refine(torch.tensor(s, dtype=dtype), torch.tensor(u_hat),
                  torch.tensor(scene.external_force, dtype=dtype), graph, DT,
                  iterations).numpy()


@pytest.mark.parametrize("material", [dict(), dict(poisson=0.499, kappa=1e7)])
def test_enough_iterations_take_the_newton_step_of_anisofems_linearized_system(material):
    scene = scene_of(af.box_beam(cells=(3, 2, 1)), **material)
    x, v, s = state(scene, 0)
    A, r, free = linearized(scene, x, v, s)
    newton = s.ravel()[free] + np.linalg.solve(A, r)
    got = refined(scene, x, v, s, 3 * free.sum()).ravel()
    np.testing.assert_allclose(got[free], newton, rtol=0, atol=1e-8 * np.abs(newton).max())
    np.testing.assert_array_equal(got[~free], s.ravel()[~free])


def test_each_iteration_lowers_the_linearized_energy():
    """CG minimizes -r . d + 1/2 d^T A d over growing Krylov spaces: the value never rises,
    and falls by orders of magnitude towards the Newton step's."""
    scene = scene_of(af.box_beam(cells=(4, 2, 2)))
    x, v, s = state(scene, 1)
    A, r, free = linearized(scene, x, v, s)
    values = []
    for k in (0, 1, 2, 5, 10, 20, 50, 100, 200):
        d = refined(scene, x, v, s, k).ravel()[free] - s.ravel()[free]
        values.append(-r @ d + 0.5 * d @ (A @ d))
    best = -0.5 * r @ np.linalg.solve(A, r)
    assert values[0] == 0 and best < 0
    assert all(b <= a + 1e-12 * abs(best) for a, b in zip(values, values[1:])), values
    assert values[-1] - best < 1e-2 * (values[0] - best)


def test_a_batch_runs_one_system_per_member():
    scenes = [scene_of(af.box_beam(cells=(3, 2, 1))), scene_of(af.box_beam(cells=(2, 2, 2)))]
    states = [state(sc, 5 + k) for k, sc in enumerate(scenes)]
    parts = np.concatenate([refined(sc, *st, 6) for sc, st in zip(scenes, states)])
    graph = G.batch([G.from_scene(sc, torch.float64) for sc in scenes])
    joint = refine(*(torch.tensor(np.concatenate(t)) for t in (
        [st[2] for st in states],
        [st[0] - sc.mesh.vertices + DT * st[1] for sc, st in zip(scenes, states)],
        [sc.external_force for sc in scenes])), graph, DT, 6).numpy()
    np.testing.assert_allclose(joint, parts, rtol=0, atol=1e-12 * np.abs(parts).max())


def test_float32_graph_iterates_in_float64():
    """A float32 model's iterations run on a float64 copy of its graph: the same answer as a
    float64 graph up to the float32 rounding of the per-tet constants."""
    scene = scene_of(af.box_beam(cells=(4, 2, 2)))
    x, v, s = state(scene, 2)
    exact = refined(scene, x, v, s, 30)
    single = refined(scene, x, v, s.astype(np.float32), 30, torch.float32)
    assert single.dtype == np.float64
    np.testing.assert_allclose(single, exact, rtol=0, atol=1e-5 * np.abs(exact).max())


def test_a_zero_residual_or_a_rest_state_stays_put():
    """At anisofem's static equilibrium with zero velocity the backward-Euler step is zero: the
    iterations keep it zero (no 0/0)."""
    scene = scene_of(af.box_beam(cells=(3, 2, 1)))
    x = af.solve(scene).x
    got = refined(scene, x, np.zeros_like(x), np.zeros_like(x), 10)
    assert np.isfinite(got).all()
    assert np.abs(got).max() < 1e-9 * np.abs(x - scene.mesh.vertices).max()


def test_a_rollout_with_many_iterations_follows_anisofems_backward_euler():
    """An untrained network with the Galerkin step is far from the FEM; 100 iterations per step
    bring it to one Newton iteration from there, within 1% of the FEM's displacement over three
    steps (each iteration lowers the error: 20 are in between)."""
    torch.manual_seed(0)
    net = GraphNet(ModelConfig(latent=16, steps=2, galerkin=True)).double().eval()
    mesh = af.box_beam(size=(0.1, 0.02, 0.02), cells=(3, 1, 1))
    scene = scene_of(mesh)
    fem = af.simulate(scene, 3, dt=DT, warn=False).positions
    scale = np.abs(fem[-1] - fem[0]).max()
    errors = [np.abs(rollout(with_galerkin(net, True, 1, k), scene, 3) - fem).max() / scale
              for k in (0, 20, 100)]
    assert errors[0] > 0.05 and errors[0] > errors[1] > errors[2]
    assert errors[2] < 1e-2, errors


@pytest.mark.parametrize("bad", [-1, 1.5, True, "3"])
def test_config_rejects_a_bad_iteration_count(bad):
    with pytest.raises(ValueError, match="cg_iterations"):
        ModelConfig(cg_iterations=bad)


def test_with_galerkin_sets_and_keeps_the_iteration_count():
    net = GraphNet(ModelConfig(latent=8, steps=1, galerkin=True))
    more = with_galerkin(net, True, None, 7)
    assert more.config.cg_iterations == 7 and more.config.stepping.endswith("7 CG iterations")
    assert with_galerkin(more, False).config.cg_iterations == 7
    assert with_galerkin(more, True, 2, 0).config.stepping == "2 Galerkin passes"
