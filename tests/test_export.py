"""export/: ONNX export of the shipped models and the numpy + onnxruntime runtime: parity with
torch, a rollout, determinism, a subprocess without torch and numba, input validation, the CLI
and the committed export/models files."""
import copy
import json
import os
import shutil
import subprocess
import sys

import numpy as np
import onnx
import pytest
import torch

import anisofem
import anisognn
from anisognn.model import with_galerkin
from export import cli, runtime
from export.writers import to_onnx
from export.runtime import OnnxSimulator

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
FIBER = np.array([1.0, 1.0, 0.0]) / np.sqrt(2.0)
KAPPA = 2e5
GRAVITY = (0.0, 0.0, -9.81)


def fan_mesh(spokes=24):
    """A bipyramid fan: a center vertex shared by 2 * spokes tets (in-degree spokes + 2), two
    apexes receiving spokes + 1 edges each."""
    angles = 2 * np.pi * np.arange(spokes) / spokes
    ring = np.stack([0.03 * np.cos(angles), 0.03 * np.sin(angles), np.zeros(spokes)], axis=1)
    vertices = np.vstack([[0, 0, 0], [0, 0, 0.02], [0, 0, -0.02], ring])
    tets = []
    for i in range(spokes):
        a, b = 3 + i, 3 + (i + 1) % spokes
        tets += [[0, a, b, 1], [0, b, a, 2]]
    return anisofem.TetMesh(vertices, np.array(tets), fix_orientation=True)


def box(cells):
    return anisofem.box_beam(size=(0.1, 0.02, 0.02), cells=cells)


def scene_of(mesh, fixed):
    material = anisofem.Material.paper(fiber_direction=FIBER, fiber_stiffness=KAPPA)
    return anisofem.Scene(mesh, material, fixed=fixed, gravity=GRAVITY)


def simulator(path, scene, **kwargs):
    mesh = scene.mesh
    return OnnxSimulator(path, mesh.vertices, mesh.tets, scene.fixed_mask, density=1000.0,
                         fiber_direction=FIBER, fiber_stiffness=KAPPA, **kwargs)


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    """{name: (torch model, onnx path)} for both shipped models and an untrained galerkin one
    (random decoder), exported fresh."""
    folder = tmp_path_factory.mktemp("onnx")
    out = {}
    for name in anisognn.shipped.NAMES:
        net = anisognn.pretrained(name)
        out[name] = net, to_onnx.export(net, str(folder / f"{name}.onnx"))
    torch.manual_seed(0)
    net = anisognn.GraphNet(anisognn.ModelConfig(latent=16, steps=2, galerkin=True))
    out[GALERKIN] = net, to_onnx.export(net, str(folder / "galerkin.onnx"))
    return out


GALERKIN = "galerkin step"


MESHES = {"box 3x2x1 (30 tets)": lambda: (box((3, 2, 1)), "x0"),
          "box 12x3x3 (540 tets)": lambda: (box((12, 3, 3)), "x0"),
          "fan (48 tets, in-degree 26)": lambda: (fan_mesh(), "ring")}


def fixed_for(mesh, which):
    if which == "x0":
        return mesh.vertices[:, 0] < 1e-9
    return np.flatnonzero(np.abs(mesh.vertices[:, 0]) > 0.029)


def states(mesh, count, seed=0):
    """count random states (x, v) around rest: positions perturbed up to 5% of an element."""
    rng = np.random.default_rng(seed)
    for k in range(count):
        x = mesh.vertices + rng.normal(0, 1e-3 * (k + 1), mesh.vertices.shape)
        yield x, rng.normal(0, 0.05, x.shape)


def assert_within_float32_reach(net, sim, scene, count):
    """torch's float32 step and onnxruntime's are close to torch's float64 step over `count`
    states of states(mesh) (within 1e-5 and 1e-4 of the largest acceleration); onnxruntime's
    positions and velocities are the integration of its acceleration."""
    graph = anisognn.from_scene(scene)
    exact = copy.deepcopy(net).double()
    f = scene.external_force
    ort, rounding, scale = 0.0, 0.0, 0.0
    for x, v in states(scene.mesh, count):
        with torch.no_grad():
            a_torch = net(torch.tensor(x), *(torch.tensor(t, dtype=torch.float32)
                                             for t in (v, f)), graph).numpy()
            a_exact = exact(*(torch.tensor(t) for t in (x, v, f)),
                            graph.to(None, torch.float64)).numpy()
        a_ort, x_next, v_next = sim.run(x, v, f)
        ort = max(ort, float(np.abs(a_ort - a_exact).max()))
        rounding = max(rounding, float(np.abs(a_torch - a_exact).max()))
        scale = max(scale, float(np.abs(a_exact).max()))
        free = x + 0.02 * v + 0.02 ** 2 * a_ort.astype(np.float64)
        expected = np.where(scene.fixed_mask, scene.fixed_positions, free)
        np.testing.assert_allclose(x_next, expected, rtol=0, atol=1e-15)
        np.testing.assert_allclose(v_next, (x_next - x) / 0.02, rtol=1e-12, atol=1e-12)
    assert scale > 1e-2
    # float32 from displacements formed in float64 (GraphNet.forward): torch's own float32 step
    # is within 1e-5 of the largest acceleration on AVX2 machines and 2.0e-5 on an AVX-512 one
    # (meshgraphnets, 540 tets; torch's kernels sum in another order there); from float32
    # positions it was up to 1.6e-5 on one state and 3.9e-3 along a rollout's first step;
    # onnxruntime sums in another order, which the second Galerkin pass amplifies on the most
    # distorted states (6e-5)
    assert rounding <= 3e-5 * scale, (rounding, scale)
    assert ort <= 1e-4 * scale, (ort, scale)


@pytest.mark.parametrize("name", anisognn.shipped.NAMES + (GALERKIN,))
@pytest.mark.parametrize("mesh_name", list(MESHES))
def test_parity_with_torch(exported, name, mesh_name):
    net, path = exported[name]
    mesh, which = MESHES[mesh_name]()
    scene = scene_of(mesh, fixed_for(mesh, which))
    assert_within_float32_reach(net, simulator(path, scene), scene, 5)


@pytest.mark.parametrize("name", anisognn.shipped.NAMES)
def test_rollout_matches_torch(exported, name):
    net, path = exported[name]
    mesh = box((7, 3, 2))
    scene = scene_of(mesh, mesh.vertices[:, 0] < 1e-9)
    ours = simulator(path, scene).rollout(200, scene.external_force)
    reference = anisognn.rollout(net, scene, 200)
    displacement = np.abs(reference - reference[0]).max()
    assert displacement > 1e-4
    # about as close to the float64 rollout as torch's own float32 one (with the Galerkin step
    # float32 rounding alone moves a 200-step rollout visibly: the step's direction changes
    # with the rounding), and at least to 1e-4 of the displacement
    exact = anisognn.rollout(copy.deepcopy(net).double(), scene, 200)
    rounding = np.abs(reference - exact).max()
    assert np.abs(ours - exact).max() <= max(1e-4 * displacement, 4 * rounding)


def test_bit_identical_over_20_runs(exported):
    _, path = exported["directional"]
    mesh = fan_mesh(spokes=40)
    scene = scene_of(mesh, fixed_for(mesh, "ring"))
    sim = simulator(path, scene)
    assert sim.constants["incoming"].shape[1] >= 40
    x, v = next(states(mesh, 1))
    first = sim.run(x, v, scene.external_force)
    for _ in range(19):
        again = sim.run(x, v, scene.external_force)
        for a, b in zip(first, again):
            assert a.tobytes() == b.tobytes()


BLOCKER = """
import sys
class Block:
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in ("torch", "numba", "anisofem", "anisognn", "scipy"):
            raise ImportError(f"{name} is blocked in this test")
sys.meta_path.insert(0, Block())
"""


def test_runtime_runs_without_torch_and_numba(exported, tmp_path):
    """The runtime file copied alone next to model.onnx steps a scene in a process where
    importing torch, numba, scipy or this repo's packages fails; same numbers as in-process."""
    _, path = exported["directional"]
    shutil.copy(os.path.join(ROOT, "export", "runtime.py"), tmp_path / "runtime.py")
    shutil.copy(path, tmp_path / "model.onnx")
    mesh = box((4, 2, 2))
    np.savez(tmp_path / "mesh.npz", vertices=mesh.vertices, tets=mesh.tets)
    script = BLOCKER + """
import numpy as np
try:
    import torch
except ImportError:
    pass
else:
    raise SystemExit("torch imported")
from runtime import OnnxSimulator
mesh = np.load("mesh.npz")
sim = OnnxSimulator("model.onnx", mesh["vertices"], mesh["tets"], mesh["vertices"][:, 0] < 1e-9,
                    fiber_direction=(1, 1, 0), fiber_stiffness=2e5)
force = sim.masses[:, None] * np.array([0.0, 0.0, -9.81])
np.save("rollout.npy", sim.rollout(20, force))
assert not any(m in sys.modules for m in ("torch", "numba", "anisofem", "anisognn"))
"""
    env = dict(os.environ, PYTHONPATH="")
    done = subprocess.run([sys.executable, "-c", script], cwd=tmp_path, env=env,
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    theirs = np.load(tmp_path / "rollout.npy")
    scene = scene_of(mesh, mesh.vertices[:, 0] < 1e-9)
    ours = simulator(path, scene).rollout(20, scene.external_force)
    assert np.abs(theirs[-1] - theirs[0]).max() > 1e-6
    np.testing.assert_allclose(theirs, ours, rtol=0, atol=1e-12)


def test_metadata(exported):
    net, path = exported["meshgraphnets"]
    meta = {p.key: p.value for p in onnx.load(path).metadata_props}
    assert meta["format"] == runtime.FORMAT
    assert json.loads(meta["config"]) == net.config.to_dict()
    assert meta["aggregation"] == "sum"
    assert float(meta["dt"]) == net.config.dt
    assert "m/s^2" in meta["units"] and meta["version"]
    assert json.loads(meta["trained_material"])["young"] == 1e5


def test_simulator_reports_masses_and_dt(exported):
    _, path = exported["directional"]
    mesh = box((4, 2, 2))
    scene = scene_of(mesh, mesh.vertices[:, 0] < 1e-9)
    sim = simulator(path, scene)
    np.testing.assert_allclose(sim.masses, scene.masses, rtol=1e-12)
    np.testing.assert_allclose(sim.masses[:, None] * GRAVITY, scene.external_force, rtol=1e-12,
                               atol=1e-18)
    assert sim.dt == 0.02
    assert np.array_equal(sim.fixed, scene.fixed_mask)


@pytest.mark.parametrize("change, field", [
    (dict(vertices=np.zeros((4, 2))), "vertices: expected shape"),
    (dict(vertices=np.full((16, 3), np.nan)), "vertices: contains NaN"),
    (dict(tets=np.array([[0, 1, 2, 99]])), "tets: vertex index out of range"),
    (dict(tets=np.array([[0, 1, 2, 2]])), "tets: 1 tet(s) have zero volume"),
    (dict(tets=np.zeros((2, 4))), "tets: expected integer"),
    (dict(fixed=np.array([0, 500])), "fixed: vertex index out of range"),
    (dict(fixed=np.ones(7, dtype=bool)), "fixed: a bool mask must have shape"),
    (dict(density=-1.0), "density: must be > 0"),
    (dict(fiber_direction=None), "fiber_direction: required"),
    (dict(fiber_direction=(0, 0, 0)), "fiber_direction: a direction has zero length"),
    (dict(fiber_stiffness=np.ones(3)), "fiber_stiffness: expected shape"),
])
def test_simulator_rejects_bad_input(exported, change, field):
    _, path = exported["directional"]
    mesh = box((1, 1, 1))
    args = dict(vertices=mesh.vertices, tets=mesh.tets, fixed=None, density=1000.0,
                fiber_direction=(1, 0, 0), fiber_stiffness=1e5)
    args.update(change)
    with pytest.raises((ValueError, TypeError), match=field.replace("(", r"\(").replace(")", r"\)")):
        OnnxSimulator(path, **args)


def test_step_rejects_bad_state(exported):
    _, path = exported["directional"]
    mesh = box((1, 1, 1))
    sim = OnnxSimulator(path, mesh.vertices, mesh.tets)
    x, v = mesh.vertices, np.zeros_like(mesh.vertices)
    with pytest.raises(ValueError, match=r"velocities: expected shape \(8, 3\)"):
        sim.step(x, v[:3], v)
    with pytest.raises(ValueError, match="external_force: contains NaN"):
        sim.step(x, v, np.full_like(v, np.nan))
    with pytest.raises(TypeError, match="positions: expected real numbers"):
        sim.step(x.astype(str), v, v)


def test_simulator_rejects_a_foreign_onnx_file(tmp_path):
    h = onnx.helper
    graph = h.make_graph([h.make_node("Identity", ["positions"], ["y"])], "other",
                         [h.make_tensor_value_info("positions", onnx.TensorProto.DOUBLE, [1])],
                         [h.make_tensor_value_info("y", onnx.TensorProto.DOUBLE, [1])])
    onnx.save(h.make_model(graph, opset_imports=[h.make_opsetid("", 17)], ir_version=8),
              str(tmp_path / "other.onnx"))
    mesh = box((1, 1, 1))
    with pytest.raises(ValueError, match="model_path: .* not an anisognn step model"):
        OnnxSimulator(tmp_path / "other.onnx", mesh.vertices, mesh.tets)
    (tmp_path / "broken.onnx").write_bytes(b"not a model")
    with pytest.raises(ValueError, match="model_path: onnxruntime cannot load"):
        OnnxSimulator(tmp_path / "broken.onnx", mesh.vertices, mesh.tets)
    with pytest.raises(FileNotFoundError, match="model_path: no such file"):
        OnnxSimulator(tmp_path / "missing.onnx", mesh.vertices, mesh.tets)


def test_cli_exports_a_checkpoint_and_a_shipped_name(tmp_path, capsys):
    source = anisognn.shipped.path("directional")
    cli.main([source, "-o", str(tmp_path / "a.onnx")])
    cli.main(["directional", "-o", str(tmp_path / "b.onnx")])
    latent = anisognn.pretrained("directional").config.latent
    assert f"directional aggregation, {latent} wide" in capsys.readouterr().out
    assert (tmp_path / "a.onnx").read_bytes() == (tmp_path / "b.onnx").read_bytes()
    with pytest.raises(SystemExit) as ended:
        cli.main([str(tmp_path / "missing.pt"), "-o", str(tmp_path / "c.onnx")])
    assert ended.value.code == 2
    assert "python -m export: error: checkpoint: no such file" in capsys.readouterr().err


def test_cli_galerkin_flags_choose_how_the_exported_model_steps(tmp_path, capsys):
    """--galerkin-passes 1 exports the shipped network with one pass (faster, less accurate),
    --galerkin off the network alone, --cg-iterations 5 its step followed by five
    conjugate-gradient iterations; each file steps like the torch model it names."""
    shipped = anisognn.pretrained("directional")
    assert shipped.config.galerkin and shipped.config.galerkin_passes == 2
    mesh = box((5, 2, 2))
    scene = scene_of(mesh, mesh.vertices[:, 0] < 1e-9)
    (x, v), = states(mesh, 1)
    steps = {}
    for flags, said, net in ((["--galerkin-passes", "1"], "1 Galerkin pass,",
                              with_galerkin(shipped, True, 1)),
                             (["--galerkin", "off"], "no Galerkin step",
                              with_galerkin(shipped, False)),
                             (["--cg-iterations", "5"], "2 Galerkin passes, 5 CG iterations",
                              with_galerkin(shipped, True, None, 5)),
                             ([], "2 Galerkin passes", shipped)):
        path = str(tmp_path / f"{len(steps)}.onnx")
        cli.main(["directional", "-o", path] + flags)
        assert said in capsys.readouterr().out
        sim = simulator(path, scene)
        assert_within_float32_reach(net, sim, scene, 1)
        steps[said] = sim.run(x, v, scene.external_force)[0]
    one, two = steps["1 Galerkin pass,"], steps["2 Galerkin passes"]
    assert np.abs(one - two).max() > 1e-3 * np.abs(two).max()
    assert np.abs(steps["2 Galerkin passes, 5 CG iterations"] - two).max() > 1e-3 * np.abs(
        two).max()
    for flags, error in ((["--galerkin", "off", "--galerkin-passes", "2"], "--galerkin-passes"),
                         (["--galerkin-passes", "0"], "galerkin_passes: must be an integer >= 1"),
                         (["--cg-iterations", "-1"], "--cg-iterations: expected an integer")):
        with pytest.raises(SystemExit) as ended:
            cli.main(["directional", "-o", str(tmp_path / "bad.onnx")] + flags)
        assert ended.value.code == 2 and error in capsys.readouterr().err


@pytest.mark.parametrize("name", anisognn.shipped.NAMES)
def test_committed_models_are_the_shipped_ones(name):
    """export/models/NAME.onnx steps like the shipped torch model (re-export when it changes:
    python -m export NAME -o export/models/NAME.onnx)."""
    path = os.path.join(ROOT, "export", "models", f"{name}.onnx")
    mesh = box((5, 2, 2))
    scene = scene_of(mesh, mesh.vertices[:, 0] < 1e-9)
    assert_within_float32_reach(anisognn.pretrained(name), simulator(path, scene), scene, 2)


def test_onnx_example_draws_the_cantilever(tmp_path):
    script = os.path.join(ROOT, "examples", "onnx_cantilever.py")
    done = subprocess.run([sys.executable, "-c", BLOCKER + f"import runpy; runpy.run_path({script!r}, run_name='__main__')"],
                          cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "240 tets" in done.stdout
    assert (tmp_path / "out" / "onnx_cantilever.png").stat().st_size > 10_000


def test_the_runtime_tells_inverted_tets_from_rest_and_flipped_ones(exported):
    mesh = box((3, 2, 1))
    scene = scene_of(mesh, fixed_for(mesh, "x0"))
    sim = simulator(exported["directional"][1], scene)
    assert sim.inversion(mesh.vertices) == (0, pytest.approx(1.0))
    x = mesh.vertices.copy()
    x[:, 2] *= -1.0  # mirror: every tet turned inside out
    count, smallest = sim.inversion(x)
    assert count == mesh.n_tets and smallest == pytest.approx(-1.0)
