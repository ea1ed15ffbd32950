"""anisognn graph, model and loss: conventions, equivariance, aggregation, loss derivative."""
from types import SimpleNamespace

import numpy as np
import pytest
import torch

import anisofem as af
import anisognn
from anisognn import graph as G
from anisognn.elastic import elastic_force
from anisognn.loss import BatchPotential, potential_loss
from anisognn.model import GraphNet, ModelConfig, integrate
from export import runtime


def fiber_scene(mesh, direction=(1.0, 1.0, 0.0), kappa=2e5):
    d = np.asarray(direction, float)
    material = af.Material(1e5, 0.48, 1000.0, d / np.linalg.norm(d), kappa)
    return af.Scene(mesh, material, fixed=mesh.vertices[:, 0] <= 1e-9, gravity=[0, 0, -9.81])


def test_reverse_edges_carry_opposite_weights_and_the_same_fiber():
    g = G.from_scene(fiber_scene(af.box_beam(cells=(4, 2, 2))))
    k = g.n_edges // 2
    assert torch.equal(g.senders[:k], g.receivers[k:])
    assert torch.equal(g.rest[:k, :3], -g.rest[k:, :3])       # weights = unit rest vectors
    assert torch.equal(g.rest[:k, 3], g.rest[k:, 3])          # same length
    assert torch.equal(g.fiber[:k], g.fiber[k:])
    assert torch.allclose(g.rest[:, :3].norm(dim=1), torch.ones(g.n_edges))


def test_fiber_sign_does_not_matter_and_per_element_fibers_do_not_cancel():
    mesh = af.box_beam(cells=(4, 2, 2))
    d = np.tile([0.6, 0.0, 0.8], (mesh.n_tets, 1))
    d[::2] *= -1  # half the tets store -d: the same fiber
    mixed = G.from_scene(af.Scene(mesh, af.Material(1e5, 0.48, 1000.0, d, 3e5), fixed=[0]))
    plain = G.from_scene(fiber_scene(mesh, (0.6, 0.0, 0.8), 3e5))
    assert torch.allclose(mixed.fiber, plain.fiber, rtol=1e-6, atol=1e-6 * 3e5)
    assert torch.allclose(plain.fiber.norm(dim=1), torch.full((plain.n_edges,), 3e5))


def test_incoming_table_lists_every_edge_once_at_its_receiver():
    g = G.from_scene(fiber_scene(af.cylinder_beam(0.06, 0.01, 3, 2, 1)))
    seen = np.zeros(g.n_edges, int)
    for vertex, row in enumerate(g.incoming.numpy()):
        for slot, e in enumerate(row):
            if e == g.n_edges:
                assert g.in_weights[vertex, slot].abs().sum() == 0
                continue
            seen[e] += 1
            assert g.receivers[e] == vertex
            assert torch.equal(g.in_weights[vertex, slot], g.rest[e, :3])
    assert (seen == 1).all()


def permuted_mesh(mesh, perm):
    """mesh with vertex i renamed to perm[i]."""
    vertices = np.empty_like(mesh.vertices)
    vertices[perm] = mesh.vertices
    return af.TetMesh(vertices, perm[mesh.tets])


@pytest.mark.parametrize("aggregation", ["directional", "sum"])
def test_permutation_equivariance(aggregation):
    torch.manual_seed(0)
    model = GraphNet(ModelConfig(latent=16, steps=3, aggregation=aggregation)).double()
    torch.nn.init.normal_(model.decoder[-1].weight)  # the zero initialization hides nothing
    mesh = af.box_beam(cells=(4, 2, 2))
    rng = np.random.default_rng(1)
    perm = rng.permutation(mesh.n_vertices)
    out = []
    for m, order in ((mesh, np.arange(mesh.n_vertices)), (permuted_mesh(mesh, perm), perm)):
        scene = fiber_scene(m)
        x = m.vertices + 1e-3 * np.sin(40 * m.vertices)
        v = 1e-2 * np.cos(30 * m.vertices)
        g = G.from_scene(scene, torch.float64)
        a = model(torch.tensor(x), torch.tensor(v), torch.tensor(scene.external_force), g)
        out.append((a.detach().numpy(), order))
    (a0, _), (a1, order) = out
    assert np.abs(a1[order] - a0).max() < 1e-10 * np.abs(a0).max()
    assert np.abs(a0).max() > 0


def test_aggregations_differ_only_in_the_processor_aggregation():
    shapes = {agg: {k: tuple(v.shape) for k, v in
                    GraphNet(ModelConfig(latent=16, steps=2, aggregation=agg)).state_dict().items()}
              for agg in ("directional", "sum")}
    assert shapes["directional"].keys() == shapes["sum"].keys()
    differ = {k for k in shapes["sum"] if shapes["sum"][k] != shapes["directional"][k]}
    # only the first layer of each vertex update reads the aggregate: 3 channels vs 1
    assert differ == {f"vertex_updates.{i}.0.weight" for i in range(2)}
    assert shapes["directional"]["vertex_updates.0.0.weight"] == (16, 16 * 4)
    assert shapes["sum"]["vertex_updates.0.0.weight"] == (16, 16 * 2)


def noisy_state(scene, rng):
    """Positions 1 mm and velocities 5 cm/s off rest (both (n, 3), m and m/s), held ones kept."""
    n = scene.mesh.n_vertices
    x = scene.initial_positions() + 1e-3 * rng.normal(size=(n, 3))
    x[scene.fixed_mask] = scene.fixed_positions[scene.fixed_mask]
    return x, 0.05 * rng.normal(size=(n, 3))


def test_loss_gradient_wrt_acceleration_matches_finite_differences():
    scene = fiber_scene(af.box_beam(cells=(3, 1, 1)))
    n = scene.mesh.n_vertices
    rng = np.random.default_rng(0)
    x, v = noisy_state(scene, rng)
    dt = 0.02
    g = G.from_scene(scene, torch.float64)
    pot = BatchPotential.backward_euler([scene], x, v, dt)
    xt, vt = torch.tensor(x), torch.tensor(v)

    def loss(a):
        return potential_loss(integrate(xt, vt, a, dt, g)[0], pot)
    a = torch.tensor(rng.normal(size=(n, 3)) * 5.0, requires_grad=True)
    loss(a).backward()
    h = 1e-3
    for i, c in [(n - 1, 2), (n - 2, 0), (5, 1), (0, 0)]:
        ap, am = a.detach().clone(), a.detach().clone()
        ap[i, c] += h
        am[i, c] -= h
        fd = (float(loss(ap)) - float(loss(am))) / (2 * h)
        assert abs(float(a.grad[i, c]) - fd) <= 1e-6 * max(abs(fd), 1e-12) + 1e-14, (i, c)
    held = scene.fixed_mask
    assert held.any() and (a.grad.numpy()[held] == 0).all()  # held components ignore a


def newton_setup(kappa, seed, dt=0.02):
    """A 3 x 1 x 1 box beam (fiber stiffness kappa, Pa) at a noisy state, its backward-Euler
    potential over dt (s), the potential's value e0 and gradient g ((n, 3)) there, the free
    components (3n mask), W = M/dt^2 and the projected Hessian H at dt on them."""
    scene = fiber_scene(af.box_beam(cells=(3, 1, 1)), kappa=kappa)
    x, v = noisy_state(scene, np.random.default_rng(seed))
    pot = BatchPotential.backward_euler([scene], x, v, dt)
    e0, g = pot.energy_gradient(x)
    free = ~scene.fixed_mask.reshape(-1)
    H = af.hessian(scene, x, x + dt * v, dt, project=True).toarray()[np.ix_(free, free)]
    W = np.repeat(scene.masses / dt ** 2, 3)[free]
    return SimpleNamespace(scene=scene, x=x, v=v, dt=dt, pot=pot, e0=e0, g=g, free=free, W=W, H=H)


@pytest.mark.parametrize("kappa", [2e5, 1e7])
def test_newton_term_is_the_mass_scaled_newton_step(kappa):
    """gradient(beta) - gradient(0) = beta (M/dt^2) H^-1 g on free components, H the projected
    Hessian (checked by multiplying back), nothing added on held ones; ordinary and stiff fibers."""
    s, beta = newton_setup(kappa, seed=1), 50.0
    e1, gb = s.pot.energy_gradient(s.x, beta)
    g, e0 = s.g, s.e0
    step = ((gb - g).reshape(-1)[s.free] / beta / s.W)
    assert np.allclose(s.H @ step, g.reshape(-1)[s.free], rtol=1e-9, atol=1e-9 * np.abs(g).max())
    held = s.scene.fixed_mask
    assert (gb[held] == g[held]).all()  # integrate() drops these
    assert e1 == pytest.approx(e0 + 0.5 * beta * step @ (s.W * step), rel=1e-12)
    # the Newton term alone: no energy gradient left
    e2, gn = s.pot.energy_gradient(s.x, beta, energy_weight=0.0)
    assert np.allclose(gn, gb - g, rtol=1e-12, atol=1e-12 * np.abs(gb).max())
    assert e2 == pytest.approx(e1 - e0, rel=1e-9)


@pytest.mark.parametrize("dt", [1e-4, 0.02])
def test_normalization_divides_by_the_newton_decrease_at_the_start(dt):
    """weights / D with D = 1/2 g0^T H0^-1 g0 at x_hat; for a tiny step from rest D is the
    free fall's 1/2 dt^2 sum |f|^2 / m (inertia dominates the Hessian)."""
    scene = fiber_scene(af.box_beam(cells=(3, 1, 1)))
    x = scene.initial_positions()
    v = np.zeros_like(x)
    pot = BatchPotential.backward_euler([scene], x, v, dt, weights=[3.0], normalize=True)
    free = ~scene.fixed_mask.reshape(-1)
    g0 = af.gradient(scene, x, x, dt).reshape(-1)[free]
    H0 = af.hessian(scene, x, x, dt, project=True).toarray()[np.ix_(free, free)]
    decrease = 0.5 * g0 @ np.linalg.solve(H0, g0)
    assert pot.weights[0] == pytest.approx(3.0 / decrease, rel=1e-9)
    if dt == 1e-4:
        f = scene.external_force.reshape(-1)[free]
        m = np.repeat(scene.masses, 3)[free]
        assert decrease == pytest.approx(0.5 * dt ** 2 * (f ** 2 / m).sum(), rel=1e-3)


def test_model_runs_on_a_batch_equal_to_its_parts():
    torch.manual_seed(0)
    model = GraphNet(ModelConfig(latent=16, steps=2)).double()
    torch.nn.init.normal_(model.decoder[-1].weight)
    scenes = [fiber_scene(af.box_beam(cells=(3, 2, 1))), fiber_scene(af.cylinder_beam(
        0.06, 0.01, 3, 2, 0), (0, 0, 1))]
    parts, xs = [], []
    for s in scenes:
        x = torch.tensor(s.mesh.vertices + 1e-3)
        parts.append(model(x, torch.zeros_like(x), torch.tensor(s.external_force),
                           G.from_scene(s, torch.float64)))
        xs.append(x)
    gb = G.batch([G.from_scene(s, torch.float64) for s in scenes])
    xb = torch.cat(xs)
    fb = torch.tensor(np.concatenate([s.external_force for s in scenes]))
    joint = model(xb, torch.zeros_like(xb), fb, gb)
    assert torch.allclose(joint, torch.cat(parts), rtol=1e-12, atol=1e-12)


def test_runtime_edges_match_anisofem():
    mesh = af.t_shape()
    assert np.array_equal(runtime.mesh_edges(mesh.tets), mesh.edges)


def test_config_validation():
    with pytest.raises(ValueError, match="aggregation"):
        ModelConfig(aggregation="mean")
    with pytest.raises(ValueError, match="latent"):
        ModelConfig(latent=0)
    with pytest.raises(ValueError, match="dt"):
        ModelConfig(dt=0.0)
    with pytest.raises(ValueError, match="galerkin"):
        ModelConfig(galerkin=1)
    with pytest.raises(ValueError, match="galerkin_passes.*galerkin = true"):
        ModelConfig(galerkin_passes=2)
    assert anisognn.ModelConfig().latent == 128 and ModelConfig().steps == 15


def per_element_fiber_scene(mesh, seed):
    """mesh with a random unit fiber and stiffness (up to 10 E) per tet, nothing held, no load."""
    rng = np.random.default_rng(seed)
    d = rng.normal(size=(mesh.n_tets, 3))
    material = af.Material(1e5, 0.48, 1000.0, d / np.linalg.norm(d, axis=1, keepdims=True),
                           rng.uniform(0.0, 1e6, mesh.n_tets))
    return af.Scene(mesh, material, gravity=(0.0, 0.0, 0.0))


@pytest.mark.parametrize("strain", [1e-3, 0.3])
def test_elastic_force_is_minus_anisofems_gradient_on_a_batch(strain):
    scenes = [per_element_fiber_scene(af.box_beam(cells=(4, 2, 2)), 0),
              per_element_fiber_scene(af.cylinder_beam(), 1)]
    rng = np.random.default_rng(2)
    xs = [s.mesh.vertices + rng.normal(0, strain * 0.01, s.mesh.vertices.shape) for s in scenes]
    expected = np.concatenate([-af.gradient(s, x) for s, x in zip(scenes, xs)])
    graph = G.batch([G.from_scene(s, torch.float64) for s in scenes])
    got = elastic_force(graph.displacement(torch.tensor(np.concatenate(xs)), torch.float64),
                        graph).numpy()
    assert np.abs(expected).max() > 1e-3
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-10 * np.abs(expected).max())
    # float32, as the network reads it: from the displacement float32 keeps its own precision
    # (from float32 positions a strain of 1e-3 kept two to three digits)
    single = G.from_scene(scenes[0])
    got32 = elastic_force(single.displacement(torch.tensor(xs[0]), torch.float32),
                          single).numpy()
    n0 = scenes[0].mesh.n_vertices
    assert np.abs(got32 - expected[:n0]).max() <= 2e-6 * np.abs(expected[:n0]).max()


def test_runtime_shape_gradients_are_anisofems():
    mesh = af.cylinder_beam()
    np.testing.assert_allclose(runtime.shape_gradients(mesh.vertices, mesh.tets),
                               mesh.shape_gradients, rtol=1e-12, atol=1e-9)


