"""Controls: named pressures and activations a controller sets every step, in the FEM and the
reduced model. The reduced energy under any controls equals the FEM's at the same positions
(exact, independently of the basis); a rollout whose controls change every step follows the
FEM's; bad control input is named."""
import json
import os
import re
import sys

import numpy as np
import pytest

import anisofem as af
from anisofem.reduced import Loads, ReducedModel

E = 1e5
ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def finger(order=1):
    """A 6 cm pneumatic finger (anisofem.actuator: a body around a cavity on a flat layer)
    held at its base, fibers along it in its layer and across it (along x) in its body: the
    pressure in its cavity a control "push", the activation of its layer's fibers a control
    "curl" and of its body's a control "squeeze"; gravity along -y."""
    mesh, volumes, surfaces, _ = af.actuator(cells=(4, 2, 8), cavity=0.5, length=0.06,
                                             order=order)
    fibers = np.where((volumes == 2)[:, None], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0])
    material = af.Material(E, 0.45, 1000.0, fibers, 5 * E)
    base = np.unique(surfaces[4])
    if order == 2:
        base = np.flatnonzero(np.abs(mesh.vertices[:, 2]) < 1e-12)
    return af.Scene(mesh, material, fixed=base, gravity=(0, -9.81, 0),
                    pressure=af.Pressure(surfaces[3], 0.0, name="push"),
                    activation=[af.Activation(volumes == 2, 0.0, "curl"),
                                af.Activation(volumes == 1, 0.0, "squeeze")])


def test_controls_are_named_and_set():
    scene = finger()
    assert scene.controls == ("push", "curl", "squeeze")
    assert scene.control_values.tolist() == [0.0, 0.0, 0.0]
    now = scene.with_controls({"curl": 0.3, "push": 200.0})
    assert now.control_values.tolist() == [200.0, 0.3, 0.0]
    assert scene.control_values.tolist() == [0.0, 0.0, 0.0]   # the scene itself is unchanged
    layer = scene.activations[0].elements
    assert np.allclose(now.elements.rest2[layer], 0.49)
    assert (np.delete(now.elements.rest2, layer) == 1.0).all()
    assert np.array_equal(scene.with_controls([200.0, 0.3, 0.0]).elements.rest2,
                          now.elements.rest2)
    # the layer's fibers (y < 0) contract, or the cavity inflates above the layer: either way
    # the tip curls toward the layer
    tip = scene.mesh.vertices[:, 2] > 0.06 - 1e-9
    rest = scene.mesh.vertices[tip, 1].mean()
    weightless = scene.plus_force(-scene.external_force)
    curled = af.solve(weightless.with_controls({"curl": 0.1})).x
    pushed = af.solve(weightless.with_controls({"push": 2e4})).x
    assert curled[tip, 1].mean() - rest < -0.005 and pushed[tip, 1].mean() - rest < -0.003


@pytest.mark.parametrize("values, message", [
    ({"sideways": 0.1}, "controls: no control 'sideways'; the scene has: push, curl, "
                        "squeeze"),
    ({"curl": 1.0}, r"control 'curl': an activation must be in \[0, 1\)"),
    ({"curl": -0.1}, r"control 'curl': an activation must be in \[0, 1\)"),
    ({"push": float("nan")}, "control 'push': expected a finite number, got nan"),
    ({"push": "high"}, "control 'push': expected a number, got 'high'"),
    ([0.1, 0.2], r"controls: expected a mapping of names to values or 3 values"),
])
def test_bad_controls_are_named(values, message):
    with pytest.raises(ValueError, match=message):
        finger().with_controls(values)


def test_bad_control_declarations_are_named():
    scene = finger()
    mesh, material = scene.mesh, scene.material
    bare = af.Material(E, 0.45, 1000.0, (1, 0, 0), np.where(np.arange(mesh.n_tets) < 4, 0.0,
                                                             5 * E))
    for make, message in (
            (lambda: af.Scene(mesh, bare, activation=af.Activation([0, 1, 9], 0.1, "a")),
             "activation 'a': 2 of its elements have no fibers"),
            (lambda: af.Scene(mesh, material, activation=[af.Activation([5, 6], 0.1, "a"),
                                                          af.Activation([6, 7], 0.1, "b")]),
             "activation 'b': 1 of its elements are activation 'a''s too"),
            (lambda: af.Scene(mesh, material, activation=[af.Activation([5], 0.1, "a"),
                                                          af.Activation([6], 0.1, "a")]),
             "controls: the name 'a' is given to two controls"),
            (lambda: af.Scene(mesh, material, activation=af.Activation([mesh.n_tets], 0.1)),
             "activation 'activation': elements: index out of range"),
            (lambda: af.Activation([1], 1.5, "a"), r"an activation must be in \[0, 1\)"),
            (lambda: af.Scene(mesh, af.Material(E, 0.45, 1000.0, (1, 0, 0), 5 * E,
                                                activation=0.1),
                              activation=af.Activation([3], 0.1, "a")),
             "activation 'a': 1 of its elements have an activation of their Material too")):
        with pytest.raises(ValueError, match=message):
            make()


def test_simulate_takes_controls_as_curves_or_a_controller():
    """simulate's controls, as (times, values) or as a callable, set each step's scene: the
    same rollout as stepping the scene with the controls set by hand."""
    scene = finger()
    dt, steps = 0.02, 6

    def controller(t):
        return {"curl": 0.1 * t / (steps * dt), "push": 500.0 * np.sin(20 * t)}
    by_callable = af.simulate(scene, steps, dt, controls=controller)
    times = (np.arange(steps + 1) * dt).tolist()
    table = {name: (times, [controller(t)[name] for t in times]) for name in ("curl", "push")}
    by_table = af.simulate(scene, steps, dt, controls=table)
    x, v = scene.initial_positions(), np.zeros_like(scene.initial_positions())
    for k in range(steps):
        result = af.step(scene.with_controls(controller((k + 1) * dt)), x, v, dt)
        x, v = result.x, result.v
    assert by_callable.converged and by_table.converged
    scale = np.abs(x - scene.mesh.vertices).max()
    assert np.abs(by_callable.positions[-1] - x).max() <= 1e-9 * scale
    assert np.abs(by_table.positions[-1] - x).max() <= 1e-9 * scale
    with pytest.raises(ValueError, match="controls: no control 'left'"):
        af.simulate(scene, 2, dt, controls={"left": ([0, 1], [0, 1])})
    with pytest.raises(ValueError, match=r"control 'curl': an activation must be in \[0, 1\)"):
        af.simulate(scene, 2, dt, controls=lambda t: {"curl": 2.0})


@pytest.mark.parametrize("order", [1, 2])
def test_the_reduced_energy_under_controls_is_the_fems(order):
    """At any reduced coordinates and any controls, the reduced model's energy and force equal
    the FEM's (elastic + pressure) at x0 + U q, projected: exact, whatever the basis."""
    scene = finger(order)
    model = ReducedModel(scene, modes=4, validate=False)
    rng = np.random.default_rng(3)
    for values in ({"push": 0.0, "curl": 0.0, "squeeze": 0.0}, {"push": 800.0, "curl": 0.4,
                                                           "squeeze": 0.0},
                   {"push": -300.0, "curl": 0.05, "squeeze": 0.6}):
        q = 0.05 * rng.normal(size=model.r)
        x = model.positions(q)
        fem = af.physics.potential.Potential(scene.with_controls(values))
        terms = fem.terms(x)
        elastic = terms["isotropic"] + terms["fiber"] + terms["pressure"]
        _, gradient = fem.energy_gradient(x)
        gradient = gradient + scene.external_force   # the external part: f_ext, taken out
        assert abs(model.energy(q, values) - elastic) <= 1e-10 * abs(elastic)
        force = model.force(q, controls=values)
        assert np.abs(force - model.basis.T @ gradient.ravel()).max() <= \
            1e-9 * np.abs(force).max()


def rollout_gap(model, controller, tip, dt, steps):
    """(the largest distance between the reduced model's tip and the FEM's over `steps` steps
    of dt from rest, both under controller(t) at each step's end; the FEM tip's largest
    motion), m; tip: the vertices (a mask or indices) whose mean is the tip. Every step of
    both converges."""
    full = af.simulate(model.scene, steps, dt, controls=controller)
    assert full.converged
    q, w, worst = np.zeros(model.r), np.zeros(model.r), 0.0
    for k in range(steps):
        q, w, report = model.step(q, w, dt, controls=controller((k + 1) * dt))
        assert report.converged
        gap = model.positions(q)[tip].mean(0) - full.positions[k + 1][tip].mean(0)
        worst = max(worst, float(np.linalg.norm(gap)))
    travel = np.linalg.norm(full.positions[:, tip].mean(1) - full.positions[0, tip].mean(0),
                            axis=1).max()
    return worst, float(travel)


#: The controls' ranges the finger's reduced model is built for.
RANGES = {"curl": (0.0, 0.15), "squeeze": (0.0, 0.1), "push": (-2e4, 2e4)}


def test_a_reduced_rollout_follows_controls_that_change_every_step():
    """The reduced model fitted to its controls' declared ranges (anisofem.reduced.Loads)
    against the FEM, the three controls changing every step: the tip's path within 1% of its
    largest displacement, and the model's own validation on unseen controls within 1%."""
    scene = finger()
    model = ReducedModel(scene, modes=6, snapshots=24, loads=Loads(controls=RANGES))
    assert model.validation.cases == 3 and model.validation.tip_error < 0.01
    dt, steps = 0.02, 25

    def controller(t):
        return {"curl": 0.15 * (1 - np.cos(8 * t)) / 2, "squeeze": 0.2 * t,
                "push": 1.5e4 * np.sin(12 * t)}
    worst, travel = rollout_gap(model, controller, scene.mesh.vertices[:, 2] > 0.06 - 1e-9,
                                dt, steps)
    assert travel > 0.01 and worst <= 0.01 * travel, (worst, travel)
    q, w = np.zeros(model.r), np.zeros(model.r)
    with pytest.raises(ValueError, match="controls: no control 'left'"):
        model.step(q, w, dt, controls={"left": 0.1})
    with pytest.raises(ValueError, match=r"control 'squeeze': an activation must be in \[0, 1\)"):
        model.solve(controls={"squeeze": 1.0})


def test_declared_control_ranges_are_checked():
    scene = finger()
    for loads, message in (
            (dict(controls={"left": (0, 1)}), "controls: no control 'left'"),
            (dict(controls={"curl": (0, 1.0)}), r"controls: 'curl' is an activation, its range "
                                                 r"must lie in \[0, 1\)"),
            (dict(controls={"push": (5, 1)}), "controls: 'push': expected finite low < high"),
            (dict(controls={"push": 5}), r"controls: 'push': expected a range \(low, high\)")):
        with pytest.raises(ValueError, match=message):
            ReducedModel(scene, modes=2, snapshots=2, loads=Loads(**loads), validate=False)


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    """The finger's reduced model fitted to its controls, written to a file."""
    from export.writers.reduced import write
    folder = tmp_path_factory.mktemp("controls")
    model = ReducedModel(finger(), modes=6, snapshots=24, loads=Loads(controls=RANGES),
                         validate=False)
    write(model, str(folder / "finger"))
    return model, str(folder / "finger"), folder


def controls_at(k):
    """Controls that change every step k: the three at once, within RANGES."""
    return [1.5e4 * np.sin(0.4 * k), 0.075 * (1 - np.cos(0.3 * k)), 0.05 * (1 + np.sin(0.5 * k))]


def test_the_runtimes_step_with_controls_like_the_model(written):
    """numpy runtime against ReducedModel (1e-10), the C runtime against the numpy one (1e-9),
    over 60 steps under gravity with the three controls changing every step."""
    from export import native
    from export.runtime import ReducedSimulator
    model, path, folder = written
    py = ReducedSimulator(path)
    assert py.controls == model.controls == ("push", "curl", "squeeze")
    assert py.control_values.tolist() == [0.0, 0.0, 0.0]
    gravity = model.scene.external_force
    q_model, v_model = np.zeros(model.r), np.zeros(model.r)
    q_py, w_py = py.rest_state()
    c = None
    if native.compiler() is not None:
        c = native.CReducedSimulator(path, native.build(str(folder / "lib")))
        assert c.controls == model.controls
        c.set_constant_force(gravity)
        q_c, w_c = c.rest_state()
    scale = 0.0
    for k in range(60):
        values = controls_at(k)
        q_model, v_model, _ = model.step(q_model, v_model, 0.02, controls=values)
        q_py, w_py = py.step(q_py, w_py, gravity, 0.02, controls=values)
        x = model.positions(q_model)
        scale = max(scale, np.abs(x - model.x0).max())
        assert np.abs(py.positions(q_py) - x).max() <= 1e-10 * scale
        if c is not None:
            c.step(q_c, w_c, None, 0.02, controls=values)
            assert np.abs(c.positions(q_c) - py.positions(q_py)).max() <= 1e-9 * scale
    assert scale > 0.01
    assert py.control_values.tolist() == pytest.approx(controls_at(59))


def test_the_runtimes_name_bad_controls_and_bad_control_arrays(written, tmp_path):
    from corrupt_files import corrupt, nan_at, set_spec
    from export import native
    from export.runtime import ReducedSimulator
    _, path, folder = written
    runtimes = [ReducedSimulator]
    if native.compiler() is not None:
        lib = native.build(str(folder / "lib"))
        runtimes.append(lambda p: native.CReducedSimulator(p, lib))
    for make in runtimes:
        sim = make(path)
        for values, error, message in (
                ({"left": 0.1}, ValueError, "controls: no control 'left'; the model has: push, "
                                            "curl, squeeze"),
                ([0.1, 0.2], ValueError, r"controls: expected 3 values \(push, curl, squeeze\)"),
                ({"curl": 1.0}, (ValueError, RuntimeError), r"'curl'.* an activation, in "
                                                             r"\[0, 1\); got 1"),
                ({"push": np.nan}, (ValueError, RuntimeError), "'push'.* a pressure, a finite "
                                                               "number of Pa; got nan")):
            with pytest.raises(error, match=message):
                sim.set_controls(values)
        assert sim.control_values.tolist() == [0.0, 0.0, 0.0]   # unchanged by a refusal
        sim.set_controls({"curl": 0.1})
        assert sim.control_values.tolist() == [0.0, 0.1, 0.0]
        for edit, message in (
                (dict(edit_bin=nan_at("control_C2")), "array control_C2 holds a non-finite"),
                (dict(edit_header=set_spec("control_S3", "shape", lambda s: [2] + s[1:])),
                 "control_S3"),
                (dict(edit_header=lambda h: h.update(controls=["push", "curl"])),
                 r"control_kinds has shape \(3,\), expected \(2\)|\"controls\" is not a list of 3 "
                 r"names")):
            bad = corrupt(path, str(tmp_path / "bad"), **edit)
            with pytest.raises(ValueError, match=message):
                make(bad)


def test_export_builds_a_scene_files_controls_for_their_ranges(tmp_path, capsys):
    """A scene file's [controls.NAME] with a range: `python -m export reduced` fits the model
    to it (the header records it) and the file steps with the control; a bad range is named."""
    from export.cli import main
    from export.runtime import ReducedSimulator
    from test_scenefile import scene_file, two_halves
    two_halves(tmp_path)
    text = ('mesh = "bar.msh"\n[material]\nfiber = [1, 0, 0]\nfiber_stiffness = 1e5\n'
            '[controls.squeeze]\nactivation = "stiff"\nrange = [0, 0.3]\n'
            '[[boundary]]\nwhere = "base"\nheld = true\n')
    path = str(tmp_path / "bar")
    main(["reduced", str(scene_file(tmp_path, text)), "--modes", "4", "--snapshots", "8",
          "-o", path])
    assert "1 drags, a 0 degree cone, 1 control ranges" in capsys.readouterr().err
    header = json.load(open(path + ".json"))
    assert header["controls"] == ["squeeze"]
    assert header["loads"]["controls"] == {"squeeze": [0.0, 0.3]}
    sim = ReducedSimulator(path)
    q, w = sim.rest_state()
    for _ in range(20):
        q, w = sim.step(q, w, np.zeros_like(sim.rest_positions), 0.02,
                        controls={"squeeze": 0.2})
    tip = sim.positions(q)[:, 0].max()
    assert tip < sim.rest_positions[:, 0].max() - 1e-4   # the stiff half's fibers contract
    for bad in ("range = [0, 1.3]", "range = [0.3]"):
        with pytest.raises(SystemExit) as exit_:
            main(["reduced", str(scene_file(tmp_path, text.replace("range = [0, 0.3]", bad),
                                            "bad.toml")), "-o", path])
        assert exit_.value.code == 2
        assert "controls.squeeze.range: expected" in capsys.readouterr().err


@pytest.fixture(scope="module")
def fitted():
    return ReducedModel(finger(), modes=6, snapshots=24, loads=Loads(controls=RANGES),
                        validate=False)


def test_reach_finds_the_controls_that_bring_the_tip_to_a_target(fitted):
    """Targets across the reachable workspace (the tip's equilibria under random controls in
    the ranges): each reached in the model within 1e-4 of the finger's length, and the FEM at
    the controls found puts the tip within 1% of it; a target above the finger (it bends
    only down) is out of reach: said, with the nearest point found."""
    model, scene = fitted, fitted.scene
    tip = int(np.flatnonzero(scene.mesh.vertices[:, 2] > 0.06 - 1e-9)[0])
    rng = np.random.default_rng(0)
    for _ in range(6):
        drawn = [rng.uniform(*RANGES[name]) for name in model.controls]
        target = model.positions(model.solve(controls=drawn)[0])[tip]
        found = model.reach(tip, target)
        assert found.reached and found.distance <= 1e-4 * 0.06, found.message
        low, high = np.array([RANGES[n] for n in model.controls]).T
        assert ((found.controls >= low) & (found.controls <= high)).all()
        full = af.solve(scene.with_controls(found.controls)).x[tip]
        assert np.linalg.norm(full - target) <= 0.01 * 0.06
    above = model.x0[tip] + [0.0, 0.05, 0.0]
    found = model.reach(tip, above)
    assert not found.reached and found.message.startswith("out of reach")
    rest = model.positions(model.solve(controls=[0, 0, 0])[0])[tip]
    assert found.distance <= np.linalg.norm(rest - above) + 1e-9
    assert np.allclose(found.position, model.positions(found.q)[tip])


def test_reach_names_bad_bounds(fitted):
    for bounds, message in (({"left": (0, 1)}, "bounds: no control 'left'"),
                            ({"curl": (0, 1.2)}, r"bounds: 'curl': expected low < high in "
                                                 r"\[0, 1\)"),
                            ({"push": (3, 1)}, "bounds: 'push': expected low < high")):
        with pytest.raises(ValueError, match=message):
            fitted.reach(0, [0, 0, 0.06], bounds=bounds)
    unranged = ReducedModel(finger(), modes=3, validate=False)
    with pytest.raises(ValueError, match="bounds: control 'push' has no range"):
        unranged.reach(0, [0, 0, 0.06])
    with pytest.raises(ValueError, match="effector: vertex 100000 is not one of"):
        fitted.reach(100000, [0, 0, 0.06])


def test_the_c_runtime_reaches_like_the_model(written):
    """af_reach against ReducedModel.reach on the same file: the same controls (1e-7 of each
    range) and effector (1e-9 m) for reachable targets, and the same out-of-reach answer, each
    target from rest and in a control loop."""
    from export import native
    if native.compiler() is None:
        pytest.skip("no C compiler")
    model, path, folder = written
    c = native.CReducedSimulator(path, native.build(str(folder / "lib")))
    c.set_constant_force(model.scene.external_force)
    tip = int(np.flatnonzero(model.scene.mesh.vertices[:, 2] > 0.06 - 1e-9)[0])
    low, high = np.array([RANGES[n] for n in model.controls]).T
    rng = np.random.default_rng(1)
    targets = [model.positions(model.solve(controls=[rng.uniform(*RANGES[n]) for n in
                                                     model.controls])[0])[tip]
               for _ in range(4)] + [model.x0[tip] + [0.0, 0.05, 0.0]]
    for loop in (False, True):   # each target from rest; then a control loop, where af_reach
        found = None             # starts from the last answer and its equilibrium
        c.set_controls(np.zeros(3))
        for target in targets:
            ours = model.reach(tip, target, controls=found.controls if loop and found else None,
                               q0=found.q if loop and found else None)
            controls, position, reached, message = c.reach([tip], [1.0], target, low, high)
            assert reached == ours.reached
            assert np.abs(controls - ours.controls).max() <= 1e-7 * np.abs(high - low).max()
            assert np.abs(position - ours.position).max() <= 1e-9
            assert reached or message.startswith("out of reach")
            found = ours
            if loop:
                c.set_controls(controls)
            else:   # af_reach leaves them as they were
                assert c.control_values.tolist() == [0.0, 0.0, 0.0]
    with pytest.raises(RuntimeError, match="reach: the bounds of 'curl' must have low < high"):
        c.reach([tip], [1.0], targets[0], [-1, 0.2, 0], [1, 0.1, 0.1])
    with pytest.raises(RuntimeError, match="'curl', control 1 is an activation"):
        c.reach([tip], [1.0], targets[0], [-1, 0.2, 0], [1, 1.5, 0.1])
    with pytest.raises(RuntimeError, match="reach: effector node 0 is -3"):
        c.reach([-3], [1.0], targets[0], low, high)


def test_under_the_sanitizers_a_file_with_controls_steps_and_reaches(written, tmp_path):
    """tests/c/load_and_step.c with AddressSanitizer and UndefinedBehaviorSanitizer: the
    controls set anew every step, one af_reach, and the corrupt control arrays each named."""
    import subprocess
    from corrupt_files import corrupt, nan_at, set_spec
    from export import native
    from test_c_runtime import _sanitized
    if native.compiler() is None:
        pytest.skip("no C compiler")
    _, path, _ = written
    exe = _sanitized(tmp_path)
    out = str(tmp_path / "bad")
    cases = [(path, r"ok 1 \d+ 50 \S+ controls 3 reach [01]$"),
             (corrupt(path, out + "-nan", edit_bin=nan_at("control_c1")),
              r"array control_c1 holds a non-finite number"),
             (corrupt(path, out + "-kinds", edit_bin=_kinds_out_of_order),
              r"array control_kinds: 0 \(pressures\), 1 \(activations\) then 2 \(cables\) "
              r"expected"),
             (corrupt(path, out + "-s3", set_spec("control_S3", "shape",
                                                  lambda s: [s[0] + 1] + s[1:])),
              r"control_S3|runs past the end"),
             (corrupt(path, out + "-names", edit_header=lambda h: h.update(controls=["a"])),
              r"the header's \"controls\" is not a list of 3 names")]
    done = subprocess.run([exe, *(c[0] for c in cases)], capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 0 and "runtime error" not in done.stderr, done.stderr
    lines = done.stdout.splitlines()
    assert len(lines) == len(cases)
    for line, (_, pattern) in zip(lines, cases):
        assert re.search(pattern, line), (pattern, line)


def _kinds_out_of_order(data, header):
    """edit_bin: control_kinds' last entry a pressure (0), after the activations."""
    offset = header["arrays"]["control_kinds"]["offset"]
    data[offset + 2] = 0
    return data


def test_trajectory_gradient_is_the_objectives(fitted):
    """The adjoint gradient of the path objective in the knots' controls (scaled) against
    central differences: within 1e-6."""
    from anisofem.inverse.control import _Trajectory
    from anisofem.reduced.reach import model_bounds
    model = fitted
    tip = int(np.flatnonzero(model.scene.mesh.vertices[:, 2] > 0.06 - 1e-9)[0])
    dt, steps = 0.02, 12
    times = dt * np.arange(steps + 1)
    points = model.x0[tip] + np.outer(times, [0.0, -0.02, 0.0])
    low, high = model_bounds(model, None)
    problem = _Trajectory(model, tip, times, points, np.linspace(0, steps * dt, 4), steps, dt,
                          low, high, 1e-3)
    z = np.random.default_rng(0).uniform(0.2, 0.8, 12)
    _, g = problem.objective(z)
    fd = np.zeros_like(z)
    for i in range(z.size):
        step = np.zeros_like(z)
        step[i] = 1e-6
        fd[i] = (problem.objective(z + step)[0] - problem.objective(z - step)[0]) / 2e-6
    assert np.linalg.norm(g - fd) <= 1e-6 * np.linalg.norm(fd)


def test_follow_finds_controls_in_time_for_a_path(fitted):
    """A path the tip takes under controls that change in time (a pressure swinging both
    ways, a curl and a squeeze): from every control at its low end, follow's controls make
    the reduced model's tip follow it within 2% of the finger's length."""
    from anisofem.inverse.control import follow
    model = fitted
    tip = int(np.flatnonzero(model.scene.mesh.vertices[:, 2] > 0.06 - 1e-9)[0])
    dt, steps = 0.02, 25

    def true(t):
        return [1.5e4 * np.sin(4 * t), 0.06 * (1 - np.cos(5 * t)), 0.04 * t]
    q = model.solve(controls=true(0.0))[0]
    w, points = np.zeros(model.r), [model.positions(q)[tip]]
    for n in range(1, steps + 1):
        q, w, _ = model.step(q, w, dt, controls=true(n * dt))
        points.append(model.positions(q)[tip])
    result = follow(model, tip, dt * np.arange(steps + 1), np.array(points), dt)
    assert result.largest_error < 0.02, result.largest_error
    low, high = np.array([RANGES[n] for n in model.controls]).T
    assert ((result.controls >= low - 1e-12) & (result.controls <= high + 1e-12)).all()


def test_the_control_command_writes_the_curves_it_found(tmp_path, capsys):
    """python -m anisofem control on the example actuator: its iterations, the tip's largest
    error in the model and in the full FEM under the controls found (both within 2% of its
    length), and a scene file whose control follows the curve found; bad input, one line."""
    from anisofem.cli import main
    from anisofem.io.scenefile import SceneFile
    scene_path = os.path.join(ROOT, "examples", "scenes", "actuator_control.toml")
    tip = SceneFile(scene_path).vertices("tip")
    rest = af.load_scene(scene_path).mesh.vertices[tip].mean(axis=0)
    times = np.linspace(0.0, 0.4, 9)
    path = rest + np.outer(np.sin(np.pi * times / 0.4) ** 2, [0.0, -0.01, 0.0])
    csv = tmp_path / "path.csv"
    np.savetxt(csv, np.column_stack([times, path]), delimiter=",", header="t,x,y,z",
               comments="")
    out = tmp_path / "controlled.toml"
    main(["control", scene_path, "--effector", "tip", "--path", str(csv), "-o", str(out)])
    text = capsys.readouterr().out
    assert "iteration 1: J = " in text
    model_error, fem_error = (float(re.search(rf"{what}: largest error .* \(([0-9.e-]+)%",
                                              text).group(1))
                              for what in (r"reduced model \(r = \d+\)", "full FEM under these "
                                                                         "controls"))
    assert model_error < 2.0 and fem_error < 2.0, text
    scene = af.load_scene(out)
    assert scene.controls == ("inflate",) and scene.timed[0].control == "inflate"
    assert scene.at(0.2).control_values[0] > 1e3
    for flags, message in ((["--path", str(tmp_path / "none.csv")], "--path: no such file"),
                           (["--effector", "nowhere"], "no physical surface 'nowhere'")):
        args = ["control", scene_path, "--effector", "tip", "--path", str(csv), *flags]
        with pytest.raises(SystemExit) as exit_:
            main(args)
        assert exit_.value.code == 2 and message in capsys.readouterr().err


def test_the_trades_reduced_rungs_follow_controls_on_curves():
    """A finger whose layer's activation follows a load curve: the trade's fitted reduced rung
    (its build samples the curve's range) follows the exact rollout within 1% of the static
    deflection at every checked time; a scene whose held vertices move on a curve leaves the
    reduced rungs out with a note."""
    from anisofem.physics.curves import LoadCurve, Timed
    from anisofem.studies.rungs import fem_rungs, select_rungs
    scene = finger().with_controls({"curl": 0.12})
    scene = scene.following([Timed(LoadCurve([0, 0.2, 0.4], [0, 1, 0.3], name="c"),
                                   control="curl")])
    result = af.trade(scene, steps=20, progress=False,
                      rungs=select_rungs(fem_rungs(), ["reduced m4 s16"]))
    row = {r["name"]: r for r in result["rungs"]}["reduced m4 s16"]
    assert max(row["errors"]) < 0.01, row["errors"]
    assert not any("reduced rungs not run" in n for n in result["notes"])
    moved = finger().following([Timed(LoadCurve([0, 1], [0, 1], name="m"),
                                      motion=lambda c: np.zeros((180, 3)))])
    result = af.trade(moved, steps=10, progress=False,
                      rungs=select_rungs(fem_rungs(), ["reduced m5"]))
    assert any("reduced rungs not run: the reduced rungs follow forces and controls" in n
               for n in result["notes"])


def test_the_tentacle_follows_activations_that_change_every_step():
    """examples/scenes/tentacle.toml (four bands of fibers) and its reduced model fitted to
    their ranges (6 modes, 24 fitted directions) against the FEM, three bands' activations
    changing smoothly every step: the tip within 1% of its largest motion over 40 steps."""
    sys.path.insert(0, os.path.join(ROOT, "examples"))
    try:
        from tentacle import LENGTH, tentacle
    finally:
        sys.path.pop(0)
    scene, ranges = tentacle()
    model = ReducedModel(scene, modes=6, snapshots=24, loads=Loads(controls=ranges),
                         validate=False)
    dt, steps = 0.02, 40

    def controller(t):
        return {"up": 0.05 * (1 - np.cos(4 * t)), "down": 0.0,
                "left": 0.05 * (1 - np.cos(3 * t)), "right": 0.02 * (1 - np.cos(5 * t))}
    worst, travel = rollout_gap(model, controller,
                                scene.mesh.vertices[:, 0] > LENGTH - 1e-9, dt, steps)
    assert travel > 0.03 and worst <= 0.01 * travel, (worst, travel)


@pytest.mark.parametrize("control, message", [
    ('[controls.c]\nactivation = "stiff"\nvalue = 1.5\n',
     r"controls\.c\.value: control 'c': an activation must be in \[0, 1\)"),
    ('[controls.c]\ncable = [[0, 0, 0.003], [0.04, 0, 0.003]]\nvalue = -0.5\n',
     r"controls\.c\.value: control 'c': a cable's tension must be >= 0 N"),
    ('[controls.c]\nactivation = "stiff"\nvalue = nan\n',
     r"controls\.c\.value: control 'c': an activation must be in \[0, 1\)|expected a finite"),
    ('[controls.c]\nactivation = "soft"\nvalue = 0.1\n',
     r"controls: activation 'c': \d+ of its elements have no fibers"),
    ('[controls.c]\ncable = [[0, 0, 0.003], [0.04, 0, 0.3]]\nvalue = 0.1\n',
     r"controls: cable 'c': point 1 at \[0.04, 0.0, 0.3\] m lies outside the mesh"),
    ('[controls.c]\nactivation = "stiff"\nvalue = 0.1\ncurve = "nope"\n',
     r"controls\.c\.curve: no curve 'nope'")])
def test_the_command_line_names_a_bad_control_in_one_line(tmp_path, control, message):
    """A scene file's bad control ends `python -m anisofem solve` with exit status 2 and one
    line naming the file, the key and the problem."""
    import subprocess
    from test_scenefile import scene_file, two_halves
    two_halves(tmp_path)
    text = ('mesh = "bar.msh"\n[regions.stiff]\nfiber = [1, 0, 0]\nfiber_stiffness = 1e5\n'
            '[[boundary]]\nwhere = "base"\nheld = true\n' + control)
    path = scene_file(tmp_path, text)
    done = subprocess.run([sys.executable, "-m", "anisofem", "solve", str(path), "-o",
                           str(tmp_path / "out.vtu")], capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 2
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and re.search(message, lines[0]), done.stderr
