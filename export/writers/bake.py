"""`python -m export bake`: the constant tensors of a scene, written for an engine that steps
model.onnx without numpy (write_arrays: a JSON header and raw little-endian arrays;
export/README.md, Baked scenes).

A baked scene holds every constant model input (runtime.INPUTS, in its dtype), for each fiber
angle asked the two fiber-dependent ones ("fiber@A", "tet_fiber@A" for A degrees from the x
axis towards z), and what a viewer needs: the boundary triangles ("surface", int32), the
vertex masses ("masses", kg) and the held vertices ("held", uint8 per component). The header
says the model's dt, the counts n (vertices), m (tets), E (directed edges), the fiber angles,
gravity and the material the model was trained on.
"""
import json
import math
import os

import numpy as np

import anisofem
from anisofem.physics import metrics
from anisofem.io.output import atomic_path
from anisofem.physics.scene import GRAVITY

from .. import runtime

#: the scenes `bake` knows: name -> (title, mesh maker, held end (axis, side))
SCENES = {
    "cantilever": ("box cantilever, 0.1 x 0.02 x 0.02 m, 200 tets", "box", (0, "min")),
    "cylinder": ("cylinder cantilever, 0.1 m long, 1 cm radius", "cylinder", (0, "min")),
    "t": ("T, 0.1 m wide, standing on its stem", "t", (2, "min")),
    "y": ("Y, arms raised 35 degrees, standing on its stem", "y", (2, "min")),
}
#: the model inputs that depend on the fiber, baked once per angle as NAME@ANGLE
FIBER_INPUTS = ("fiber", "tet_fiber")
#: fiber angles baked by default, degrees (the fiber stiffness is the trained material's E)
ANGLES = (0, 15, 30, 45, 60, 75, 90)


def scene_mesh(name):
    """(vertices (n, 3) m, tets (m, 4), held (n, 3) bool) of a scene of SCENES."""
    _, shape, (axis, side) = SCENES[name]
    mesh = {"box": lambda: anisofem.box_beam(size=(0.1, 0.02, 0.02), cells=(10, 2, 2)),
            "cylinder": lambda: anisofem.cylinder_beam(0.1, 0.01, 8, 2, 0),
            "t": lambda: anisofem.t_shape(),
            "y": lambda: anisofem.y_shape()}[shape]()
    held = np.zeros((mesh.n_vertices, 3), dtype=bool)
    held[metrics.end_vertices(mesh, axis, side)] = True
    return mesh.vertices, mesh.tets, held


def fiber_direction(angle):
    """(3,) unit fiber at `angle` degrees from the x axis towards z."""
    a = math.radians(angle)
    return np.array([math.cos(a), 0.0, math.sin(a)])


def bake(name, out, model_path, angles=ANGLES):
    """Write the scene `name` (a key of SCENES) for the model at model_path to out.json and
    out.bin; returns the header."""
    if name not in SCENES:
        raise ValueError(f"scene: expected one of {sorted(SCENES)}, got {name!r}")
    if not os.path.isfile(model_path):
        raise FileNotFoundError(f"model: no such file {str(model_path)!r}")
    angles = [float(a) for a in angles]
    if not angles:
        raise ValueError("angles: give at least one fiber angle")
    vertices, tets, held = scene_mesh(name)
    young = _trained_young(model_path)
    sim = runtime.OnnxSimulator(model_path, vertices, tets, fixed=held,
                                fiber_direction=fiber_direction(angles[0]),
                                fiber_stiffness=young)
    arrays = {key: value for key, value in sim.constants.items() if key not in FIBER_INPUTS}
    arrays["surface"] = runtime.surface_triangles(vertices, tets).astype(np.int32)
    arrays["masses"] = sim.masses
    arrays["held"] = held.astype(np.uint8)
    edges = runtime.mesh_edges(tets)
    stiffness = np.full(tets.shape[0], young)
    dtypes = {key: dtype for key, dtype, _ in runtime.INPUTS}
    for angle in angles:
        directions = np.tile(fiber_direction(angle), (tets.shape[0], 1))
        tag = f"@{angle:g}"
        arrays["fiber" + tag] = runtime.edge_fibers(tets, edges, directions, stiffness).astype(
            dtypes["fiber"])
        arrays["tet_fiber" + tag] = directions.astype(dtypes["tet_fiber"])
    header = {"scene": name, "title": SCENES[name][0], "model_format": runtime.FORMAT,
              "dt": sim.dt, "n": int(vertices.shape[0]), "m": int(tets.shape[0]),
              "E": int(sim.constants["senders"].shape[0]), "fiber_angles": angles,
              "gravity": list(GRAVITY),
              "trained_material": json.loads(sim.metadata["trained_material"])}
    write_arrays(out, arrays, header)
    return header


def write_arrays(path, arrays, header=None):
    """Write arrays {name: numpy array} as PATH.bin (raw little-endian, each array starting at
    a multiple of 8 bytes) and PATH.json: {"format": ARRAYS_FORMAT, "bin": file name,
    "arrays": {name: {"dtype", "shape", "offset" (bytes)}}} plus the entries of header (a
    JSON-able dict). A C++/C#/JS engine reads them without numpy. Both files are written
    atomically (a temporary file renamed)."""
    table, chunks, offset = {}, [], 0
    for name, value in arrays.items():
        value = np.asarray(value)
        kind = next((k for k, v in runtime.ARRAY_DTYPES.items() if np.dtype(v) == value.dtype),
                    None)
        if kind is None:
            raise TypeError(f"arrays[{name!r}]: dtype {value.dtype} is not one of "
                            f"{list(runtime.ARRAY_DTYPES)}")
        raw = np.ascontiguousarray(value, dtype=runtime.ARRAY_DTYPES[kind]).tobytes()
        table[name] = {"dtype": kind, "shape": list(value.shape), "offset": offset}
        pad = -len(raw) % 8
        chunks.append(raw + bytes(pad))
        offset += len(raw) + pad
    meta = {"format": runtime.ARRAYS_FORMAT, **(header or {}),
            "bin": os.path.basename(str(path)) + ".bin", "arrays": table}
    with atomic_path(str(path) + ".bin") as tmp, open(tmp, "wb") as f:
        f.write(b"".join(chunks))
    with atomic_path(str(path) + ".json") as tmp, open(tmp, "w") as f:
        json.dump(meta, f, indent=1)


def _trained_young(model_path):
    """E (Pa) of the material the model at model_path was trained on (its metadata)."""
    import onnx
    meta = {p.key: p.value for p in onnx.load(model_path, load_external_data=False)
            .metadata_props}
    return float(json.loads(meta["trained_material"])["young"])
