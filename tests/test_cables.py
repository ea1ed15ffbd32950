"""Cables (tendons): against beam theory, their derivatives against central differences at
ordinary and extreme tensions, as a control changed every step, and bad input named."""
import numpy as np
import pytest

import anisofem as af
from anisofem.physics.potential import Potential
from anisofem.reduced import ReducedModel
from test_derivatives import fd_gradient, fd_hessian, rel_err

L, H, E = 0.1, 0.02, 1e5


def beam(cells=(10, 2, 2), order=2, tension=0.0, offset=0.006):
    """A cantilever L x H x H along x held at x = 0, a cable straight along it at `offset`
    above its axis (z) from the held end to the tip, through 9 points inside the body."""
    mesh = af.box_beam(size=(L, H, H), cells=cells, order=order)
    points = [(x, 0.0, offset) for x in np.linspace(0.0, L, 9)]
    return af.Scene(mesh, af.Material(E, 0.3, 1000.0),
                    fixed=af.metrics.end_vertices(mesh, 0, "min"),
                    cable=af.Cable(points, tension, "pull"))


def test_a_cable_bends_a_beam_by_an_end_moment():
    """A small tension T at offset e anchored at the tip is an end moment T e: the tip
    deflects T e L^2 / (2 E I) within 2% (quadratic tets, 10 x 2 x 2 cells), and the beam
    shortens by T L / (E A)."""
    T, e = 0.01, 0.006
    scene = beam(tension=T, offset=e)
    result = af.solve(scene, rtol=1e-10)
    assert result.converged
    X = scene.mesh.vertices
    tip = (result.x - X)[np.abs(X[:, 0] - L) < 1e-12].mean(axis=0)
    bending = T * e * L ** 2 / (2 * E * H ** 4 / 12)
    assert abs(tip[2] / bending - 1) < 0.02, tip[2] / bending
    assert abs(-tip[0] / (T * L / (E * H * H)) - 1) < 0.02
    # no tension, no deflection; a tension doubled, about twice the deflection (small T)
    assert np.abs(af.solve(scene.with_controls({"pull": 0.0})).x - X).max() < 1e-15
    twice = af.solve(scene.with_controls({"pull": 2 * T}), rtol=1e-10).x
    ratio = (twice - X)[np.abs(X[:, 0] - L) < 1e-12, 2].mean() / tip[2]
    assert abs(ratio - 2) < 0.01


@pytest.mark.parametrize("order", [1, 2])
@pytest.mark.parametrize("tension", [0.05, 500.0])
def test_the_cables_gradient_and_hessian_are_its_energys(order, tension):
    """At a deformed state, the potential's gradient and Hessian with a cable through vertices
    and interior points match central differences of its energy and gradient (1e-6), at an
    ordinary tension and one 10^4 times larger; the energy's derivative in the tension is the
    cable's length."""
    mesh = af.box_beam(size=(L, H, H), cells=(3, 1, 1), order=order)
    points = [int(np.argmin(mesh.vertices[:, 0])), (0.03, 0.002, 0.004), (0.06, -0.003, 0.001),
              int(np.argmax(mesh.vertices[:, 0] - mesh.vertices[:, 2]))]
    scene = af.Scene(mesh, af.Material(E, 0.3, 1000.0), fixed=[0],
                     cable=af.Cable(points, tension, "pull"))
    rng = np.random.default_rng(2)
    x = mesh.vertices + 0.002 * rng.standard_normal(mesh.vertices.shape)
    g = af.gradient(scene, x)
    assert rel_err(g, fd_gradient(scene, x, 1e-7)) < 1e-6
    Hm = af.hessian(scene, x).toarray()
    assert rel_err(Hm, fd_hessian(scene, x, 1e-7)) < 1e-6
    h = 1e-3 * tension
    slope = (Potential(scene.with_controls({"pull": tension + h})).energy(x)
             - Potential(scene.with_controls({"pull": tension - h})).energy(x)) / (2 * h)
    assert abs(slope - scene.cables[0].length(x)) <= 1e-6 * scene.cables[0].length(x)


def test_a_tension_changed_every_step_follows_the_controller():
    """simulate with a tension from a callable: each step's scene pulls with it (the same
    rollout as stepping by hand), and the tip rises and falls with the tension."""
    scene = beam(cells=(6, 1, 1), order=1)
    dt, steps = 0.02, 8

    def controller(t):
        return {"pull": 0.5 * np.sin(np.pi * t / (steps * dt))}
    rollout = af.simulate(scene, steps, dt, controls=controller)
    x, v = scene.initial_positions(), np.zeros_like(scene.initial_positions())
    for k in range(steps):
        result = af.step(scene.with_controls(controller((k + 1) * dt)), x, v, dt)
        x, v = result.x, result.v
    assert rollout.converged
    assert np.abs(rollout.positions[-1] - x).max() <= 1e-12 + 1e-9 * np.abs(x).max()
    tip = np.abs(scene.mesh.vertices[:, 0] - L) < 1e-12
    lift = rollout.positions[:, tip, 2].mean(axis=1)
    assert lift.max() > lift[0] + 1e-4


def test_bad_cables_are_named():
    mesh = af.box_beam(size=(L, H, H), cells=(3, 1, 1))
    material = af.Material(E, 0.3, 1000.0)
    for make, message in (
            (lambda: af.Cable([0], 1.0, "c"), "cable 'c': points: a cable runs through at "
                                               "least two points, got 1"),
            (lambda: af.Cable([0, 1], -1.0, "c"), "control 'c': a cable's tension must be >= 0"),
            (lambda: af.Cable([0, 1], float("nan"), "c"), "control 'c': expected a finite"),
            (lambda: af.Scene(mesh, material, cable=af.Cable([0, (0.05, 0.0, 0.5)], 1.0, "c")),
             r"cable 'c': point 1 at \[0.05, 0.0, 0.5\] m lies outside the mesh"),
            (lambda: af.Scene(mesh, material, cable=af.Cable([0, 10 ** 6], 1.0, "c")),
             "cable 'c': point 1 is vertex 1000000, not one of the mesh's"),
            (lambda: af.Scene(mesh, material, cable=af.Cable([0, "tip"], 1.0, "c")),
             "cable 'c': point 1: expected a vertex index or a finite rest point"),
            (lambda: af.Scene(mesh, material, cable=af.Cable([3, 3], 1.0, "c")),
             "cable 'c': its points all lie at one place"),
            (lambda: beam(cells=(3, 1, 1), order=1).with_controls({"pull": -2.0}),
             "control 'pull': a cable's tension must be >= 0")):
        with pytest.raises(ValueError, match=message):
            make()
    from anisofem.reduced import Loads
    with pytest.raises(ValueError, match="controls: 'pull' is a cable, its range must lie at "
                                         ">= 0 N"):
        ReducedModel(beam(cells=(3, 1, 1), order=1), modes=2, snapshots=2,
                     loads=Loads(controls={"pull": (-1.0, 1.0)}), validate=False)


def test_a_scene_file_routes_a_cable(tmp_path):
    from test_scenefile import scene_file, two_halves
    two_halves(tmp_path)
    text = ('mesh = "bar.msh"\n[controls.pull]\ncable = [[0, 0, 0.003], [0.02, 0, 0.003], '
            '[0.04, 0, 0.003]]\nvalue = 0.01\n[[boundary]]\nwhere = "base"\nheld = true\n')
    scene = af.load_scene(scene_file(tmp_path, text))
    assert scene.controls == ("pull",) and scene.cables[0].tension == 0.01
    assert scene.cables[0].rest_length == pytest.approx(0.04)
    for bad, message in (("value = 0.01", "value = -1"), ("[0.04, 0, 0.003]]",
                                                           "[0.04, 0, 0.3]]")):
        with pytest.raises(ValueError, match="controls"):
            af.load_scene(scene_file(tmp_path, text.replace(bad, message), "bad.toml"))


@pytest.fixture(scope="module")
def cable_model():
    """A cable finger (the 0.1 m beam, a cable at 6 mm above its axis, gravity) and its reduced
    model fitted to tensions up to 0.6 N."""
    mesh = af.box_beam(size=(L, H, H), cells=(10, 2, 2))
    points = [(x, 0.0, 0.006) for x in np.linspace(0.0, L, 9)]
    scene = af.Scene(mesh, af.Material(E, 0.3, 1000.0), gravity=(0.0, 0.0, -9.81),
                     fixed=af.metrics.end_vertices(mesh, 0, "min"),
                     cable=af.Cable(points, 0.0, "pull"))
    from anisofem.reduced import Loads
    return ReducedModel(scene, modes=6, snapshots=16, loads=Loads(controls={"pull": (0, 0.6)}))


def test_the_reduced_model_pulls_a_cable_exactly_and_follows_it(cable_model):
    """The reduced model's energy and force with a pulled cable equal the FEM's at x0 + U q
    (whatever the basis); fitted to the tension's range (its validation within 1%), a
    rollout with the tension changing every step under gravity follows the FEM's tip within
    1% of its largest motion."""
    model = cable_model
    scene, mesh = model.scene, model.scene.mesh
    assert model.validation.tip_error < 0.01
    q = 0.01 * np.random.default_rng(0).standard_normal(model.r)
    x = model.positions(q)
    fem = Potential(scene.with_controls({"pull": 1.3}))
    terms = fem.terms(x)
    expected = terms["isotropic"] + terms["fiber"] + terms["pressure"]
    assert abs(model.energy(q, {"pull": 1.3}) - expected) <= 1e-10 * abs(expected)
    force = (fem.energy_gradient(x)[1] + scene.external_force).ravel() @ model.basis
    assert np.abs(model.force(q, controls={"pull": 1.3}) - force).max() <= 1e-9 * np.abs(
        force).max()
    dt, steps = 0.02, 25

    def controller(t):
        return {"pull": 0.3 * (1 - np.cos(10 * t))}
    from test_controls import rollout_gap
    worst, travel = rollout_gap(model, controller, np.abs(mesh.vertices[:, 0] - L) < 1e-12,
                                dt, steps)
    assert worst <= 0.01 * travel, (worst, travel)


def test_the_runtimes_pull_the_cable_like_the_model(cable_model, tmp_path):
    """Written to a file: the numpy runtime steps like the model and the C runtime like numpy,
    to 1e-9 of the largest displacement over 40 steps with the tension changing every step
    (slack in some); the C runtime under the sanitizers too; a negative tension is named."""
    import re
    import subprocess
    from export import native
    from export.runtime import ReducedSimulator
    from export.writers.reduced import write
    model = cable_model
    path = str(tmp_path / "finger")
    write(model, path)
    py = ReducedSimulator(path)
    assert py.controls == ("pull",)
    c = None
    if native.compiler() is not None:
        c = native.CReducedSimulator(path, native.build(str(tmp_path / "lib")))
        c.set_constant_force(model.scene.external_force)
        q_c, w_c = c.rest_state()
    q, w = np.zeros(model.r), np.zeros(model.r)
    q_py, w_py = py.rest_state()
    scale = 0.0
    for k in range(40):
        tension = max(0.0, 0.5 * np.sin(0.3 * k))
        q, w, _ = model.step(q, w, 0.02, controls=[tension])
        q_py, w_py = py.step(q_py, w_py, model.scene.external_force, 0.02, controls=[tension])
        x = model.positions(q)
        scale = max(scale, np.abs(x - model.x0).max())
        assert np.abs(py.positions(q_py) - x).max() <= 1e-9 * scale
        if c is not None:
            c.step(q_c, w_c, None, 0.02, controls=[tension])
            assert np.abs(c.positions(q_c) - py.positions(q_py)).max() <= 1e-9 * scale
    for sim in [py] + ([c] if c else []):
        with pytest.raises((ValueError, RuntimeError), match="'pull'.* a cable, a tension >= 0 "
                                                             "N; got -1"):
            sim.set_controls([-1.0])
    if c is None:
        return
    from test_c_runtime import _sanitized
    done = subprocess.run([_sanitized(tmp_path), path], capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 0 and "runtime error" not in done.stderr, done.stderr
    assert re.match(r"ok 1 \d+ 50 \S+ controls 1 reach [01]$", done.stdout.strip()), done.stdout


def test_the_c_runtime_reaches_with_a_cable_like_the_model(cable_model, tmp_path):
    """af_reach on a cable model against ReducedModel.reach: the same tension (1e-7 of its
    range) and tip (1e-9 m), from a slack start."""
    from export import native
    from export.writers.reduced import write
    if native.compiler() is None:
        pytest.skip("no C compiler")
    model = cable_model
    path = str(tmp_path / "finger")
    write(model, path)
    c = native.CReducedSimulator(path, native.build(str(tmp_path / "lib")))
    c.set_constant_force(model.scene.external_force)
    tip = np.flatnonzero(np.abs(model.scene.mesh.vertices[:, 0] - L) < 1e-12)
    target = model.positions(model.solve(controls=[0.4])[0])[tip].mean(axis=0)
    ours = model.reach(list(tip), target)
    controls, position, reached, _ = c.reach(tip, np.full(tip.size, 1.0 / tip.size), target,
                                             [0.0], [0.6])
    assert ours.reached and reached
    assert abs(controls[0] - ours.controls[0]) <= 1e-7 * 0.6
    assert np.abs(position - ours.position).max() <= 1e-9
