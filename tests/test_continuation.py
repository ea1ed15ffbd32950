"""Load continuation for statics: the load ramped in increments, each from the last equilibrium,
used where the whole load fails and on request, and its bad input."""
import numpy as np
import pytest

import anisofem as af
from anisofem.solvers import continuation


@pytest.fixture(scope="module")
def cantilever():
    mesh = af.box_beam(size=(0.1, 0.02, 0.02), cells=(10, 2, 2))
    angle = np.radians(40)
    material = af.Material(1e5, 0.48, 1000.0, (np.cos(angle), 0.0, np.sin(angle)), 1e5,
                           model="neohookean")
    return af.Scene(mesh, material, fixed=af.metrics.end_vertices(mesh, 0, "min"),
                    gravity=(0.0, 0.0, -9.81 * 5))


def test_a_share_of_the_load_scales_forces_and_prescribed_displacements():
    mesh = af.box_beam(cells=(4, 2, 2))
    held = af.metrics.end_vertices(mesh, 0, "min")
    target = mesh.vertices.copy()
    target[held] += [0.0, 0.004, -0.002]
    scene = af.Scene(mesh, fixed=held, fixed_positions=target[held], gravity=(0, 0, -9.81),
                     nodal_force=np.full((mesh.n_vertices, 3), 0.01))
    part = scene.loaded(0.25)
    assert np.allclose(part.external_force, 0.25 * scene.external_force)
    moved = part.fixed_positions - mesh.vertices
    assert np.allclose(moved[held], [0.0, 0.001, -0.0005])
    assert not moved[~scene.fixed_mask.all(1)].any()
    assert np.array_equal(scene.loaded(1.0).external_force, scene.external_force)


def test_ramped_answer_is_the_direct_one(cantilever):
    direct = af.solve(cantilever, continuation="never")
    ramped = af.solve(cantilever, continuation="always")
    assert direct.converged and ramped.converged
    assert direct.increments == 0 and ramped.increments >= 2
    scale = np.abs(direct.x - cantilever.mesh.vertices).max()
    assert np.abs(ramped.x - direct.x).max() <= 1e-6 * scale
    assert ramped.stability.minimum


def test_a_whole_load_out_of_reach_is_finished_by_increments(cantilever):
    """max_iter 6 is too few for the whole load from rest (it takes more), enough per
    increment: the automatic continuation reaches the same answer and says so."""
    with pytest.warns(af.ConvergenceWarning):
        alone = af.solve(cantilever, max_iter=6, continuation="never")
    assert alone.failed
    ramped = af.solve(cantilever, max_iter=6)
    assert ramped.converged and ramped.increments >= 2 and ramped.message == "converged"
    assert ramped.iterations > 6  # the failed attempt and every increment, counted
    exact = af.solve(cantilever)
    scale = np.abs(exact.x - cantilever.mesh.vertices).max()
    assert np.abs(ramped.x - exact.x).max() <= 1e-6 * scale


def test_a_step_out_of_reach_is_the_same_step_by_increments(cantilever):
    """A 1 s step from rest needs more than 6 iterations; with max_iter 6 the step ramps its
    external force and lands on the step that unlimited Newton takes."""
    x = cantilever.mesh.vertices
    v = np.zeros_like(x)
    exact = af.step(cantilever, x, v, 1.0)
    assert exact.converged and exact.newton.increments == 0 and exact.newton.iterations > 6
    ramped = af.step(cantilever, x, v, 1.0, max_iter=6)
    assert ramped.converged and ramped.newton.increments >= 2
    assert ramped.newton.iterations > 6  # the failed attempt, counted
    scale = np.abs(exact.x - x).max()
    assert np.abs(ramped.x - exact.x).max() <= 1e-6 * scale


def test_a_continuation_that_cannot_go_on_says_how_far_it_got(cantilever, monkeypatch):
    monkeypatch.setattr(continuation, "SMALLEST", 0.2)  # one halving allowed
    with pytest.warns(af.ConvergenceWarning, match="load continuation stopped at"):
        result = af.solve(cantilever, max_iter=1, continuation="always")
    assert result.failed and np.isfinite(result.x).all()


def test_prescribed_motion_is_ramped_too():
    mesh = af.box_beam(size=(0.1, 0.02, 0.02), cells=(8, 2, 2))
    ends = np.flatnonzero(np.isclose(mesh.vertices[:, 0], 0.0)
                          | np.isclose(mesh.vertices[:, 0], 0.1))
    target = mesh.vertices[ends].copy()
    far = target[:, 0] > 0.05
    target[far, 0] -= 0.03  # squeeze the beam by 30 %
    scene = af.Scene(mesh, af.Material(1e5, 0.45, 1000.0, model="neohookean"), fixed=ends,
                     fixed_positions=target)
    with pytest.raises(ValueError, match="x0: .* inside out"):
        af.solve(scene, continuation="never")  # from rest with the ends moved: inverted
    ramped = af.solve(scene)
    assert ramped.converged and ramped.increments >= 2 and ramped.stability.minimum
    assert np.allclose(ramped.x[ends], target)


@pytest.mark.parametrize("options, field", [
    ({"continuation": "sometimes"}, "continuation"),
    ({"continuation": "always", "iterations": 3}, "continuation"),
])
def test_bad_continuation_options_are_named(cantilever, options, field):
    with pytest.raises(ValueError, match=field):
        af.solve(cantilever, **options)
