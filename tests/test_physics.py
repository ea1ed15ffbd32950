"""Physics against closed forms and limits: uniaxial rods, symmetric cantilevers, mesh
refinement, dynamics settling to statics."""
import warnings

import meshio
import numpy as np
import pytest
from conftest import mirror_partner

import anisofem as af
from anisofem.physics import metrics
from anisofem.studies import uniaxial
from anisofem.physics.inversion import volume_change

E = 1e5


@pytest.mark.parametrize("direction,kappa", [
    ((1, 0, 0), 5 * E),                      # strong fibers along the load
    ((1, 0, 0), E / 5),                      # weak fibers along the load
    ((0, 1, 0), E / 5),                      # fibers across the load
    ((0, 0, 1), 5 * E),
    ((np.sqrt(0.5), np.sqrt(0.5), 0), E),    # 45 degrees: shear couples in
])
@pytest.mark.parametrize("stress", [2e4, -2e3])  # -2 kPa stays below Euler buckling
def test_uniaxial_bar_matches_homogeneous_solution(direction, kappa, stress):
    mat = af.Material(E, 0.48, 1000.0, direction, kappa)
    mesh = af.box_beam(cells=(6, 2, 2))
    exact = uniaxial.uniaxial_analytic(stress, E, 0.48, direction, kappa)
    result = af.solve(uniaxial.uniaxial_bar_scene(mesh, mat, stress), rtol=1e-10)
    assert result.converged
    A = mesh.vertices.min(axis=0)
    expected = A + (mesh.vertices - A) @ exact.F.T
    u = expected - mesh.vertices
    assert np.abs(result.x - expected).max() <= 1e-6 * np.abs(u).max()


def test_uniaxial_closed_form_limits():
    # small-strain slope: E without fibers; with nu = 0 the directions decouple, so fibers
    # across the load change nothing and fibers along it add 8 kappa
    for nu, kappa, d, modulus in [(0.3, 0.0, (1, 0, 0), E), (0.0, E, (0, 1, 0), E),
                                  (0.0, E, (1, 0, 0), 9 * E)]:
        st = uniaxial.uniaxial_analytic(1.0, E, nu, d, kappa)
        assert abs((st.stretch - 1) * modulus - 1.0) < 1e-4


def test_uniaxial_curve_follows_closed_form():
    mat = af.Material(E, 0.48, 1000.0, (1, 0, 0), 5 * E)
    stresses = np.linspace(0, 5e4, 6)
    stretch, _ = uniaxial.uniaxial_curve(mat, stresses, af.box_beam(cells=(4, 2, 2)), rtol=1e-12)
    exact = [uniaxial.uniaxial_analytic(s, E, 0.48, (1, 0, 0), 5 * E).stretch for s in stresses]
    assert np.allclose(stretch, exact, rtol=1e-9)
    assert np.all(np.diff(stretch) > 0)


def test_symmetric_cantilever_bends_symmetrically(beam):
    result = af.solve(af.default_scene(beam))
    assert result.converged
    u = result.x - beam.vertices
    j = mirror_partner(beam.vertices, axis=1)
    scale = np.abs(u).max()
    # mirror across y = 0: u_x, u_z even, u_y odd
    assert np.abs(u[:, [0, 2]] - u[j][:, [0, 2]]).max() < 1e-9 * scale
    assert np.abs(u[:, 1] + u[j, 1]).max() < 1e-9 * scale
    tip = metrics.tip_displacement(beam, result.x)
    assert abs(tip[1]) < 1e-9 * scale
    assert tip[2] < -0.01  # it sags about 2 cm


def test_fibers_along_the_beam_stiffen_bending(beam):
    sag = {}
    for name, d in [("along", (1, 0, 0)), ("gravity", (0, 0, 1))]:
        scene = af.Scene(beam, af.Material.paper(d, E), fixed=metrics.end_vertices(beam, 0, "min"),
                         gravity=(0, 0, -9.81))
        sag[name] = -metrics.tip_displacement(beam, af.solve(scene).x)[2]
    iso = -metrics.tip_displacement(beam, af.solve(af.default_scene(beam)).x)[2]
    assert sag["along"] < 0.6 * iso
    assert sag["along"] < sag["gravity"] <= iso


def test_refinement_study_converges():
    """Tip sag under refinement: grows (linear tets lock at nu = 0.48) with shrinking
    increments; the finest (10^4 tets) converges to a relative residual of 1e-8."""
    sags = []
    for n in (1, 2, 4):
        mesh = af.box_beam(cells=(8 * n, 2 * n, 2 * n))
        result = af.solve(af.default_scene(mesh), rtol=1e-8)
        assert result.converged and result.residuals[-1] <= 1e-8
        sags.append(-metrics.tip_displacement(mesh, result.x)[2])
    print("tip sag (m) at 160, 1280, 10240 tets:", sags)
    assert mesh.n_tets == 10240
    assert sags[0] < sags[1] < sags[2]
    assert (sags[2] - sags[1]) < 0.6 * (sags[1] - sags[0])


def test_backward_euler_settles_to_static_solution():
    mesh = af.box_beam(cells=(5, 2, 2))
    scene = af.default_scene(mesh)
    static = af.solve(scene).x
    roll = af.simulate(scene, steps=300, dt=0.02)
    assert roll.converged and roll.positions.shape == (301, mesh.n_vertices, 3)
    u = static - mesh.vertices
    assert np.abs(roll.positions[-1] - static).max() < 1e-5 * np.abs(u).max()
    assert np.abs(roll.velocities[-1]).max() < 1e-5
    # it oscillated on the way (the first steps overshoot or lag the static sag)
    assert not np.allclose(roll.positions[5], static, atol=1e-3 * np.abs(u).max())


def test_volume_change_and_imbalanced_force_metrics(beam):
    scene = af.default_scene(beam)
    result = af.solve(scene)
    dv = volume_change(beam, result.x)
    assert dv.shape == (beam.n_tets,) and np.abs(dv).max() < 0.05  # nu = 0.48: nearly kept
    assert np.abs(volume_change(beam, 1.1 * beam.vertices) - 0.331).max() < 1e-12
    at_rest = metrics.imbalanced_force(scene, scene.initial_positions())
    solved = metrics.imbalanced_force(scene, result.x)
    weight = scene.masses.sum() * 9.81
    assert at_rest.max > 0.001 * weight
    assert solved.max < 1e-8 * weight
    split = metrics.energy_split(scene, result.x)
    # at equilibrium under dead load: elastic energy ~ half the external work (nonlinear: close)
    assert split["kinetic"] == 0.0 and split["fiber"] == 0.0
    assert 0.4 < split["isotropic"] / -split["external"] < 0.6


@pytest.mark.parametrize("g, inverted", [(9.81, False), (98.1, True), (981.0, True)])
def test_turned_inside_out_is_reported_not_hidden(beam, tmp_path, g, inverted):
    """The 200-tet cantilever (fibers along it, kappa = E) under 1, 10 and 100 g: StVK converges
    to equilibria with inverted elements under the larger loads; the result, the warning, the
    rollout and the written file say so."""
    scene = af.Scene(beam, af.Material(1e5, 0.48, 1000.0, (1, 0, 0), 1e5),
                     fixed=af.metrics.end_vertices(beam, 0, "min"), gravity=(0, 0, -g))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        res = af.solve(scene)
    warned = [w for w in caught if issubclass(w.category, af.InversionWarning)]
    J = af.inversion.volume_change(beam, res.x) + 1.0
    assert res.inversion.inverted == int((J <= 0).sum())
    assert res.inversion.min_volume_ratio == pytest.approx(J.min())
    assert res.physical == (not inverted) and bool(warned) == inverted
    if inverted:
        assert "not physical" in str(warned[0].message) and res.inversion.inverted >= 10
        af.write_mesh(tmp_path / "bent.vtu", beam, res.x, scene)
        cells = meshio.read(tmp_path / "bent.vtu").cell_data["inverted"][0]
        assert int(cells.sum()) == res.inversion.inverted
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        roll = af.simulate(scene, 3, x0=res.x)
    assert roll.physical == (not inverted)
