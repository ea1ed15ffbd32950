"""Pressure on a cavity (anisofem.physics.pressure): its volume against the body's, its gradient and
Hessian against central finite differences on linear and quadratic tets, Lame's thick-walled
tube, the energy balance of a static pressure ramp, and the refusals."""
import numpy as np
import pytest

import anisofem as af
from anisofem.physics.inversion import volume_change
from anisofem.physics.meshgen import box_beam, tube
from anisofem.physics.potential import Potential

A, B = 0.01, 0.02       # the tube's radii, m
E, NU = 1e5, 0.3


def tube_scene(order, cells, pressure, length=0.005, fibers=0.0):
    """A quarter tube in plane strain (every vertex held along z, rollers on x = 0 and y = 0)
    with `pressure` Pa on its inner wall."""
    mesh = tube(A, B, length, cells, order=order)
    X = mesh.vertices
    fixed = np.zeros((mesh.n_vertices, 3), bool)
    fixed[np.abs(X[:, 0]) < 1e-12, 0] = True
    fixed[np.abs(X[:, 1]) < 1e-12, 1] = True
    fixed[:, 2] = True
    inner = mesh.faces_where(lambda c: np.hypot(c[:, 0], c[:, 1]) < (A + B) / 2)
    material = af.Material(E, NU, fiber_direction=(0.0, 0.0, 1.0), fiber_stiffness=fibers)
    return af.Scene(mesh, material, fixed=fixed, pressure=af.Pressure(inner, pressure))


def whole_surface_scene(order, pressure=1e3):
    """A box under pressure on its whole outer surface (a closed surface), its x-min end held."""
    mesh = box_beam((0.04, 0.02, 0.02), (4, 2, 2), order=order)
    x = mesh.vertices[:, 0]
    return af.Scene(mesh, af.Material(E, 0.45), fixed=np.flatnonzero(x < 1e-12),
                    pressure=af.Pressure(mesh.boundary_faces, pressure))


@pytest.mark.parametrize("order", [1, 2])
def test_enclosed_volume_of_a_closed_surface_is_the_body_volume(order):
    """Over a body's whole surface the cavity volume is minus the body's, at a deformed state
    with curved quadratic faces too: the triangle rule is exact."""
    scene = whole_surface_scene(order)
    rng = np.random.default_rng(1)
    x = scene.mesh.vertices + 1e-3 * rng.standard_normal(scene.mesh.vertices.shape)
    body = float(np.sum(scene.mesh.rest_volumes * (1.0 + _mean_volume_change(scene.mesh, x))))
    assert scene.pressures[0].volume(x) == pytest.approx(-body, rel=1e-12)


def _mean_volume_change(mesh, x):
    """(m,) each tet's deformed volume over its rest volume, minus 1: the mean of det F - 1
    over the element's quadrature rule (exact: det F is cubic and the tet10 rule has degree 5)."""
    if mesh.order == 1:
        return volume_change(mesh, x)
    F = np.einsum("eak,epaj->epkj", x[mesh.cells], mesh.point_gradients)
    return np.einsum("p,ep->e", mesh.element.weights / mesh.element.weights.sum(),
                     np.linalg.det(F)) - 1.0


@pytest.mark.parametrize("order", [1, 2])
@pytest.mark.parametrize("kind", ["tube", "closed"])
def test_gradient_and_hessian_against_finite_differences(order, kind):
    """The potential's gradient and Hessian with the pressure term, at a deformed state, against
    central differences (relative 1e-6), and the term's own parts alone."""
    scene = (tube_scene(order, (2, 4, 2), 5e3, fibers=1e5) if kind == "tube"
             else whole_surface_scene(order, 5e3))
    cavity = scene.pressures[0]
    rng = np.random.default_rng(2)
    x = scene.mesh.vertices + 5e-4 * rng.standard_normal(scene.mesh.vertices.shape)
    d = rng.standard_normal(x.shape)
    h = 1e-7  # m along d (unit entries): truncation 1e-8 relative, round-off far below
    potential = Potential(scene)
    _, g = potential.energy_gradient(x)
    slope = (potential.energy(x + h * d) - potential.energy(x - h * d)) / (2 * h)
    assert np.sum(g * d) == pytest.approx(slope, rel=1e-6)
    own = np.zeros_like(x)
    cavity.energy(x, own)
    assert np.sum(own * d) == pytest.approx(
        (cavity.energy(x + h * d) - cavity.energy(x - h * d)) / (2 * h), rel=1e-6)
    assert np.linalg.norm(own) > 1e-3 * np.linalg.norm(g)  # the term is not negligible
    H = af.hessian(scene, x)
    g_plus = potential.energy_gradient(x + h * d)[1]
    g_minus = potential.energy_gradient(x - h * d)[1]
    fd = ((g_plus - g_minus) / (2 * h)).ravel()
    assert np.linalg.norm(H @ d.ravel() - fd) <= 1e-6 * np.linalg.norm(fd)


@pytest.mark.parametrize("order, cells, tolerance", [(2, (4, 16, 1), 0.003),
                                                     (1, (8, 32, 1), 0.006)])
def test_lame_thick_walled_tube(order, cells, tolerance):
    """A quarter tube in plane strain under 100 Pa inside (strains ~2e-4): radial displacement
    within 1% of Lame's u(r) = (1 + nu) p a^2 / (E (b^2 - a^2)) ((1 - 2 nu) r + b^2 / r) at
    every node; measured 0.14% (quadratic, 320 tets) and 0.46% (linear, 1,280 tets)."""
    p = 100.0
    scene = tube_scene(order, cells, p)
    result = af.solve(scene)
    assert result.converged
    X = scene.mesh.vertices
    r = np.hypot(X[:, 0], X[:, 1])
    u = result.x - X
    radial = (u[:, 0] * X[:, 0] + u[:, 1] * X[:, 1]) / r
    lame = (1 + NU) * p * A ** 2 / (E * (B ** 2 - A ** 2)) * ((1 - 2 * NU) * r + B ** 2 / r)
    assert np.abs(radial - lame).max() <= tolerance * lame.max()


def test_static_ramp_stores_the_pressure_work():
    """Ramping the pressure to 5 kPa (the inner radius grows 1%, geometrically nonlinear) in
    static steps: the elastic energy at the end equals the work int p dV (trapezoid over 20
    steps) within 1%, and the volume grows with the pressure."""
    scene = tube_scene(2, (2, 8, 1), 5e3, fibers=2e5)
    shares = np.linspace(0.0, 1.0, 21)
    volumes, x = [], scene.initial_positions()
    for share in shares:
        result = af.solve(scene.loaded(share), x0=x)
        assert result.converged
        x = result.x
        volumes.append(scene.pressures[0].volume(x))
    volumes = np.array(volumes)
    assert (np.diff(volumes) > 0).all()
    work = np.trapezoid(shares * scene.pressures[0].magnitude, volumes)
    terms = Potential(scene).terms(x)
    assert terms["isotropic"] + terms["fiber"] == pytest.approx(work, rel=0.01)
    assert terms["pressure"] == pytest.approx(-5e3 * (volumes[-1] - volumes[0]), rel=1e-12)


def test_backward_euler_under_pressure_settles_without_gaining_energy():
    """A suddenly applied pressure in backward Euler: the tube swings out and settles at the
    static answer; its mechanical energy (elastic + pressure + kinetic) never rises."""
    scene = tube_scene(1, (2, 8, 1), 2e3)
    rollout = af.simulate(scene, steps=60, dt=0.002)
    static = af.solve(scene).x
    potential = Potential(scene)
    energy = []
    for x, v in zip(rollout.positions, rollout.velocities):
        kinetic = 0.5 * float(np.sum(scene.masses[:, None] * v ** 2))
        energy.append(potential.energy(x) + kinetic)
    assert np.all(np.diff(energy) <= 1e-12 * max(abs(e) for e in energy))
    assert np.abs(rollout.positions[-1] - static).max() < 0.05 * np.abs(static - scene.mesh.vertices).max()


def test_pressure_refusals():
    mesh = tube(A, B, 0.005, (2, 4, 1))
    inner = mesh.faces_where(lambda c: np.hypot(c[:, 0], c[:, 1]) < (A + B) / 2)
    with pytest.raises(ValueError, match="rim vertex .* is free"):
        af.Scene(mesh, fixed=[0], pressure=af.Pressure(inner, 1.0))
    faces = np.sort(mesh.tets[:, [[1, 2, 3], [0, 2, 3], [0, 1, 3], [0, 1, 2]]].reshape(-1, 3),
                    axis=1)
    unique, counts = np.unique(faces, axis=0, return_counts=True)
    inside = unique[counts == 2][:1]      # a face two tets share: inside the body
    with pytest.raises(ValueError, match="not a boundary face"):
        af.Scene(mesh, pressure=af.Pressure(inside, 1.0))
    with pytest.raises(ValueError, match="pressure magnitude: must be finite"):
        af.Pressure(inner, float("nan"))
    with pytest.raises(ValueError, match="pressure faces: expected shape"):
        af.Pressure(inner[:, :2], 1.0)
    with pytest.raises(TypeError, match="pressure: expected anisofem.Pressure"):
        af.Scene(mesh, pressure=[(inner, 1.0)])
    with pytest.raises(ValueError, match="given twice"):
        af.Scene(mesh, fixed=np.arange(mesh.n_vertices),
                 pressure=af.Pressure(np.vstack([inner, inner[:1]]), 1.0))


@pytest.mark.parametrize("order", [1, 2])
def test_reduced_model_keeps_the_pressure_exact(order):
    """A reduced model of a pressurized scene: its polynomial equals the full potential's
    elastic and pressure energy at x0 + U q, with the projected gradient and Hessian, to
    round-off; its static answer is the full FEM's within what the basis allows."""
    from anisofem.reduced import ReducedModel
    scene = tube_scene(order, (2, 6, 1), 3e3, fibers=1e5)
    model = ReducedModel(scene, modes=4)
    q = 1e-4 * np.random.default_rng(0).standard_normal(model.r)
    x = model.positions(q)
    potential = Potential(scene)
    terms = potential.terms(x)
    assert model.energy(q) == pytest.approx(terms["isotropic"] + terms["fiber"]
                                            + terms["pressure"], rel=1e-12)
    full_gradient = potential.energy_gradient(x)[1].ravel() + scene.external_force.ravel()
    g, H = model.force(q, hessian=True)
    assert np.linalg.norm(g - model.basis.T @ full_gradient) <= 1e-12 * np.linalg.norm(g)
    full_hessian = model.basis.T @ (af.hessian(scene, x) @ model.basis)
    assert np.abs(H - full_hessian).max() <= 1e-10 * np.abs(full_hessian).max()
    assert model.validation.converged and model.validation.tip_error < 0.05


def test_trade_on_a_pressure_scene():
    """The trade runs its FEM and reduced rungs on a pressure scene and says why the networks
    are left out."""
    scene = tube_scene(1, (2, 4, 1), 1e3)
    result = af.trade(scene, steps=4, dt=0.01, progress=False,
                      rungs=af.studies.rungs.fem_rungs()[:1] + [af.studies.rungs.reduced_rung(4)])
    assert [r["name"] for r in result["rungs"]][1:] == ["reduced m4"]
    notes = []
    kept = af.studies.rungs.representable([af.studies.rungs.Rung("net", "surrogate", None)],
                                          scene, notes)
    assert kept == [] and notes == ["surrogate rungs not run: the surrogates take nodal "
                                    "forces, not pressure"]
