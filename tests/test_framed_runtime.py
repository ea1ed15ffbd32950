"""The framed model written by export.writers.reduced.write_framed and stepped by
framed_runtime.FramedSimulator (numpy only) moves like the library's FramedModel, refuses
another file and another mesh, and `python -m export reduced --framed` writes it."""
import json

import numpy as np
import pytest

import anisofem as af
from anisofem.reduced import Drag, FramedModel, Loads
from export.writers import reduced as writer
from export import cli
from export.cli import main
from export.framed_runtime import FRAMED_FORMAT, FramedSimulator
from export.runtime import ReducedSimulator
from test_framed_model import beam_scene, cubature_model, swung_base, t_scene  # noqa: F401


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    scene = t_scene()
    model = FramedModel(scene, validate=False)
    path = str(tmp_path_factory.mktemp("framed") / "t")
    writer.write_framed(model, path, "t", gravity=scene.gravity)
    return scene, model, path


def rollouts(scene, model, sim, steps, drag, base=None):
    """Largest position difference between the library's and the runtime's rollouts (the drag
    for the first half, then released; the held nodes at base(k) (3, 4) at step k where
    given) over the largest displacement; the Newton iterations of each, per step."""
    now = before = model.rest()
    a = b = sim.rest_state()
    worst = size = 0.0
    iterations = []
    for k in range(steps):
        extra = drag if k < steps // 2 else np.zeros_like(drag)
        at = None if base is None else base(k + 1)
        after, report = model.step(now, before, 0.02, force=extra, base=at)
        assert report.converged
        now, before = after, now
        a, b = sim.step(a, b, scene.external_force + extra, 0.02, base=at), a
        iterations.append((report.iterations, sim.iterations))
        x = model.positions(now)
        worst = max(worst, np.abs(x - sim.positions(a)).max())
        size = max(size, np.abs(x - scene.mesh.vertices).max())
    return worst / size, iterations


def arm_drag(scene, share=0.5):
    """A sideways drag of `share` of the body's weight at the tip of the T's +x arm."""
    force = np.zeros((scene.mesh.n_vertices, 3))
    force[int(np.argmax(scene.mesh.vertices[:, 0])), 1] = share * scene.masses.sum() * 9.81
    return force


def test_runtime_steps_like_the_library(written):
    """100 steps (a drag of half the weight at an arm's tip, then released): the same
    iterations, positions within 1e-9 of the largest displacement."""
    scene, model, path = written
    error, iterations = rollouts(scene, model, FramedSimulator(path), 100, arm_drag(scene))
    assert error < 1e-9
    assert all(a == b for a, b in iterations)


def test_runtime_follows_a_moving_base_like_the_library(written):
    """The T's foot turned and moved (test_framed_model.swung_base) while an arm is dragged:
    the same iterations, within 1e-9 of the largest displacement; a base that is not a rigid
    motion is refused."""
    scene, model, path = written
    sim = FramedSimulator(path)
    error, iterations = rollouts(scene, model, sim, 40, arm_drag(scene), swung_base)
    assert error < 1e-9 and all(a == b for a, b in iterations)
    now = sim.rest_state()
    with pytest.raises(ValueError, match="base: its first 3 columns must be a rotation"):
        sim.step(now, now, scene.external_force, 0.02, base=np.ones((3, 4)))


def test_runtime_steps_quadratic_tets_with_fibers_like_the_library(tmp_path):
    """10-node tets (4 quadrature points) and stiff fibers in the joints."""
    scene = beam_scene(order=2, kappa=1e6, cells=(3, 1, 1))
    tip = tuple(int(i) for i in af.metrics.end_vertices(scene.mesh, 0, "max"))
    model = FramedModel(scene, bands=2, coordinates=6, validate=False,
                        loads=Loads(drags=(Drag(tip, 0.05, directions=((0.0, 1.0, 0.0),)),)))
    writer.write_framed(model, str(tmp_path / "beam"))
    drag = np.zeros((scene.mesh.n_vertices, 3))
    drag[list(tip), 1] = 0.05 / len(tip)
    error, _ = rollouts(scene, model, FramedSimulator(str(tmp_path / "beam")), 20, drag)
    assert error < 1e-9


@pytest.fixture(scope="module")
def cubature_written(tmp_path_factory, cubature_model):
    """The beam's framed model with a cubature of its joints (test_framed_model), written."""
    model = cubature_model[0]
    path = str(tmp_path_factory.mktemp("cubature") / "beam")
    header = writer.write_framed(model, path, "beam", gravity=model.scene.gravity)
    return model, path, header


def tip_drag(scene, share=0.5):
    """A sideways drag of `share` of the body's weight spread over the tip of a beam along x."""
    tip = af.metrics.end_vertices(scene.mesh, 0, "max")
    force = np.zeros((scene.mesh.n_vertices, 3))
    force[tip, 1] = share * scene.masses.sum() * 9.81 / tip.size
    return force


def test_runtime_steps_a_joint_cubature_like_the_library(cubature_written):
    """The cubature is written as its elements, their weights folded into their volumes: the
    file holds those and says of how many, and the runtime steps it as the library does."""
    model, path, header = cubature_written
    assert header["joint_elements"] == len(model.cubature.elements) < header["joint_layer"]
    assert cli._cubature(header) == " (a cubature of its 320)"
    error, iterations = rollouts(model.scene, model, FramedSimulator(path), 40,
                                 tip_drag(model.scene))
    assert error < 1e-9
    assert all(a == b for a, b in iterations)


def test_header_holds_the_model_and_its_validation(tmp_path):
    scene = t_scene()
    model = FramedModel(scene)
    header = writer.write_framed(model, str(tmp_path / "t"), "t")
    saved = json.load(open(tmp_path / "t.json"))
    assert saved["model_format"] == header["model_format"] == FRAMED_FORMAT
    assert saved["domains"] == len(model.domains) == 5 and saved["unknowns"] == model.r
    assert saved["validation"]["tip_error"] == pytest.approx(model.validation.tip_error)


def test_runtimes_refuse_each_others_files_and_another_mesh(written, tmp_path):
    scene, _, path = written
    with pytest.raises(ValueError, match=r"holds no framed model .*rebuild it with "
                                         r"`python -m export reduced SCENE --framed"):
        FramedSimulator(_linear_file(tmp_path))
    with pytest.raises(ValueError, match="holds no reduced model"):
        ReducedSimulator(path)
    other = scene.mesh.vertices.copy()
    other[0] += 1e-3
    with pytest.raises(ValueError, match="vertices"):
        FramedSimulator(path, vertices=other, tets=scene.mesh.tets)
    sim = FramedSimulator(path)
    now = sim.rest_state()
    with pytest.raises(ValueError, match="force"):
        sim.step(now, now, np.full((scene.mesh.n_vertices, 3), np.nan), 0.02)
    with pytest.raises(ValueError, match="dt"):
        sim.step(now, now, scene.external_force, 0.0)


def _linear_file(tmp_path):
    from anisofem.reduced import ReducedModel
    path = str(tmp_path / "linear")
    writer.write(ReducedModel(t_scene(), modes=2, validate=False), path)
    return path


@pytest.fixture(scope="module")
def displayed(tmp_path_factory):
    """A 0.2 m beam's framed model (320 tets) written for a coarser mesh of the same box whose
    vertices are not the model's: (scene, model, display TetMesh, path)."""
    fine = af.box_beam(size=(0.2, 0.02, 0.02), cells=(16, 2, 2))
    shown = af.box_beam(size=(0.2, 0.02, 0.02), cells=(5, 1, 1))
    scene = af.Scene(fine, af.Material(1e5, 0.48, 1000.0),
                     fixed=af.metrics.end_vertices(fine, 0, "min"), gravity=(0, 0, -9.81))
    model = FramedModel(scene, validate=False)
    path = str(tmp_path_factory.mktemp("display") / "beam")
    writer.write_framed(model, path, display=shown)
    return scene, model, shown, path


def test_a_display_mesh_moves_as_the_model_nodes_it_is_drawn_from(displayed):
    """Each display vertex a weighted sum of the model's nodes that reproduces its rest place
    (some across two domains); a drag at the display's tip and gravity on its masses, then
    released: the runtime against the library under the same forces spread on those nodes,
    interpolated likewise, within 1e-9 of the largest displacement, the same iterations."""
    scene, model, shown, path = displayed
    sim = FramedSimulator(path, shown.vertices, shown.tets)
    nodes, weights = sim._display
    assert np.allclose(weights.sum(axis=1), 1.0)
    assert np.abs(np.einsum("pk,pka->pa", weights, scene.mesh.vertices[nodes])
                  - shown.vertices).max() < 1e-12
    weighs = np.abs(weights) > 1e-12
    labels = np.where(weighs, model.labels[nodes], -2)
    assert any(len(set(row) - {-2}) > 1 for row in labels)         # across a joint
    assert abs(sim.masses.sum() - scene.masses.sum()) < 1e-12 * scene.masses.sum()
    drag = np.zeros((shown.n_vertices, 3))
    drag[np.argmax(shown.vertices[:, 0]), 1] = 0.5 * scene.masses.sum() * 9.81
    gravity = sim.masses[:, None] * np.array([0.0, 0.0, -9.81])

    def spread(f):
        out = np.zeros((scene.mesh.n_vertices, 3))
        np.add.at(out, nodes, weights[:, :, None] * f[:, None, :])
        return out
    now = before = model.rest()
    a = b = sim.rest_state()
    worst = size = 0.0
    for k in range(40):
        f = gravity + (drag if k < 20 else 0.0)
        after, report = model.step(now, before, 0.02, force=spread(f) - scene.external_force)
        now, before = after, now
        a, b = sim.step(a, b, f, 0.02), a
        assert sim.iterations == report.iterations
        expected = np.einsum("pk,pka->pa", weights, model.positions(now)[nodes])
        worst = max(worst, np.abs(sim.positions(a) - expected).max())
        size = max(size, np.abs(expected - shown.vertices).max())
    assert size > 0.02 and worst < 1e-9 * size


def test_command_writes_a_framed_model_for_a_display_mesh(tmp_path, capsys):
    shown = tmp_path / "coarse.vtu"
    af.write_mesh(str(shown), af.box_beam(cells=(3, 1, 1)))
    out = str(tmp_path / "beam")
    main(["reduced", "box", "--cells", "10", "2", "2", "--framed", "--display", str(shown),
          "-o", out])
    assert "16 vertices, 15 tets" in capsys.readouterr().out
    sim = FramedSimulator(out)
    now = sim.rest_state()
    x = sim.positions(sim.step(now, now, sim.masses[:, None] * (0.0, 0.0, -9.81), 0.02))
    assert x.shape == (16, 3) and (x[:, 2] < sim.rest_positions[:, 2] - 1e-9).any()


def test_command_writes_a_framed_model_and_refuses_the_linear_models_flags(tmp_path, capsys):
    out = str(tmp_path / "t")
    main(["reduced", "t", "--fixed", "z-min", "--framed", "-o", out])
    said = capsys.readouterr().out
    assert "5 domains" in said and "off the full FEM on 3 unseen loads" in said
    sim = FramedSimulator(out)
    now = sim.rest_state()
    x = sim.positions(sim.step(now, now, sim.masses[:, None] * (0.0, 0.0, -9.81), 0.02))
    assert np.isfinite(x).all() and (x[:, 2] < sim.rest_positions[:, 2] - 1e-9).any()
    with pytest.raises(SystemExit) as stop:
        main(["reduced", "t", "--framed", "--snapshots", "4", "-o", out])
    assert stop.value.code == 2
    assert "--framed" in capsys.readouterr().err


def test_bake_command_writes_the_framed_models_per_fiber_angle(tmp_path, capsys):
    out = str(tmp_path / "t-reduced")
    main(["bake-reduced", "t", "--framed", "--angles", "45", "-o", out])
    assert "5 framed domains" in capsys.readouterr().out
    with pytest.raises(ValueError, match="fiber angles"):
        FramedSimulator(out)
    sim = FramedSimulator(out, angle=45)
    assert sim.header["validation"][0]["tip_error"] < 0.02
    now = sim.rest_state()
    after = sim.step(now, now, sim.masses[:, None] * np.asarray(sim.header["gravity"]),
                     sim.header["dt"])
    assert np.isfinite(sim.positions(after)).all()


def test_bench_row_measures_the_framed_model(tmp_path):
    from export.benches import reduced as bench_reduced
    from export import native
    lib = native.build(str(tmp_path / "c")) if native.compiler() else None
    row = bench_reduced.measure_framed((6, 1, 1), str(tmp_path), lib=lib)
    assert row["tets"] == 30 and row["snapshots"] == "framed" and row["validation_cases"] == 3
    assert row["library_ms"] > 0 and row["runtime_ms"] > 0 and (lib is None or row["c_ms"] > 0)
    assert 0 <= row["tip_error"] < 0.5
