"""The inversion-safe Neo-Hookean base: its small-strain limit is StVK, its projection is the
eigenvalue clamp, and the scenes that turn StVK inside out stay physical with it."""
import warnings

import numpy as np
import pytest
from test_derivatives import deformed, random_tet

import anisofem as af
from anisofem.physics.potential import Potential

E = 1e5


def cantilever(model, gravity=9.81, cells=(10, 2, 2)):
    """The README's cantilever: 0.1 x 0.02 x 0.02 m, fibers along it with kappa = E."""
    mesh = af.box_beam(cells=cells)
    x = mesh.vertices[:, 0]
    mat = af.Material(E, 0.48, 1000.0, (1.0, 0.0, 0.0), E, model=model)
    return af.Scene(mesh, mat, fixed=np.flatnonzero(x <= x.min() + 1e-9),
                    gravity=(0.0, 0.0, -gravity))


def tip_sag(scene, x):
    X = scene.mesh.vertices
    tip = X[:, 0] >= X[:, 0].max() - 1e-9
    return -float((x - X)[tip, 2].mean())


def mechanical_energy(scene, x, v):
    return Potential(scene).energy(x) + 0.5 * float((scene.masses[:, None] * v * v).sum())


def test_small_strain_limit_is_stvk():
    rng = np.random.default_rng(5)
    mesh = random_tet(rng)
    d = rng.standard_normal(3)
    scenes = [af.Scene(mesh, af.Material(E, 0.45, 1000.0, d / np.linalg.norm(d), 2 * E,
                                         model=m)) for m in af.physics.material.MODELS]
    rest = mesh.vertices
    H = [af.hessian(s, rest).toarray() for s in scenes]
    assert np.abs(H[1] - H[0]).max() <= 1e-12 * np.abs(H[0]).max()
    for strain in (1e-3, 1e-5):
        x = deformed(rng, mesh, (1 + strain, 1 - 0.5 * strain, 1 + 0.3 * strain))
        g = [af.gradient(s, x) for s in scenes]
        # the two energies differ at second order in the strain: relative gap ~ strain
        gap = np.linalg.norm(g[1] - g[0]) / np.linalg.norm(g[0])
        assert gap < 3 * strain
    sags = [tip_sag(s, af.solve(s).x) for s in (cantilever("stvk"), cantilever("neohookean"))]
    assert abs(sags[1] - sags[0]) <= 0.01 * sags[0]


def f_space_clamp(mesh, He):
    """The element Hessian with the eigenvalues of its 9x9 F-space form clamped at zero."""
    G = mesh.shape_gradients[0]
    B = np.zeros((9, 12))
    for i in range(3):
        for j in range(3):
            for a in range(4):
                B[3 * i + j, 3 * a + i] = G[a, j]
    Bp = np.linalg.pinv(B)
    w, Q = np.linalg.eigh(Bp.T @ He @ Bp)
    return B.T @ (Q * np.maximum(w, 0.0)) @ Q.T @ B


@pytest.mark.parametrize("nu", [0.3, 0.48, 0.499])
@pytest.mark.parametrize("stretches", [(0.5, 0.9, 0.7), (0.2, 1.0, 1.3), (3.0, 2.0, 0.5),
                                       (1.3, 1.2, 1.1), (1.0, 1.0, 1.0 - 1e-9), (2.5, 2.5, 2.5)])
def test_projection_clamps_the_negative_eigenvalues(nu, stretches):
    rng = np.random.default_rng(int(nu * 1000) + int(sum(stretches) * 100))
    mesh = random_tet(rng)
    scene = af.Scene(mesh, af.Material(E, nu, 1000.0, model="neohookean"))
    x = deformed(rng, mesh, stretches)
    H = af.hessian(scene, x).toarray()
    Hp = af.hessian(scene, x, project=True).toarray()
    expected = f_space_clamp(mesh, H)
    assert np.abs(Hp - expected).max() <= 1e-9 * np.abs(H).max()
    assert np.linalg.eigvalsh(Hp).min() >= -1e-12 * np.abs(H).max()


def test_projection_with_fibers_is_psd_and_exact_where_nothing_is_negative():
    rng = np.random.default_rng(9)
    for stretches, compressed in [((0.5, 0.9, 0.7), True), ((1.3, 1.2, 1.1), False)]:
        mesh = random_tet(rng)
        d = rng.standard_normal(3)
        scene = af.Scene(mesh, af.Material(E, 0.3, 1000.0, d / np.linalg.norm(d), 10 * E,
                                           model="neohookean"))
        x = deformed(rng, mesh, stretches)
        H = af.hessian(scene, x).toarray()
        Hp = af.hessian(scene, x, project=True).toarray()
        assert np.linalg.eigvalsh(Hp).min() >= -1e-12 * np.abs(H).max()
        if compressed:
            assert np.linalg.eigvalsh(H).min() < -1e-6 * np.abs(H).max()
        else:
            assert np.abs(Hp - H).max() <= 1e-12 * np.abs(H).max()


def test_growing_gravity_inverts_stvk_and_not_neohookean():
    gravities = [9.81, 98.1, 981.0, 9810.0, 98100.0]
    inverted, sags = {}, {}
    for model in af.physics.material.MODELS:
        inverted[model], sags[model] = [], []
        for g in gravities:
            scene = cantilever(model, g)
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                result = af.solve(scene)
            assert result.converged
            inv = result.inversion
            warned = any(issubclass(w.category, af.InversionWarning) for w in caught)
            assert warned == (inv.inverted > 0) == (inv.min_volume_ratio <= 0)
            inverted[model].append(inv.inverted)
            sags[model].append(tip_sag(scene, result.x))
    # StVK: every load from 10 g up converges to a turned-inside-out state, and says so
    assert inverted["stvk"][0] == 0 and all(k > 0 for k in inverted["stvk"][1:])
    assert inverted["neohookean"] == [0] * len(gravities)
    assert np.all(np.diff(sags["neohookean"]) > 0)


def test_cantilever_dropped_under_10g_stays_physical():
    scene = cantilever("neohookean", 98.1)
    rollout = af.simulate(scene, 100, dt=0.02)
    assert rollout.converged and rollout.physical
    energies = [mechanical_energy(scene, x, v)
                for x, v in zip(rollout.positions, rollout.velocities)]
    # backward Euler dissipates: never above where it started
    assert max(energies) <= energies[0] + 1e-9 * abs(min(energies))
    assert tip_sag(scene, rollout.positions[-1]) > 0.02


def squash(model, steps=40, dt=0.01, height=0.04):
    """A block pressed to half its height by its top face, moved down at constant speed:
    (results of each step, mechanical energies, scene at the end)."""
    mesh = af.box_beam(size=(height, height, height), cells=(4, 4, 4))
    z = mesh.vertices[:, 2]
    top = z >= z.max() - 1e-9
    scene = af.Scene(mesh, af.Material(E, 0.48, 1000.0, (1.0, 0.0, 0.0), E, model=model),
                     fixed=np.flatnonzero(top | (z <= z.min() + 1e-9)))
    x, v = mesh.vertices.copy(), np.zeros_like(mesh.vertices)
    results, energies = [], []
    for k in range(steps):
        target = mesh.vertices.copy()
        target[top, 2] -= 0.5 * height * (k + 1) / steps
        moved = scene.held_at(target)
        res = af.step(moved, x, v, dt, warn=False)
        results.append(res.newton)
        x, v = res.x, res.v
        energies.append(mechanical_energy(moved, x, v))
    return results, energies, moved, x


def test_block_squashed_to_half_height_stays_physical():
    results, energies, scene, x = squash("neohookean")
    assert all(r.converged for r in results)
    assert max(r.inversion.inverted for r in results) == 0
    assert min(r.inversion.min_volume_ratio for r in results) > 0.3
    # the energy stays within a few times the static energy of the squashed block
    static = af.solve(scene, x0=x)
    assert static.converged and static.physical
    assert np.isfinite(energies).all()
    assert max(energies) <= 3 * Potential(scene).energy(static.x)
    stvk = squash("stvk")[0]
    assert max(r.inversion.inverted for r in stvk) > 0  # the scene does turn StVK inside out


def test_a_start_outside_the_domain_is_refused_or_avoided():
    scene = cantilever("neohookean")
    x0 = scene.mesh.vertices.copy()
    x0[:, 2] *= -1.0  # mirrored: every element inverted
    with pytest.raises(ValueError, match=r"x0: \d+ Neo-Hookean elements start turned inside out"):
        af.solve(scene, x0=x0)
    # prescribed positions that jump through the body in one step
    target = scene.mesh.vertices.copy()
    held = scene.fixed_mask[:, 0]
    target[held, 0] += 0.05
    with pytest.raises(ValueError, match="fixed_positions: .* move the prescribed positions"):
        af.step(scene.held_at(target), scene.mesh.vertices, np.zeros_like(target), 0.02)
    # a velocity whose inertial predictor inverts elements: the step starts from x_n instead
    v = np.zeros_like(target)
    v[~held, 2] = np.where(scene.mesh.vertices[~held, 2] > 0, -0.6, 0.6)
    res = af.step(scene, scene.mesh.vertices, v, 0.02)
    assert scene.outside_domain(scene.mesh.vertices + 0.02 * v) > 0
    assert res.converged and res.newton.physical


def test_model_choice_per_element():
    mesh = af.box_beam(cells=(2, 2, 2))
    m = mesh.n_tets
    rng = np.random.default_rng(2)
    x = mesh.vertices + 2e-3 * rng.standard_normal(mesh.vertices.shape)
    per_model = {name: af.element_energy(af.Scene(mesh, af.Material(model=name)), x)
                 for name in af.physics.material.MODELS}
    names = np.where(np.arange(m) % 3 == 0, "neohookean", "stvk")
    mixed = af.element_energy(af.Scene(mesh, af.Material(model=list(names))), x)
    expected = np.where(names == "neohookean", per_model["neohookean"], per_model["stvk"])
    assert np.allclose(mixed, expected, rtol=1e-14, atol=0)
    assert not np.allclose(per_model["stvk"], per_model["neohookean"], rtol=1e-6, atol=0)
    with pytest.raises(ValueError, match="model: expected one of"):
        af.Material(model="mooney")
    with pytest.raises(ValueError, match="model: expected one name or 40"):
        af.Scene(mesh, af.Material(model=["stvk"] * 3))
    assert "model='neohookean'" in repr(af.Material(model="neohookean"))


def test_held_at_moves_only_the_held_components():
    scene = cantilever("stvk")
    target = scene.mesh.vertices + 0.001
    moved = scene.held_at(target)
    held = scene.fixed_mask
    assert np.array_equal(moved.fixed_positions[held], target[held])
    assert np.array_equal(moved.fixed_positions[~held], scene.fixed_positions[~held])
    assert moved.elements is scene.elements
    assert np.array_equal(scene.fixed_positions, scene.mesh.vertices)  # the original is kept
    with pytest.raises(ValueError, match="fixed_positions: expected shape"):
        scene.held_at(target[:5])
