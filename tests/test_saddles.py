"""Newton leaves saddles: the static solves that used to stop short of an equilibrium (soft
cantilevers whose compressed face meets a mesh-scale instability) reach a minimum, a column
past its buckling load leaves the straight state, and the stability verdict is the smallest
eigenvalue of the free Hessian."""
import warnings

import numpy as np
import pytest

import anisofem as af
from anisofem.studies import robustness
from anisofem.physics.potential import Potential
from anisofem.solvers.stability import stability

#: (length m, base, g): 20 x 4 x 4 cells, fibers along x, kappa = E; each ended "max_iter
#: reached" or "the line search stalled" with the projected-Hessian fallback alone
STOPPED_BEFORE = [(0.1, "stvk", 5), (0.1, "neohookean", 10), (0.1, "neohookean", 20),
                  (0.2, "stvk", 2), (0.2, "stvk", 5), (0.2, "neohookean", 5),
                  (0.2, "neohookean", 10)]


@pytest.mark.parametrize("length, base, g", STOPPED_BEFORE)
def test_soft_cantilevers_reach_a_minimum(length, base, g):
    scene = robustness.scene(length, (20, 4, 4), "x", base, g)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", af.InversionWarning)  # StVK may invert: it says so
        result = af.solve(scene)
    assert result.converged, result.message
    assert result.stability.minimum, result.stability
    assert result.physical or base == "stvk"


@pytest.mark.parametrize("length", [0.1, 0.2])
@pytest.mark.parametrize("dt", [0.02, 0.2, 1.0])
def test_neohookean_rollouts_at_10_g_take_every_step(length, dt):
    """Each of these six rollouts stopped at its second step, "max_iter reached"."""
    rollout = af.simulate(robustness.scene(length, (20, 4, 4), "x", "neohookean", 10), 10, dt)
    assert rollout.converged and rollout.physical


def test_a_crawl_to_a_saddle_is_cut_short():
    """The projected steps converged to a saddle at 0.81 per iteration and spent max_iter on
    it; after ten of them in a row Newton looks for negative curvature and leaves."""
    scene = robustness.scene(0.05, (10, 2, 2), "40 deg", "stvk", 30)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", af.InversionWarning)  # StVK at 30 g: a few invert
        result = af.solve(scene, continuation="never")
    assert result.converged and result.stability.minimum
    assert result.iterations <= 50


def test_steps_converging_below_the_energy_noise_finish():
    """Each step's last iterations lowered G by less than 1e-13 of |G| while the gradient fell
    to 0.74 per iteration; the line search used to wait for it to halve and stalled at step 1."""
    scene = robustness.scene(0.05, (10, 2, 2), "x", "neohookean", 100)
    rollout = af.simulate(scene, 10, dt=0.02)
    assert rollout.converged and rollout.physical


def column(force):
    """A 0.1 m Neo-Hookean column held at x = 0 under a dead compressive force (N) on its
    free end, past the buckling load from about 1 N on this mesh."""
    mesh = af.box_beam(size=(0.1, 0.02, 0.02), cells=(10, 2, 2))
    tip = af.metrics.end_vertices(mesh, 0, "max")
    f = np.zeros((mesh.n_vertices, 3))
    f[tip, 0] = -force / tip.size
    return af.Scene(mesh, af.Material(model="neohookean"),
                    fixed=af.metrics.end_vertices(mesh, 0, "min"), nodal_force=f)


def test_a_buckled_column_leaves_the_straight_saddle_that_projection_alone_stops_at():
    scene = column(1.0)
    straight = af.solve(scene, projection="always")
    assert straight.converged and not straight.stability.minimum
    assert straight.stability.smallest < 0
    assert np.abs(af.metrics.tip_displacement(scene.mesh, straight.x)[1:]).max() < 1e-9
    buckled = af.solve(scene)
    assert buckled.converged and buckled.stability.minimum and buckled.physical
    assert buckled.energy < straight.energy
    assert np.abs(af.metrics.tip_displacement(scene.mesh, buckled.x)[1:]).max() > 1e-3
    below = af.solve(column(0.5))  # under the buckling load the straight state is the minimum
    assert below.stability.minimum and below.iterations <= 5


@pytest.mark.parametrize("state", ["rest", "bent", "crushed"])
def test_lanczos_smallest_eigenvalue_is_the_dense_one(state):
    mesh = af.box_beam(cells=(4, 2, 2))
    scene = af.Scene(mesh, af.Material(1e5, 0.48, 1000.0, (0.6, 0.0, 0.8), 5e5),
                     fixed=af.metrics.end_vertices(mesh, 0, "min"), gravity=(0, 0, -9.81))
    x = {"rest": mesh.vertices, "bent": af.solve(scene).x,
         "crushed": mesh.vertices * np.array([0.7, 1.0, 1.0])}[state]
    got = stability(Potential(scene), x)
    free = scene.free_dofs
    dense = af.hessian(scene, x).toarray()[np.ix_(free, free)]
    values = np.linalg.eigvalsh(dense)
    assert got.smallest == pytest.approx(values[0], rel=1e-6, abs=1e-9 * values[-1])
    assert got.minimum == (values[0] >= -1e-9 * dense.diagonal().max())
    assert abs(got.vector @ dense @ got.vector - values[0]) <= 1e-6 * values[-1]


def test_robustness_report_counts_minima_and_lists_the_rest(capsys):
    rows = [robustness.static_row(0.1, (4, 2, 2), "x", "neohookean", 1)]
    assert rows[0]["converged"] and rows[0]["minimum"] and rows[0]["inverted"] == 0
    stuck = dict(rows[0], converged=False, minimum=False, message="max_iter reached",
                 smallest_eigenvalue=-3.0, g=100)
    dyn = robustness.dynamic_row(0.1, (4, 2, 2), "x", "stvk", 10, 0.2)
    assert dyn["converged"] and dyn["steps"] == robustness.STEPS
    robustness.print_report({"statics": rows + [stuck], "dynamics": [dyn]})
    said = capsys.readouterr().out
    assert "not a minimum: 0.1 m 4x2x2 fiber x neohookean 100 g: max_iter reached" in said
    assert "stvk          10 g  dt 0.2   |   1 of 1" in said and "   1/1 " in said


def test_a_lanczos_that_does_not_converge_says_unknown_not_minimum(monkeypatch):
    scene = robustness.scene(0.1, (20, 4, 4), "x", "stvk", 5)
    x = af.solve(scene, projection="always", max_iter=20, continuation="never", warn=False).x
    monkeypatch.setattr("anisofem.solvers.stability.MAX_LANCZOS", 1)
    unknown = stability(Potential(scene), x)
    # the factorization already refused the Hessian: unknown eigenvalue, but not a minimum
    assert np.isnan(unknown.smallest) and not unknown.minimum and unknown.vector is None
    monkeypatch.undo()
    again = stability(Potential(scene), x)
    assert again.smallest < 0 and not again.minimum
