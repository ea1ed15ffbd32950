"""Bad input gets a ValueError or TypeError naming the field and the problem."""
import warnings

import numpy as np
import pytest

import anisofem as af

X = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1]])
T = np.array([[0, 1, 2, 3], [1, 2, 3, 4]])


def test_valid_mesh_is_accepted():
    mesh = af.TetMesh(X, T)
    assert mesh.n_tets == 2 and (mesh.rest_volumes > 0).all()


@pytest.mark.parametrize("vertices,tets,error,match", [
    (np.vstack([X[:3], [0.5, 0.5, 0]]), [[0, 1, 2, 3]], ValueError, "zero rest volume"),
    (X, [[0, 1, 1, 3]], ValueError, "repeat a vertex"),
    (X, [[0, 1, 2, 7]], ValueError, "out of range"),
    (X, [[0, 1, 2, -1]], ValueError, "out of range"),
    (X, [[0, 1, 2, 3], [1, 0, 3, 2]], ValueError, "duplicate"),
    (X, [[0, 1, 2]], ValueError, r"tets: expected \(m, 4\) linear or \(m, 10\) quadratic"),
    (X[:, :2], T, ValueError, r"vertices: expected shape \(\*, 3\)"),
    (X, T.astype(float), TypeError, "tets: expected an integer array"),
    (X.astype(str), T, TypeError, "vertices"),
    (np.where(np.eye(5, 3) > 0, np.nan, X), T, ValueError, "vertices: contains NaN"),
    (np.where(np.eye(5, 3) > 0, np.inf, X), T, ValueError, "vertices: contains NaN or inf"),
    (X, np.zeros((0, 4), int), ValueError, "no tetrahedra"),
])
@pytest.mark.filterwarnings("ignore:vertices.*used by no tet")  # one-tet meshes of X
def test_bad_meshes(vertices, tets, error, match):
    with pytest.raises(error, match=match):
        af.TetMesh(vertices, tets)


def test_inverted_tets_are_reoriented_unless_refused():
    with pytest.raises(ValueError, match="inverted"):
        af.TetMesh(X, [[0, 2, 1, 3]], fix_orientation=False, unreferenced="drop")
    mesh = af.TetMesh(X, [[0, 2, 1, 3]], unreferenced="drop")
    assert mesh.rest_volumes[0] > 0


def test_unreferenced_vertices_warn_drop_or_error():
    with pytest.warns(UserWarning, match="used by no tet"):
        mesh = af.TetMesh(X, T[:1])
    scene = af.Scene(mesh, fixed=[0, 1, 2])
    assert scene.fixed_mask[4].all()  # held in place
    assert af.solve(scene).converged
    dropped = af.TetMesh(X, T[:1], unreferenced="drop")
    assert dropped.n_vertices == 4 and dropped.kept_vertices.tolist() == [0, 1, 2, 3]
    with pytest.raises(ValueError, match="used by no tet"):
        af.TetMesh(X, T[:1], unreferenced="error")
    with pytest.raises(ValueError, match="unreferenced"):
        af.TetMesh(X, T[:1], unreferenced="ignore")


@pytest.mark.parametrize("kwargs,error,match", [
    ({"young": 0.0}, ValueError, "young"),
    ({"young": -1.0}, ValueError, "young"),
    ({"poisson": 0.5}, ValueError, "poisson"),
    ({"poisson": 0.6}, ValueError, "poisson"),
    ({"poisson": -1.0}, ValueError, "poisson"),
    ({"density": 0.0}, ValueError, "density"),
    ({"density": -5.0}, ValueError, "density"),
    ({"fiber_stiffness": -1.0}, ValueError, "fiber_stiffness"),
    ({"fiber_stiffness": 1.0, "fiber_direction": (1.0, 1.0, 0.0)}, ValueError, "not unit"),
    ({"fiber_stiffness": 1.0, "fiber_direction": (0.0, 0.0, 0.0)}, ValueError, "zero"),
    ({"fiber_direction": (1.0, 0.0)}, ValueError, "fiber_direction: expected shape"),
    ({"young": np.nan}, ValueError, "young: must be finite, got nan"),
    ({"fiber_stiffness": np.inf}, ValueError, "fiber_stiffness: must be finite, got inf"),
    ({"young": "soft"}, TypeError, "young"),
    ({"fiber_stiffness": [1.0, 1.0], "fiber_direction": [[1, 0, 0]] * 3}, ValueError,
     "different lengths"),
])
def test_bad_materials(kwargs, error, match):
    with pytest.raises(error, match=match):
        af.Material(**kwargs)


def test_zero_fiber_direction_is_fine_without_fibers():
    af.Material(fiber_direction=(0, 0, 0), fiber_stiffness=0.0)
    af.Material(fiber_direction=[[0, 0, 0], [1, 0, 0]], fiber_stiffness=[0.0, 1.0])


@pytest.fixture
def mesh():
    return af.box_beam(cells=(2, 2, 2))


@pytest.mark.parametrize("kwargs,error,match", [
    ({"fixed": [0, 99]}, ValueError, "fixed: vertex index out of range"),
    ({"fixed": [0, 0]}, ValueError, "fixed: repeated"),
    ({"fixed": [0.0, 1.0]}, TypeError, "fixed: expected an integer array"),
    ({"fixed": np.ones(5, bool)}, ValueError, "fixed: a bool mask must have shape"),
    ({"fixed": [0], "fixed_positions": np.zeros((2, 3))}, ValueError, "fixed_positions"),
    ({"fixed": [0], "fixed_positions": [[np.nan, 0, 0]]}, ValueError, "fixed_positions: "
     "contains NaN"),
    ({"gravity": (0, -9.81)}, ValueError, "gravity: expected shape"),
    ({"body_force": np.ones((3, 3))}, ValueError, "body_force"),
    ({"body_force": (0, 0, np.inf)}, ValueError, "body_force: contains NaN"),
    ({"nodal_force": np.ones((3, 3))}, ValueError, "nodal_force: expected shape"),
    ({"traction": (0, 0, 1.0)}, ValueError, "traction, traction_faces"),
    ({"traction": (0, 0, 1.0), "traction_faces": [[0, 1, 2]]}, ValueError,
     "not a boundary face"),
])
def test_bad_scenes(mesh, kwargs, error, match):
    with pytest.raises(error, match=match):
        af.Scene(mesh, **kwargs)


def test_scene_type_checks(mesh):
    with pytest.raises(TypeError, match="mesh"):
        af.Scene(np.zeros((4, 3)))
    with pytest.raises(TypeError, match="material"):
        af.Scene(mesh, material={"young": 1e5})


def test_per_element_material_must_match_the_mesh(mesh):
    with pytest.raises(ValueError, match=r"young: expected a scalar or shape \(40,\)"):
        af.Scene(mesh, af.Material(young=np.full(7, 1e5)))


def test_static_scene_without_fixed_vertices(mesh):
    with pytest.raises(ValueError, match="fixed: a static scene needs fixed vertices"):
        af.solve(af.Scene(mesh, gravity=(0, 0, -9.81)))
    roller = np.zeros((mesh.n_vertices, 3), bool)
    roller[:, 2] = True  # z held everywhere, x and y free: rigid translation
    with pytest.raises(ValueError, match="axis"):
        af.solve(af.Scene(mesh, fixed=roller))


def test_bad_states_and_steps(mesh):
    scene = af.default_scene(mesh)
    x = scene.initial_positions()
    v = np.zeros_like(x)
    bad = x.copy()
    bad[3, 1] = np.nan
    with pytest.raises(ValueError, match="x: contains NaN"):
        af.energy(scene, bad)
    with pytest.raises(ValueError, match="x: expected shape"):
        af.gradient(scene, x[:-1])
    with pytest.raises(ValueError, match="v: contains NaN"):
        af.step(scene, x, bad, 0.02)
    for dt in (0.0, -0.01):
        with pytest.raises(ValueError, match="dt: the time step must be > 0"):
            af.step(scene, x, v, dt)
    with pytest.raises(ValueError, match="dt: must be finite"):
        af.step(scene, x, v, np.nan)
    with pytest.raises(ValueError, match="x_hat, dt: give both"):
        af.energy(scene, x, x_hat=x)
    with pytest.raises(ValueError, match="linear_solver"):
        af.solve(scene, linear_solver="magic")
    with pytest.raises(ValueError, match="projection"):
        af.solve(scene, projection="sometimes")
    with pytest.raises(TypeError, match="scene"):
        af.solve("beam.msh")


def test_non_convergence_is_never_success(mesh):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", af.ConvergenceWarning)
        result = af.solve(af.default_scene(mesh), max_iter=1)
        roll = af.simulate(af.default_scene(mesh), steps=3, max_iter=0)
    assert not result.converged and np.isfinite(result.x).all()
    assert not roll.converged and roll.positions.shape[0] == 1


def test_library_boundaries_name_the_users_input(tmp_path):
    mesh = af.box_beam(cells=(2, 1, 1))
    assert not af.Scene(mesh, fixed=[]).fixed_mask[mesh.vertices[:, 0] < 1e-9].any()
    with pytest.raises(TypeError, match="steps: expected a whole number, got 2.5"):
        af.simulate(af.default_scene(mesh), steps=2.5)
    with pytest.raises(TypeError, match="bogus: not an option of method 'auto'"):
        af.solve(af.default_scene(mesh), bogus=3)
    af.write_mesh(tmp_path / "made" / "here" / "o.vtu", mesh)  # the folder is made
    assert (tmp_path / "made" / "here" / "o.vtu").exists()
    (tmp_path / "afile").write_text("")
    with pytest.raises(FileNotFoundError, match="the folder of .*afile.* cannot be made"):
        af.write_mesh(tmp_path / "afile" / "o.vtu", mesh)
    with pytest.raises(ValueError, match="has no mesh format"):
        af.write_mesh(tmp_path / "o.txt", mesh)
    (tmp_path / "empty.msh").write_text("")
    with pytest.raises(ValueError, match="path: meshio cannot read"):
        af.read_mesh(tmp_path / "empty.msh")
    with pytest.raises(FileNotFoundError, match="path: no such mesh file"):
        af.read_mesh(tmp_path / "missing.msh")
