"""Fiber activation (Material's activation a: the fibers' rest stretch s = 1 - a): a bar free
to contract against the closed form of its homogeneous state, on both base laws and both
element orders; the derivatives at activated fibers against central finite differences, at
ordinary and extreme parameters; bad input; the models that take passive fibers only say so."""
import numpy as np
import pytest
from scipy.optimize import brentq

import anisofem as af
from anisofem.reduced import FramedModel
from test_derivatives import deformed, fd_gradient, fd_hessian, min_altitude, random_tet, rel_err

E, NU = 1e5, 0.45


def contracted_stretch(model, kappa, activation):
    """The stretch along the fibers of a body free to contract (no load, lateral faces free),
    its homogeneous state F = diag(l, t, t) minimizing psi: derived here, independently of
    the library. StVK: S22 = 0 gives E2 = -lam E1 / (2 (lam + mu)), and S11 = 0 then
    E1 = -4 kappa (1 - s^2) / (E + 8 kappa). Neo-Hookean: the two stationarity equations,
    l S11 = mu (l^2 - 1) + lam ln J + 4 kappa l^2 (l^2 - s^2) = 0 and t S22 = mu (t^2 - 1) +
    lam ln J = 0 (J = l t^2), solved to round-off by nested bisection."""
    mu, lam = E / (2 * (1 + NU)), E * NU / ((1 + NU) * (1 - 2 * NU))
    s2 = (1.0 - activation) ** 2
    if model == "stvk":
        return np.sqrt(1.0 + 2.0 * (-4.0 * kappa * (1.0 - s2) / (E + 8.0 * kappa)))

    def lateral(l):  # the lateral stretch where S22 = 0: mu (t^2 - 1) + lam ln(l t^2) = 0
        return brentq(lambda t: mu * (t * t - 1) + lam * np.log(l * t * t), 0.2, 5.0,
                      xtol=1e-16, rtol=1e-15)

    def s11(l):      # l S11 with the lateral stretch at its optimum
        ln_j = np.log(l * lateral(l) ** 2)
        return mu * (l * l - 1) + lam * ln_j + 4 * kappa * l * l * (l * l - s2)
    return brentq(s11, 0.3, 1.0, xtol=1e-16, rtol=1e-15)


def bar(order, model, kappa, activation):
    """A bar along x held only by its three symmetry planes (x, y, z = their minimum), fibers
    along it, activated."""
    mesh = af.box_beam(size=(0.1, 0.02, 0.02), cells=(4, 2, 2), order=order)
    X = mesh.vertices
    fixed = np.zeros((mesh.n_vertices, 3), bool)
    for axis in range(3):
        fixed[:, axis] = X[:, axis] < X[:, axis].min() + 1e-12
    material = af.Material(E, NU, 1000.0, (1, 0, 0), kappa, model=model, activation=activation)
    return af.Scene(mesh, material, fixed=fixed)


@pytest.mark.parametrize("order", [1, 2])
@pytest.mark.parametrize("model", ["stvk", "neohookean"])
def test_a_free_bar_contracts_to_the_closed_form(order, model):
    for kappa, activation in ((E, 0.1), (10 * E, 0.3), (100 * E, 0.5)):
        scene = bar(order, model, kappa, activation)
        result = af.solve(scene, rtol=1e-12)
        assert result.converged and result.physical
        X, x = scene.mesh.vertices, result.x
        far = X[:, 0] > X[:, 0].max() - 1e-12
        stretch = (x[far, 0] - X[:, 0].min()).mean() / np.ptp(X[:, 0])
        exact = contracted_stretch(model, kappa, activation)
        assert exact < 1 - 0.5 * activation * kappa / (kappa + E)   # it did contract
        assert abs(stretch - exact) <= 1e-8 * exact, (kappa, activation, stretch, exact)


def test_the_closed_form_is_the_minimizer_of_the_density():
    """The StVK formula against a one-dimensional search: psi minimized over the lateral
    stretch for each fiber stretch, then over the fiber stretch (brentq on the derivative)."""
    mu, lam = E / (2 * (1 + NU)), E * NU / ((1 + NU) * (1 - 2 * NU))
    kappa, activation = 10 * E, 0.3

    def slope(l):  # d psi / d l with the lateral stretch at its optimum (S22 = 0)
        e1 = (l * l - 1) / 2
        e2 = -lam * e1 / (2 * (lam + mu))
        return l * (lam * (e1 + 2 * e2) + 2 * mu * e1 + 4 * kappa * (l * l - (1 - activation) ** 2))
    searched = brentq(slope, 0.3, 1.0, xtol=1e-15)
    assert abs(searched - contracted_stretch("stvk", kappa, activation)) < 1e-12


@pytest.mark.parametrize("model", ["stvk", "neohookean"])
@pytest.mark.parametrize("kappa,activation", [(E, 0.2), (100 * E, 0.5), (10 * E, 0.9)])
def test_derivatives_of_activated_fibers_match_finite_differences(model, kappa, activation):
    rng = np.random.default_rng(int(kappa) + int(100 * activation))
    mesh = random_tet(rng)
    d = rng.standard_normal(3)
    scene = af.Scene(mesh, af.Material(E, 0.48, 1000.0, d / np.linalg.norm(d), kappa,
                                       model=model, activation=activation))
    for stretches in ((1.1, 0.9, 1.05), (0.6, 1.0, 1.2)):   # fibers longer and shorter than s
        x = deformed(rng, mesh, stretches)
        h = 1e-6 * min_altitude(mesh)
        assert rel_err(af.gradient(scene, x), fd_gradient(scene, x, h)) < 1e-6
        H = af.hessian(scene, x).toarray()
        assert rel_err(H, fd_hessian(scene, x, h)) < 1e-6
        projected = af.hessian(scene, x, project=True).toarray()
        assert np.linalg.eigvalsh(projected).min() > -1e-9 * np.abs(projected).max()


def test_activation_at_rest_pulls_and_its_energy_is_the_closed_form():
    """At rest (I4 = 1) an activated fiber holds energy kappa (1 - s^2)^2 per volume and pulls
    its element's ends together."""
    mesh = af.box_beam(size=(0.1, 0.02, 0.02), cells=(2, 1, 1))
    kappa, activation = E, 0.25
    scene = af.Scene(mesh, af.Material(E, NU, 1000.0, (1, 0, 0), kappa, activation=activation))
    volume = mesh.rest_volumes.sum()
    assert af.energy(scene, mesh.vertices) == pytest.approx(
        kappa * (1 - (1 - activation) ** 2) ** 2 * volume, rel=1e-12)
    g = af.gradient(scene, mesh.vertices)
    ends = mesh.vertices[:, 0] > 0.1 - 1e-12
    assert (g[ends, 0] > 0).all()   # the energy falls as the far end moves in (-x)


def test_bad_activation_is_one_clear_error():
    for value, message in ((1.0, r"activation: a share in \[0, 1\)"),
                           (-0.1, r"activation: a share in \[0, 1\)"),
                           (np.nan, "activation: must be finite")):
        with pytest.raises(ValueError, match=message):
            af.Material(fiber_stiffness=E, activation=value)
    with pytest.raises(ValueError, match="activation: 1 element is activated with no fibers"):
        af.Material(fiber_stiffness=[E, 0.0], activation=[0.0, 0.2])


def test_models_of_passive_fibers_refuse_an_activated_scene():
    """The framed model and the networks take passive fibers only, and say so; the trade
    leaves their rungs out with a note and runs the linear reduced model's."""
    scene = bar(1, "stvk", E, 0.2)
    scene = af.Scene(scene.mesh, scene.material, fixed=af.metrics.end_vertices(scene.mesh, 0,
                                                                               "min"))
    with pytest.raises(ValueError, match="the framed model takes passive fibers"):
        FramedModel(scene, validate=False)
    result = af.trade(scene, steps=10, progress=False)
    assert any("passive fibers" in note for note in result["notes"])
    kinds = {r["name"]: r["kind"] for r in result["rungs"]}
    assert "reduced m5" in kinds and not any(n.startswith("framed") for n in kinds)


def test_a_scene_file_activates_a_region(tmp_path):
    from test_scenefile import scene_file, two_halves
    two_halves(tmp_path)
    text = ('mesh = "bar.msh"\n[material]\nfiber = [1, 0, 0]\nfiber_stiffness = 1e5\n'
            '[regions.stiff]\nactivation = 0.2\n[[boundary]]\nwhere = "base"\nheld = true\n')
    scene = af.load_scene(scene_file(tmp_path, text))
    _, volumes = two_halves(tmp_path)
    assert np.array_equal(scene.elements.rest2 != 1.0, volumes == 2)
    assert np.allclose(scene.elements.rest2[volumes == 2], 0.64)


def active_bar(order, model, kappa, value):
    """bar()'s body with passive fibers and its whole activation a control "squeeze"."""
    scene = bar(order, model, kappa, 0.0)
    return af.Scene(scene.mesh, scene.material, fixed=scene.fixed_mask,
                    activation=af.Activation(np.arange(scene.mesh.n_tets), value, "squeeze"))


def test_activation_follows_a_load_curve():
    """An activation control on a load curve: Scene.at(t) sets it to curve(t) times the
    written value, and each state solves to the closed form at that activation; a curve that
    would take it to 1 or more is refused."""
    from anisofem.physics.curves import LoadCurve, Timed
    scene = active_bar(1, "neohookean", 10 * E, 0.4)
    ramp = LoadCurve([0.0, 1.0], [0.0, 1.0], name="ramp")
    timed = scene.following([Timed(ramp, control="squeeze")])
    for t in (0.0, 0.25, 1.0, 2.0):   # the curve holds its last value after its last point
        now = timed.at(t)
        a = 0.4 * min(t, 1.0)
        assert np.allclose(now.elements.rest2, (1 - a) ** 2)
        assert now.control_values.tolist() == [a]
        result = af.solve(now, rtol=1e-12)
        X, x = now.mesh.vertices, result.x
        far = X[:, 0] > X[:, 0].max() - 1e-12
        stretch = (x[far, 0] - X[:, 0].min()).mean() / np.ptp(X[:, 0])
        assert abs(stretch - contracted_stretch("neohookean", 10 * E, a)) <= 1e-8
    rollout = af.simulate(timed, 10, 0.1)
    assert rollout.converged
    tip = rollout.positions[:, :, 0].max(axis=1)
    assert tip[-1] < tip[1] < tip[0] + 1e-12   # the bar shortens as the activation ramps up
    with pytest.raises(ValueError, match=r"timed\[0\].control: the curve 'ramp' takes "
                                         r"activation 'squeeze' outside \[0, 1\)"):
        scene.following([Timed(LoadCurve([0.0, 1.0], [0.0, 3.0], name="ramp"),
                               control="squeeze")])


def test_a_scene_file_puts_a_regions_activation_on_a_curve(tmp_path):
    from test_scenefile import scene_file, two_halves
    _, volumes = two_halves(tmp_path)
    text = ('mesh = "bar.msh"\n[material]\nfiber = [1, 0, 0]\nfiber_stiffness = 1e5\n'
            '[controls.squeeze]\nactivation = "stiff"\nvalue = 0.3\ncurve = "pulse"\n'
            '[curves.pulse]\ntimes = [0, 1, 2]\nvalues = [0, 1, 0]\n'
            '[[boundary]]\nwhere = "base"\nheld = true\n')
    scene = af.load_scene(scene_file(tmp_path, text))
    assert scene.controls == ("squeeze",)
    assert np.allclose(scene.elements.rest2[volumes == 2], 0.49)   # statics: the factor 1
    for t, a in ((0.0, 0.0), (0.5, 0.15), (1.0, 0.3), (1.5, 0.15)):
        rest2 = scene.at(t).elements.rest2
        assert np.allclose(rest2[volumes == 2], (1 - a) ** 2) and (rest2[volumes == 1] == 1).all()
    for bad, good, message in (
            ('curve = "pulse"', 'curve = "nowhere"', "controls.squeeze.curve: no curve "
                                                     "'nowhere'"),
            ('activation = "stiff"', 'activation = "hard"', "controls.squeeze.activation: the "
                                                            "mesh has no physical volume 'hard'"),
            ("value = 0.3", "value = 1.2", r"controls.squeeze.value: control 'squeeze': an "
                                           r"activation must be in \[0, 1\)"),
            ('activation = "stiff"', 'activation = "stiff"\npressure = "end"',
             "controls.squeeze: give one of pressure"),
            ("fiber_stiffness = 1e5\n", "fiber_stiffness = 0\n",
             "controls: activation 'squeeze': 80 of its elements have no fibers")):
        with pytest.raises(ValueError, match=message):
            af.load_scene(scene_file(tmp_path, text.replace(bad, good), "bad.toml"))
