"""Baked scenes (python -m export bake): the arrays file format an engine reads without numpy,
the boundary triangles a viewer draws, and the scenes the browser page steps."""
import json
import os

import numpy as np
import pytest

import anisofem
from export.writers import bake
from export import cli, runtime

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
MODEL = os.path.join(ROOT, "export", "models", "directional.onnx")


def test_arrays_round_trip_byte_exact_with_aligned_offsets(tmp_path):
    rng = np.random.default_rng(0)
    arrays = {"a": rng.normal(size=(5, 3)), "b": rng.normal(size=7).astype(np.float32),
              "c": np.arange(11, dtype=np.int64).reshape(11, 1), "d": np.arange(3, dtype=np.int32),
              "e": np.array([1, 0, 1], dtype=np.uint8), "empty": np.zeros((0, 4))}
    bake.write_arrays(tmp_path / "s", arrays, {"note": "x"})
    header, back = runtime.read_arrays(tmp_path / "s")
    assert header["note"] == "x" and header["bin"] == "s.bin"
    for name, value in arrays.items():
        assert back[name].dtype == value.dtype and back[name].shape == value.shape
        np.testing.assert_array_equal(back[name], value)
        assert header["arrays"][name]["offset"] % 8 == 0
    # what a reader without numpy does: the bytes at the offset, little-endian
    raw = (tmp_path / "s.bin").read_bytes()
    spec = header["arrays"]["a"]
    assert np.frombuffer(raw, "<f8", 15, spec["offset"]).tolist() == arrays["a"].ravel().tolist()
    assert not [p for p in os.listdir(tmp_path) if ".tmp" in p]


def test_arrays_refuse_bad_input(tmp_path):
    with pytest.raises(TypeError, match=r"arrays\['flags'\]: dtype bool"):
        bake.write_arrays(tmp_path / "s", {"flags": np.zeros(3, bool)})
    (tmp_path / "t.json").write_text(json.dumps({"format": "other"}))
    with pytest.raises(ValueError, match="not an 'anisognn-arrays-1' header"):
        runtime.read_arrays(tmp_path / "t")


@pytest.mark.parametrize("make", [lambda: anisofem.box_beam(cells=(4, 2, 3)),
                                  lambda: anisofem.cylinder_beam(0.1, 0.01, 4, 2, 1),
                                  lambda: anisofem.y_shape()], ids=["box", "cylinder", "y"])
def test_surface_is_closed_and_faces_outward(make):
    mesh = make()
    faces = runtime.surface_triangles(mesh.vertices, mesh.tets)
    # closed: every edge of the surface borders exactly two triangles, once in each direction
    directed = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    assert len({tuple(e) for e in directed.tolist()}) == len(directed)
    reverse = {tuple(e) for e in directed[:, ::-1].tolist()}
    assert reverse == {tuple(e) for e in directed.tolist()}
    # outward: the divergence theorem gives the mesh's volume from the oriented faces
    x0, x1, x2 = (mesh.vertices[faces[:, i]] for i in range(3))
    volume = np.einsum("ij,ij->i", x0, np.cross(x1, x2)).sum() / 6.0
    np.testing.assert_allclose(volume, runtime.tet_volumes(mesh.vertices, mesh.tets).sum(),
                               rtol=1e-12)


def test_a_baked_scene_holds_runtimes_constants_for_each_angle(tmp_path):
    header = bake.bake("cantilever", tmp_path / "c", MODEL, angles=[0, 60])
    again, arrays = runtime.read_arrays(tmp_path / "c")
    assert again == json.loads((tmp_path / "c.json").read_text()) and header["n"] == 99
    assert header["fiber_angles"] == [0.0, 60.0] and header["dt"] == 0.02
    vertices, tets, held = bake.scene_mesh("cantilever")
    for angle in (0, 60):
        sim = runtime.OnnxSimulator(MODEL, vertices, tets, fixed=held,
                                    fiber_direction=bake.fiber_direction(angle),
                                    fiber_stiffness=1e5)
        for name, value in sim.constants.items():
            key = f"{name}@{angle}" if name in bake.FIBER_INPUTS else name
            np.testing.assert_array_equal(arrays[key], value)
    np.testing.assert_array_equal(arrays["held"].astype(bool), held)
    assert arrays["surface"].dtype == np.int32 and arrays["surface"].max() < header["n"]


def test_bake_command_and_its_errors(tmp_path, capsys):
    cli.main(["bake", "t", "-o", str(tmp_path / "t"), "--model", MODEL, "--angles", "30"])
    assert "T, 0.1 m wide" in capsys.readouterr().out
    assert runtime.read_arrays(tmp_path / "t")[0]["fiber_angles"] == [30.0]
    with pytest.raises(SystemExit) as ended:
        cli.main(["bake", "y", "-o", str(tmp_path / "y"), "--model", str(tmp_path / "no.onnx")])
    assert ended.value.code == 2
    assert "python -m export bake: error: model: no such file" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        cli.main(["bake", "sphere", "-o", str(tmp_path / "s")])
