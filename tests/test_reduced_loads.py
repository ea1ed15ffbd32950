"""Reduced models fitted to declared loads (anisofem.reduced.loads, .snapshots): the
declaration's defaults and checks, the load cases drawn from it, the principal directions, and
a fitted basis that follows the 0.2 m cantilever's large bending on unseen loads where the
modal basis does not."""
import math

import numpy as np
import pytest

import anisofem as af
from anisofem.studies import rungs as ladder_rungs
from anisofem.physics import meshgen
from anisofem.reduced import Carry, Drag, Loads, ReducedModel, default_loads
from anisofem.reduced import loads as loads_module
from anisofem.reduced.snapshots import principal_directions
from test_reduced import cantilever, random_q


@pytest.fixture(scope="module")
def long_beam():
    """The 0.2 m cantilever on 200 tets: it sags about 80% of its length."""
    return cantilever(length=0.2)


@pytest.fixture(scope="module")
def tee():
    mesh = meshgen.t_shape()
    return af.Scene(mesh, af.Material(1e5, 0.48, 1000.0),
                    fixed=af.metrics.end_vertices(mesh, 2, "min"), gravity=(0, 0, -9.81))


def test_free_ends_are_the_tip_face_and_the_arms_of_a_tee(long_beam, tee):
    (end,) = loads_module.free_ends(long_beam)
    assert set(end) == set(af.metrics.end_vertices(long_beam.mesh, 0, "max"))
    ends = loads_module.free_ends(tee)
    assert len(ends) == 2 and not set(ends[0]) & set(ends[1])
    x = tee.mesh.vertices
    sides = sorted(np.sign(x[e, 0].mean()) for e in ends)
    assert sides == [-1, 1]
    for e in ends:  # each arm's end, the farthest vertices from the stem's foot
        assert abs(x[e, 0]).min() > 0.7 * abs(x[:, 0]).max()


def test_default_loads_drag_half_the_weight_at_each_free_end(tee):
    loads = default_loads(tee)
    weight = tee.masses.sum() * 9.81
    assert len(loads.drags) == 2 and loads.cone == 0
    for d in loads.drags:
        assert d.magnitude == pytest.approx(loads_module.DRAG_SHARE * weight)
        assert d.directions is None


def test_drag_force_spreads_the_magnitude_by_mass(long_beam):
    end = af.metrics.end_vertices(long_beam.mesh, 0, "max")
    drag = Drag(end, 0.3, directions=[(0, 3.0, 4.0)])
    assert drag.directions == ((0.0, 0.6, 0.8),)
    f = drag.force(long_beam, drag.directions[0])
    assert np.allclose(f.sum(axis=0), [0, 0.18, 0.24])
    m = long_beam.masses[end]
    assert np.allclose(f[end, 2], 0.24 * m / m.sum())
    assert not f[np.setdiff1d(np.arange(len(f)), end)].any()


def test_gravity_change_turns_the_weight(long_beam):
    g = long_beam.gravity
    assert not loads_module.gravity_change(long_beam, g / np.linalg.norm(g)).any()
    sideways = np.array([0.0, 1.0, 0.0])
    total = long_beam.external_force + loads_module.gravity_change(long_beam, sideways)
    assert np.allclose(total.sum(axis=0), [0, long_beam.masses.sum() * 9.81, 0])


def test_build_cases_cover_every_direction_share_and_the_cone(long_beam):
    end = af.metrics.end_vertices(long_beam.mesh, 0, "max")
    loads = Loads((Drag(end, 0.5), Drag(end, 0.2, directions=[(0, 1, 0)])), cone=30)
    chains = loads_module.build_cases(long_beam, loads)
    cone = 2 * loads_module.CONE_DIRECTIONS
    assert len(chains) == len(loads_module.ANY_DIRECTION) + 1 + cone
    assert all(len(c) == len(loads_module.SHARES) for c in chains[:-cone])
    last, controls = chains[len(loads_module.ANY_DIRECTION)][-1]
    assert np.allclose(last.sum(axis=0), [0, 0.2, 0]) and controls == {}
    weight = long_beam.masses.sum() * 9.81
    for ((f, _),) in chains[-cone:]:  # gravity turned by 30 or 15 degrees
        total = (long_beam.external_force + f).sum(axis=0)
        angle = math.degrees(math.acos(-total[2] / np.linalg.norm(total)))
        assert np.linalg.norm(total) == pytest.approx(weight)
        assert min(abs(angle - 30), abs(angle - 15)) < 1e-6


def test_unseen_cases_stay_within_the_declaration_and_repeat(long_beam):
    end = af.metrics.end_vertices(long_beam.mesh, 0, "max")
    loads = Loads((Drag(end, 0.5),), cone=20)
    cases = loads_module.unseen_cases(long_beam, loads, 20, seed=3)
    again = loads_module.unseen_cases(long_beam, loads, 20, seed=3)
    assert all(np.array_equal(a[1], b[1]) for a, b in zip(cases, again))
    others = np.setdiff1d(np.arange(long_beam.mesh.n_vertices), end)
    m = long_beam.masses
    for which, f, carry, controls in cases:
        assert which == 0 and carry is None and controls == {}
        turn = f[others].sum(axis=0) / m[others].sum()  # gravity's change, m/s^2
        g = long_beam.gravity + turn
        pull = f[end].sum(axis=0) - m[end].sum() * turn
        assert 0.3 * 0.5 - 1e-9 <= np.linalg.norm(pull) <= 0.5 + 1e-9
        assert np.linalg.norm(g) == pytest.approx(9.81)
        assert math.degrees(math.acos(-g[2] / 9.81)) <= 20 + 1e-9


def test_principal_directions_weigh_each_snapshot_alike():
    rng = np.random.default_rng(0)
    mass = rng.uniform(1, 2, 30)
    a, b, c = np.eye(30)[:3]
    snaps = np.column_stack([1e4 * a, b, a + b, 1e-3 * c])
    U = principal_directions(snaps, mass, 3)
    assert U.shape == (30, 3)
    assert np.allclose(U.T @ (mass[:, None] * U), np.eye(3), atol=1e-12)
    for v in (a, b, c):  # the tiny snapshot along c is kept: every snapshot has unit norm
        assert np.linalg.norm(v - U @ (U.T @ (mass * v))) < 1e-9
    against = (a / math.sqrt(mass[0]))[:, None]
    W = principal_directions(snaps, mass, 3, against=against)
    assert W.shape[1] == 2 and np.abs(against.T @ (mass[:, None] * W)).max() < 1e-12


def test_fitted_basis_follows_large_bending_on_unseen_loads(long_beam):
    loads = default_loads(long_beam)
    fitted = ReducedModel(long_beam, modes=4, snapshots=16)
    modal = ReducedModel(long_beam, modes=6, loads=loads)
    assert fitted.loads == loads and fitted.r == 20
    chains = loads_module.build_cases(long_beam, loads)
    assert fitted.snapshots.kept == 1 + len(chains) * len(loads_module.SHARES)
    U = fitted.basis[long_beam.free_dofs]
    mass = np.repeat(long_beam.masses, 3)[long_beam.free_dofs]
    assert np.allclose(U.T @ (mass[:, None] * U), np.eye(fitted.r), atol=1e-9)
    for m in (fitted, modal):
        v = m.validation
        assert v.cases == 3 and v.converged and v.inverted == 0
    # measured: 0.0058 fitted (r = 20), 0.045 modal (r = 27)
    assert fitted.validation.tip_error < 0.015
    assert modal.validation.tip_error > 3 * fitted.validation.tip_error


def test_fitted_model_derivatives_match_finite_differences(long_beam):
    model = ReducedModel(long_beam, modes=2, snapshots=6, validate=False)
    rng = np.random.default_rng(1)
    q = random_q(model, rng)
    g, H = model.force(q, hessian=True)
    p = random_q(model, rng)
    for h in (1e-3, 1e-4):
        fd = (model.energy(q + h * p) - model.energy(q - h * p)) / (2 * h)
        assert fd == pytest.approx(g @ p, rel=1e-6)
    h = 1e-4
    fd = (model.force(q + h * p) - model.force(q - h * p)) / (2 * h)
    assert np.allclose(fd, H @ p, rtol=1e-6, atol=1e-9 * np.abs(H).max())


def test_the_trade_lists_the_fitted_rungs():
    names = [r.name for r in ladder_rungs.fem_rungs()]
    assert "reduced m4 s16" in names and "reduced m8 s20" in names


@pytest.mark.parametrize("make, message", [
    (lambda end: Drag(end, float("nan")), "magnitude"),
    (lambda end: Drag(end, -1.0), "magnitude"),
    (lambda end: Drag([], 1.0), "vertices"),
    (lambda end: Drag(end, 1.0, directions=[(0, 0, 0)]), "directions"),
    (lambda end: Drag(end, 1.0, directions=[(1, 0)]), "directions"),
    (lambda end: Drag(end, 1.0, directions=[(np.nan, 0, 1)]), "directions"),
    (lambda end: Loads(cone=-1), "cone"),
    (lambda end: Loads(cone=181), "cone"),
    (lambda end: Loads(cone=float("nan")), "cone"),
    (lambda end: Loads(drags=("tip",)), "drags"),
    (lambda end: Carry(turn=-1), "turn"),
    (lambda end: Carry(turn=190), "turn"),
    (lambda end: Carry(move=float("nan")), "move"),
    (lambda end: Carry(move=-0.1), "move"),
    (lambda end: Carry(seconds=0.0), "seconds"),
    (lambda end: Loads(carry=(30, 0.1)), "carry"),
])
def test_bad_declarations_are_refused(long_beam, make, message):
    end = af.metrics.end_vertices(long_beam.mesh, 0, "max")
    with pytest.raises((ValueError, TypeError), match=message):
        make(end)


def test_declarations_the_scene_cannot_take_are_refused(long_beam):
    n = long_beam.mesh.n_vertices
    held = af.metrics.end_vertices(long_beam.mesh, 0, "min")
    with pytest.raises(ValueError, match=r"drags\[0\].vertices: 1 indices outside"):
        ReducedModel(long_beam, modes=2, snapshots=2, loads=Loads((Drag([0, n], 1.0),)))
    with pytest.raises(ValueError, match="held fixed"):
        ReducedModel(long_beam, modes=2, snapshots=2, loads=Loads((Drag(held, 1.0),)))
    flat = af.Scene(long_beam.mesh, long_beam.material, fixed=held)
    with pytest.raises(ValueError, match="no gravity"):
        ReducedModel(flat, modes=2, snapshots=2, loads=Loads(cone=10))
    with pytest.raises(TypeError, match="loads"):
        ReducedModel(long_beam, modes=2, snapshots=2, loads="tip")
    with pytest.raises(ValueError, match="carry: the linear reduced model holds"):
        ReducedModel(long_beam, modes=2, snapshots=2, loads=Loads(carry=Carry(turn=30)))
    with pytest.raises(ValueError, match="snapshots"):
        ReducedModel(long_beam, modes=2, snapshots=-1)


def test_a_carry_adds_its_inertia_to_the_build_and_draws_carries_within_it(long_beam):
    """Build: the cone widened to the turn (8 gravity cases), the move's inertia along the 14
    directions and the turn's about 6 axes, each in 3 shares; unseen cases: from rest, smooth,
    then held at a turn and a move of the held vertices within the declaration."""
    carry = Carry(turn=40, move=0.05, seconds=0.4)
    chains = loads_module.build_cases(long_beam, Loads(carry=carry))
    assert len(chains) == 8 + 14 + 6 and all(len(c) == 3 for c in chains[:20])
    peak = math.pi ** 2 / (2 * 0.4 ** 2)
    move, _ = chains[0][-1]
    assert move.sum(axis=0) == pytest.approx(long_beam.masses.sum() * 0.05 * peak
                                             * np.array(loads_module.ANY_DIRECTION[0]))
    held = long_beam.fixed_mask.any(axis=1)
    h = long_beam.mesh.vertices[held].mean(axis=0)
    for _, _, base, _ in loads_module.unseen_cases(long_beam, Loads(carry=carry), 10, seed=2):
        assert np.allclose(base(0.0), np.eye(3, 4))
        for t in (0.1, 0.4, 1.0):
            R, c = base(t)[:, :3], base(t)[:, 3]
            assert np.allclose(R @ R.T, np.eye(3)) and np.linalg.det(R) > 0
            angle = math.degrees(math.acos(np.clip((np.trace(R) - 1) / 2, -1, 1)))
            assert angle <= 40 + 1e-9 and np.linalg.norm(R @ h + c - h) <= 0.05 + 1e-12
        assert np.allclose(base(0.4), base(1.0))
        assert angle >= 0.3 * 40 - 1e-9


def test_a_build_whose_loads_fold_the_body_says_so(long_beam):
    """A drag pushing the tip back along the beam at 20 times its weight turns StVK elements
    inside out in the snapshots: they are left out and the build warns, naming how many."""
    end = af.metrics.end_vertices(long_beam.mesh, 0, "max")
    weight = long_beam.masses.sum() * 9.81
    folding = Loads(drags=(Drag(end, 20 * weight, directions=[(-1, 0, 0)]),))
    with pytest.warns(af.InversionWarning, match=r"of the 4 static snapshots, 3 turned "
                      r"elements inside out .* stand on 1\."):
        model = ReducedModel(long_beam, modes=4, snapshots=4, loads=folding, validate=False)
    assert (model.snapshots.kept, model.snapshots.inverted) == (1, 3)
