"""Adjoint derivatives of a static equilibrium (anisofem.inverse.sensitivity) against central finite
differences of full solves, for every parameter kind, both base laws and both element orders,
at ordinary and extreme parameters; and the refusals."""
import types

import numpy as np
import pytest

import anisofem as af
import anisofem.inverse.sensitivity  # noqa: F401
from anisofem.inverse.sensitivity import fiber_angles, fiber_direction, static_sensitivity

LENGTH = 0.06

#: (Young's modulus range, Pa; Poisson's ratio range; kappa range, Pa; activation range):
#: ordinary and extreme (near-incompressible, fibers 100x stiffer than the base and activated
#: by half)
REGIMES = {"ordinary": ((1e5, 1.3e5), (0.3, 0.4), (0.0, 2e5), (0.05, 0.2)),
           "extreme": ((1e5, 1.3e5), (0.495, 0.499), (5e6, 1e7), (0.45, 0.5))}
#: The extreme activation on the StVK base: fibers of rest stretch s this much stiffer than the
#: base pull the body to a stretch near s, and StVK in compression has its limit point at
#: 1/sqrt(3) = 0.58 (it softens past it, and elements invert): a = 0.5 has no unique answer
#: there, so StVK's extreme is 0.3 to 0.35
STVK_EXTREME_ACTIVATION = (0.3, 0.35)


def cantilever(order, law, E, nu, kappa, angles, activation=0.0):
    mesh = af.box_beam((LENGTH, 0.01, 0.01), (6, 2, 2), order=order)
    X = mesh.vertices
    return af.Scene(mesh, af.Material(E, nu, 1000.0, fiber_direction(angles), kappa, model=law,
                                      activation=activation),
                    fixed=np.flatnonzero(X[:, 0] < 1e-9), gravity=(0, 0, -9.81))


def tip_height(scene):
    """J(x) = the tip's mean z (m) and its gradient (n, 3)."""
    X = scene.mesh.vertices
    tip = np.flatnonzero(X[:, 0] > LENGTH - 1e-9)
    gradient = np.zeros_like(X)
    gradient[tip, 2] = 1.0 / tip.size
    return (lambda x: float(x[tip, 2].mean())), gradient


def solved(scene):
    result = af.solve(scene, rtol=1e-12, warn=False)
    assert result.converged
    return result


@pytest.mark.parametrize("regime", list(REGIMES))
@pytest.mark.parametrize("law", ["stvk", "neohookean"])
@pytest.mark.parametrize("order", [1, 2])
def test_static_derivatives_against_finite_differences(order, law, regime):
    """Each kind along a random direction of per-element changes: dJ/dp . delta against
    central differences (J(p + h delta) - J(p - h delta)) / 2h at h and h / 2, h stated per
    kind, Richardson-extrapolated, to 1e-6 relative."""
    (E_lo, E_hi), (nu_lo, nu_hi), (k_lo, k_hi), (a_lo, a_hi) = REGIMES[regime]
    if law == "stvk" and regime == "extreme":
        a_lo, a_hi = STVK_EXTREME_ACTIVATION
    m = af.box_beam((LENGTH, 0.01, 0.01), (6, 2, 2)).n_tets
    rng = np.random.default_rng(3)
    p = {"E": rng.uniform(E_lo, E_hi, m), "nu": rng.uniform(nu_lo, nu_hi, m),
         "kappa": rng.uniform(k_lo, k_hi, m), "activation": rng.uniform(a_lo, a_hi, m),
         "angles": np.stack([rng.uniform(-1, 1, m), rng.uniform(-0.7, 0.7, m)], axis=1)}

    def scene_with(**changed):
        return cantilever(order, law, **{"E": p["E"], "nu": p["nu"], "kappa": p["kappa"],
                                         "angles": p["angles"],
                                         "activation": p["activation"]} | changed)
    scene = scene_with()
    J, gradient = tip_height(scene)
    S = static_sensitivity(scene, solved(scene), gradient)
    kinds = {  # name: (changed parameters at step t, adjoint slope, step h)
        "young": (lambda t, d=rng.standard_normal(m) * p["E"]: {"E": p["E"] + t * d},
                  lambda d: S.young @ d, 1e-4),
        "poisson": (lambda t, d=rng.standard_normal(m) * 1e-3: {"nu": p["nu"] + t * d},
                    lambda d: S.poisson @ d, 1e-3),
        "kappa": (lambda t, d=rng.standard_normal(m) * 1e5: {"kappa": p["kappa"] + t * d},
                  lambda d: S.kappa @ d, 1e-4),
        "fiber_angles": (lambda t, d=rng.standard_normal((m, 2)): {"angles": p["angles"] + t * d},
                         lambda d: np.sum(S.fiber_angles * d), 1e-5),
        "activation": (lambda t, d=rng.standard_normal(m) * 1e-2:
                       {"activation": p["activation"] + t * d},
                       lambda d: S.activation @ d, 1e-3)}
    def central(change, h):
        return (J(solved(scene_with(**change(h))).x) - J(solved(scene_with(**change(-h))).x)) / (
            2 * h)
    for name, (change, slope, h) in kinds.items():
        d = change.__defaults__[0]
        # Richardson: the central differences at h and h / 2 combined cancel their h^2 error
        fd = (4 * central(change, h / 2) - central(change, h)) / 3
        assert slope(d) == pytest.approx(fd, rel=1e-6), name
        assert abs(fd) > 1e-12  # the objective moves with the parameter


@pytest.mark.parametrize("order", [1, 2])
def test_pressure_derivative(order):
    """d(the tube's inner wall radius)/dp against central differences of solves (h = 1 Pa)."""
    from test_pressure import tube_scene
    scene = tube_scene(order, (2, 6, 1), 2e3, fibers=1e5)
    X = scene.mesh.vertices
    inner = np.flatnonzero(np.abs(np.hypot(X[:, 0], X[:, 1]) - 0.01) < 1e-9)
    gradient = np.zeros_like(X)  # the wall moves radially: its rest radial direction
    gradient[inner, :2] = X[inner, :2] / 0.01 / inner.size

    def J(x):
        return float(np.mean(np.hypot(x[inner, 0], x[inner, 1])))
    S = static_sensitivity(scene, solved(scene), gradient)
    h = 1.0
    fd = (J(solved(scene.loaded(1 + h / 2e3)).x) - J(solved(scene.loaded(1 - h / 2e3)).x)) / (2 * h)
    assert S.pressure[0] == pytest.approx(fd, rel=1e-6)
    assert S.pressure[0] > 0


def test_refused_where_the_derivative_is_not_defined():
    """Not at a converged solve, and not at a saddle: a clamped column squeezed by 10% (past
    its buckling strain, about 3%), held straight by its centerline, is an equilibrium of
    the free column and a saddle."""
    mesh = af.box_beam((0.1, 0.01, 0.01), (10, 2, 2))
    X = mesh.vertices
    ends = np.flatnonzero((X[:, 0] < 1e-9) | (X[:, 0] > 0.1 - 1e-9))
    held = X[ends].copy()
    held[:, 0] *= 0.9
    scene = af.Scene(mesh, af.Material(1e5, 0.3), fixed=ends, fixed_positions=held)
    _, gradient = tip_height(af.default_scene(mesh))
    unconverged = af.solve(scene, max_iter=1, warn=False, continuation="never")
    with pytest.raises(ValueError, match="did not converge"):
        static_sensitivity(scene, unconverged, gradient)
    straight = np.zeros((mesh.n_vertices, 3), bool)  # the centerline held in y and z: by
    straight[ends] = True                             # the mesh's mirror symmetry, it pushes
    axis = (np.abs(X[:, 1]) < 1e-9) & (np.abs(X[:, 2]) < 1e-9)  # on nothing there
    straight[axis, 1:] = True
    column = af.Scene(mesh, af.Material(1e5, 0.3), fixed=straight,
                      fixed_positions=scene.fixed_positions)
    x = solved(column).x
    assert np.abs(af.gradient(scene, x)[~scene.fixed_mask]).max() < 1e-9  # an equilibrium
    with pytest.raises(ValueError, match="saddle"):
        static_sensitivity(scene, types.SimpleNamespace(converged=True, x=x), gradient)


def test_fiber_angles_round_trip():
    d = fiber_direction(np.random.default_rng(0).uniform(-1.5, 1.5, (20, 2)))
    assert np.allclose(np.linalg.norm(d, axis=1), 1.0)
    assert np.allclose(fiber_direction(fiber_angles(d)), d)


TRADE_FIBER = (0.766, 0.0, 0.643)   # the trade's cantilever: fibers at 40 degrees in x-z
STEPS, DT = 20, 0.02


@pytest.mark.parametrize("law", ["stvk", "neohookean"])
@pytest.mark.parametrize("order", [1, 2])
def test_rollout_derivatives_against_finite_differences(order, law):
    """J = the tip's height after 10 and after 20 backward-Euler steps of the trade's 0.1 m
    cantilever (200 tets, fibers at 40 degrees, kappa = E) falling from rest: the adjoint's
    dJ/dp along random per-element changes against central differences of whole rollouts
    (steps as in the static test), to 1e-6 relative."""
    mesh = af.box_beam((0.1, 0.02, 0.02), (10, 2, 2), order=order)
    m, X = mesh.n_tets, mesh.vertices
    rng = np.random.default_rng(5)
    base = {"E": np.full(m, 1e5), "nu": np.full(m, 0.48), "kappa": np.full(m, 1e5),
            "angles": np.tile(fiber_angles(np.array(TRADE_FIBER) / np.linalg.norm(TRADE_FIBER)),
                              (m, 1))}

    def rollout(**changed):
        p = base | changed
        scene = af.Scene(mesh, af.Material(p["E"], p["nu"], 1000.0, fiber_direction(p["angles"]),
                                           p["kappa"], model=law),
                         fixed=np.flatnonzero(X[:, 0] < 1e-9), gravity=(0, 0, -9.81))
        result = af.simulate(scene, STEPS, DT, rtol=1e-12, warn=False)
        assert result.converged
        return scene, result
    tip = np.flatnonzero(X[:, 0] > 0.1 - 1e-9)

    def J(result):
        return sum(float(result.positions[k][tip, 2].mean()) for k in (10, 20))
    scene, result = rollout()
    gradients = np.zeros((STEPS + 1,) + X.shape)
    for k in (10, 20):
        gradients[k, tip, 2] = 1.0 / tip.size
    S = af.inverse.sensitivity.rollout_sensitivity(scene, result, gradients, DT)
    cases = {"young": ("E", rng.standard_normal(m) * 1e5, S.young, 1e-4),
             "poisson": ("nu", rng.standard_normal(m) * 1e-3, S.poisson, 1e-3),
             "kappa": ("kappa", rng.standard_normal(m) * 1e5, S.kappa, 1e-4),
             "fiber_angles": ("angles", rng.standard_normal((m, 2)), S.fiber_angles, 1e-5)}
    for name, (key, d, slope, h) in cases.items():
        plus = J(rollout(**{key: base[key] + h * d})[1])
        minus = J(rollout(**{key: base[key] - h * d})[1])
        fd = (plus - minus) / (2 * h)
        assert np.sum(slope * d) == pytest.approx(fd, rel=1e-6), name


@pytest.mark.parametrize("order", [1, 2])
def test_rollout_pressure_derivative(order):
    """A suddenly pressurized tube (2 kPa) rolled out 20 steps of 2 ms: d(the inner wall's mean
    radius after 10 and 20 steps)/dp against central differences of rollouts (h = 1 Pa)."""
    from test_pressure import tube_scene
    scene = tube_scene(order, (2, 6, 1), 2e3, fibers=1e5)
    X = scene.mesh.vertices
    inner = np.flatnonzero(np.abs(np.hypot(X[:, 0], X[:, 1]) - 0.01) < 1e-9)
    steps, dt = 20, 0.002

    def J(result):
        return sum(float(np.mean(np.hypot(*result.positions[k][inner, :2].T))) for k in (10, 20))
    gradients = np.zeros((steps + 1,) + X.shape)
    for k in (10, 20):  # the wall moves radially: its rest radial direction is J's gradient
        gradients[k, inner, :2] = X[inner, :2] / 0.01 / inner.size
    result = af.simulate(scene, steps, dt, rtol=1e-12, warn=False)
    S = af.inverse.sensitivity.rollout_sensitivity(scene, result, gradients, dt)
    h = 1.0
    fd = (J(af.simulate(scene.loaded(1 + h / 2e3), steps, dt, rtol=1e-12, warn=False))
          - J(af.simulate(scene.loaded(1 - h / 2e3), steps, dt, rtol=1e-12, warn=False))) / (2 * h)
    assert S.pressure[0] == pytest.approx(fd, rel=1e-6)


@pytest.mark.parametrize("regime", ["ordinary", "extreme"])
@pytest.mark.parametrize("law", ["stvk", "neohookean"])
def test_control_derivatives(regime, law):
    """The derivative of the tip height in each control of a cantilever with an activation
    control (its upper half's fibers), a cable along its top and a load pulling its tip,
    against Richardson-extrapolated central differences of solves, within 1e-6: ordinary (kappa
    2 E, activation 0.1, tension 0.02 N) and extreme (kappa 100 E, activation 0.5 for
    Neo-Hookean, tension 0.2 N; StVK at activation 0.1: from 0.2 on, the upper half's pull
    curls it until its elements turn inside out)."""
    kappa, a, T = {"ordinary": (2e5, 0.1, 0.02), "extreme": (1e7, 0.5, 0.2)}[regime]
    if law == "stvk" and regime == "extreme":
        a = 0.1
    base = cantilever(1, law, 1e5, 0.4, kappa, np.tile([0.0, 0.2], (120, 1)))
    mesh = base.mesh
    top = mesh.vertices[mesh.tets].mean(axis=1)[:, 2] > 0
    points = [(x, 0.0, 0.003) for x in np.linspace(0.0, LENGTH, 5)]
    scene = af.Scene(mesh, base.material, fixed=base.fixed_mask, gravity=(0, 0, -9.81),
                     activation=af.Activation(top, a, "top"),
                     cable=af.Cable(points, T, "pull"))
    J, gradient = tip_height(scene)
    S = static_sensitivity(scene, solved(scene), gradient)
    slopes = {"top": float(S.activation[top].sum()), "pull": float(S.tension[0])}
    for name, value, h in (("top", a, 1e-3), ("pull", T, 1e-3 * T)):
        def change(step):
            return J(solved(scene.with_controls({name: value + step})).x)

        def central(change, h):
            return (change(h) - change(-h)) / (2 * h)
        fd = (4 * central(change, h / 2) - central(change, h)) / 3
        assert slopes[name] == pytest.approx(fd, rel=1e-6), name
        assert abs(fd) > 1e-12


@pytest.mark.parametrize("regime", ["ordinary", "extreme"])
def test_pressure_control_derivative(regime):
    """A pneumatic actuator (anisofem.actuator, Neo-Hookean) with its cavity's pressure a
    control: the derivative of its tip's height in the pressure against Richardson central
    differences of solves, within 1e-6; ordinary (nu 0.45, kappa 5 E, no activation) and
    extreme (nu 0.499, kappa 100 E, its layer's fibers activated by 0.5)."""
    nu, kappa, a = {"ordinary": (0.45, 5e5, 0.0), "extreme": (0.499, 1e7, 0.5)}[regime]
    mesh, volumes, surfaces, _ = af.actuator(cells=(4, 2, 8), cavity=0.5, length=0.06)
    fibers = np.where((volumes == 2)[:, None], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0])
    material = af.Material(1e5, nu, 1000.0, fibers, kappa, model="neohookean")
    scene = af.Scene(mesh, material, fixed=np.unique(surfaces[4]),
                     pressure=af.Pressure(surfaces[3], 3e3, name="push"),
                     activation=af.Activation(volumes == 2, a, "curl"))
    tip = np.flatnonzero(mesh.vertices[:, 2] > 0.06 - 1e-9)
    gradient = np.zeros_like(mesh.vertices)
    gradient[tip, 1] = 1.0 / tip.size

    def J(x):
        return float(x[tip, 1].mean())
    S = static_sensitivity(scene, solved(scene), gradient)

    def change(step):
        return J(solved(scene.with_controls({"push": 3e3 + step})).x)

    def central(h):
        return (change(h) - change(-h)) / (2 * h)
    fd = (4 * central(1.0) - central(2.0)) / 3
    assert S.pressure[0] == pytest.approx(fd, rel=1e-6)
    assert abs(fd) > 1e-12
