"""Reading meshes and writing results through meshio (.msh, .vtu, .xdmf and the rest of
meshio's formats). Results carry fields a person can open in ParaView: point data
"displacement" (m), cell data "fiber_direction", "fiber_stiffness" (Pa), "energy" (J per tet),
"energy_density" (J/m^3), "volume_change" (det F - 1) and "inverted" (1 where det F <= 0: the
element is turned inside out)."""
import contextlib
import io
import os
from dataclasses import dataclass

import meshio
import numpy as np

from .output import atomic_path, check_folder
from .._validate import as_float_array
from ..physics.mesh import TetMesh
from ..physics.obstacles import Surface
from ..physics.inversion import volume_change
from ..physics.potential import element_energy


def read_mesh(path, **mesh_options):
    """The tetrahedra of a mesh file as a TetMesh: linear (tetra) or quadratic (tetra10) cells,
    one order per file; other cell types are ignored.

    mesh_options go to TetMesh (fix_orientation, unreferenced). Lower-dimensional cells
    (surface triangles, lines) are common in .msh files, and the vertices only they use are
    dropped unless unreferenced is given.
    """
    return read_tagged_mesh(path, **mesh_options)[0]


@dataclass
class MeshTags:
    """What a mesh file says about its tets and surfaces besides their geometry.

    volumes: (m,) int physical group of each tet (Gmsh's "gmsh:physical"), or None; surfaces:
    {physical group: (k, 3) corner vertex triples of its triangles}; names: {name: (group,
    dimension)} (Gmsh's physical names: 3 for volumes, 2 for surfaces); cell_data: {name: (m,
    ...) array} the tets' other cell fields (a fiber field, say).
    """
    volumes: object
    surfaces: dict
    names: dict
    cell_data: dict


def read_tagged_mesh(path, **mesh_options):
    """(TetMesh, MeshTags) of a mesh file: read_mesh's mesh with the file's physical groups,
    names and cell fields (numbered for the mesh's vertices and tets)."""
    path = os.fspath(path)
    if not os.path.isfile(path):
        raise FileNotFoundError(f"path: no such mesh file {path!r}")
    m = _meshio_read(path)
    types = sorted({c.type for c in m.cells})
    other = [t for t in types if t.startswith("tetra") and t not in TET_TYPES]
    if other:
        raise ValueError(f"path: {path} holds {', '.join(other)} cells; anisofem reads linear "
                         f"(tetra) and quadratic (tetra10) tets")
    found = [t for t in TET_TYPES if t in types]
    if not found:
        raise ValueError(f"path: {path} holds no tetra or tetra10 cells (found {types})")
    if len(found) > 1:
        raise ValueError(f"path: {path} mixes linear (tetra) and quadratic (tetra10) tets; a "
                         f"mesh has one order")
    blocks = [k for k, c in enumerate(m.cells) if c.type == found[0]]
    tets = np.concatenate([m.cells[k].data for k in blocks]).astype(np.int64)
    mesh_options.setdefault("unreferenced", "drop")
    mesh = TetMesh(m.points[:, :3], tets, **mesh_options)
    new = np.arange(len(m.points))
    if mesh.kept_vertices is not None:
        new = np.full(len(m.points), -1)
        new[mesh.kept_vertices] = np.arange(mesh.kept_vertices.size)
    fields = {name: np.concatenate([np.asarray(data[k]) for k in blocks])
              for name, data in m.cell_data.items()}
    volumes = fields.pop("gmsh:physical", None)
    fields.pop("gmsh:geometrical", None)
    surfaces = {}
    physical = m.cell_data.get("gmsh:physical")
    for k, block in enumerate(m.cells):
        if block.type not in ("triangle", "triangle6") or physical is None:
            continue
        corners = new[np.asarray(block.data[:, :3], dtype=np.int64)]
        if (corners < 0).any():
            raise ValueError(f"path: {path} has surface triangles on vertices no tet uses")
        for tag in np.unique(physical[k]):
            part = corners[np.asarray(physical[k]) == tag]
            surfaces[int(tag)] = np.concatenate([surfaces.get(int(tag), np.empty((0, 3), int)),
                                                 part])
    names = {str(name): (int(v[0]), int(v[1])) for name, v in (m.field_data or {}).items()
             if np.size(v) >= 2}
    return mesh, MeshTags(None if volumes is None else np.asarray(volumes, np.int64), surfaces,
                          names, fields)


#: meshio's cell types of the tets anisofem reads, by order
TET_TYPES = ("tetra", "tetra10")


def _meshio_read(path):
    """meshio.read(path) by each format its extension may name (Gmsh first for .msh), with
    meshio's own printing silenced; a ValueError naming the file where none reads it (meshio
    prints its errors and exits the process when it cannot read a file)."""
    ext = os.path.splitext(path)[1].lower()
    formats = sorted(meshio.extension_to_filetypes.get(ext, [None]), key=lambda f: f != "gmsh")
    errors = []
    for fmt in formats:
        try:
            with contextlib.redirect_stdout(io.StringIO()), \
                    contextlib.redirect_stderr(io.StringIO()):
                return meshio.read(path, file_format=fmt)
        except (Exception, SystemExit) as err:  # ReadError, ValueError, IndexError, exit...
            why = "" if isinstance(err, SystemExit) or not str(err) else f": {str(err)[:200]}"
            errors.append(f"not {fmt or 'a mesh'}{why}")
    raise ValueError(f"path: meshio cannot read {path!r} ({'; '.join(errors)})")


def read_surface(path, *, name=None, friction=None):
    """An obstacle (anisofem.Surface) of the triangles of a surface file (.stl, .obj, .ply,
    .off, .msh, .vtu, ...: every triangle cell meshio reads), m; name defaults to the file's
    name without its extension. A file without triangles is a ValueError naming it."""
    path = os.fspath(path)
    if not os.path.isfile(path):
        raise FileNotFoundError(f"path: no such surface file {path!r}")
    m = _meshio_read(path)
    blocks = [c.data for c in m.cells if c.type == "triangle"]
    if not blocks:
        raise ValueError(f"path: {path} holds no triangles (found "
                         f"{sorted({c.type for c in m.cells})})")
    triangles = np.concatenate(blocks).astype(np.int64)
    used, triangles = np.unique(triangles, return_inverse=True)
    name = name if name is not None else os.path.splitext(os.path.basename(path))[0]
    return Surface(np.asarray(m.points, dtype=float)[used, :3], triangles.reshape(-1, 3),
                   name=name, friction=friction)


def check_output_path(path):
    """path (a str) if a mesh can be written there: a format meshio knows from the extension,
    in a folder that exists or can be made (writing makes it); else FileNotFoundError /
    ValueError naming it."""
    path = os.fspath(path)
    check_folder(path)
    if not any(path.lower().endswith(ext) for ext in meshio.extension_to_filetypes):
        raise ValueError(f"path: {path!r} has no mesh format meshio writes (use .vtu, .xdmf, "
                         f".msh, ...)")
    return path


def write_mesh(path, mesh, x=None, scene=None):
    """Write the rest mesh with the state x (n, 3) as the point field "displacement" (x - X; in
    ParaView, "Warp By Vector" shows the deformed shape); the format follows the extension.
    With a scene, the energy and fiber fields of the module docstring are added. The file is
    written under a temporary name in the same folder, then renamed (atomic)."""
    path = check_output_path(path)
    x = mesh.vertices if x is None else as_float_array(x, "x", shape=mesh.vertices.shape)
    points = {"displacement": x - mesh.vertices}
    change = volume_change(mesh, x)
    cells = {"volume_change": [change], "inverted": [(change <= -1.0).astype(np.int32)]}
    if scene is not None:
        energy = element_energy(scene, x)
        cells["energy"] = [energy]
        cells["energy_density"] = [energy / mesh.rest_volumes]
        cells["fiber_direction"] = [scene.elements.fiber]
        cells["fiber_stiffness"] = [scene.elements.kappa]
    ext = os.path.splitext(path)[1]
    if ext == ".msh":
        # Gmsh's own tags (all tets in entity 1); without them meshio warns that it made them up
        ones = np.ones(mesh.n_tets, dtype=np.int32)
        cells.update({"gmsh:physical": [ones], "gmsh:geometrical": [ones]})
    out = meshio.Mesh(mesh.vertices, [(TET_TYPES[mesh.order - 1], np.asarray(mesh.cells))],
                      point_data=points, cell_data=cells)
    # XDMF keeps its arrays inline (one file to move around); .msh is binary Gmsh 2.2 (meshio
    # cannot read back the fields of its ASCII .msh output with numpy 2)
    kwargs = {".xdmf": {"data_format": "XML"},
              ".msh": {"file_format": "gmsh22", "binary": True}}.get(ext, {})
    with atomic_path(path, ext) as tmp:
        meshio.write(tmp, out, **kwargs)


def write_tagged_mesh(path, mesh, volumes=None, surfaces=None, names=None, cell_data=None):
    """Write a mesh with physical groups, as Gmsh would: volumes (m,) int the group of each tet
    (default 1), surfaces {group: (k, 3) boundary triangles}, names {name: group} (a volume's
    or a surface's; Gmsh files only), cell_data {name: (m, ...)} fields of the tets (.vtu and
    .xdmf only: meshio's Gmsh reader loses cell fields beside surface triangles).
    read_tagged_mesh reads it back; a scene file names its groups. Atomic."""
    path = check_output_path(path)
    ext = os.path.splitext(path)[1].lower()
    gmsh = ext == ".msh"
    if gmsh and cell_data:
        raise ValueError(f"cell_data: write cell fields to .vtu or .xdmf ({path!r} is Gmsh, "
                         f"whose reader loses them)")
    if names and not gmsh:
        raise ValueError(f"names: group names are written to Gmsh files (.msh); {path!r} keeps "
                         f"the groups' numbers only")
    surfaces = surfaces or {}
    tags = (np.ones(mesh.n_tets, np.int32) if volumes is None
            else np.asarray(volumes, np.int32))
    if tags.shape != (mesh.n_tets,):
        raise ValueError(f"volumes: expected one group per tet, shape ({mesh.n_tets},), got "
                         f"{tags.shape}")
    triangles = [np.asarray(t, np.int64).reshape(-1, 3) for t in surfaces.values()]
    groups = [np.full(len(t), g, np.int32) for g, t in zip(surfaces, triangles)]
    cells, physical = [], []
    if triangles:
        cells.append(("triangle", np.concatenate(triangles)))
        physical.append(np.concatenate(groups))
    cells.append((TET_TYPES[mesh.order - 1], np.asarray(mesh.cells)))
    physical.append(tags)
    data = {"gmsh:physical": physical}
    if gmsh:
        data["gmsh:geometrical"] = physical
    for name, field in (cell_data or {}).items():
        field = np.asarray(field, dtype=float)
        if field.shape[0] != mesh.n_tets:
            raise ValueError(f"cell_data: {name!r} has {field.shape[0]} rows for "
                             f"{mesh.n_tets} tets")
        data[name] = [np.zeros((len(c[1]),) + field.shape[1:]) for c in cells[:-1]] + [field]
    dims = {int(g): 2 for g in surfaces}
    field_data = {name: np.array([g, dims.get(int(g), 3)]) for name, g in (names or {}).items()}
    out = meshio.Mesh(mesh.vertices, cells, cell_data=data, field_data=field_data)
    kwargs = ({"file_format": "gmsh22", "binary": True} if gmsh else  # see write_mesh
              {"data_format": "XML"} if ext == ".xdmf" else {})
    with atomic_path(path, ext) as tmp:
        meshio.write(tmp, out, **kwargs)


def write_series(path, mesh, states, times, scene=None):
    """Write states (k, n, 3) at times (k,) as a ParaView collection: path (.pvd) indexing one
    .vtu per state (write_mesh's fields) named after it, _0000.vtu and on. Each file atomic."""
    path = os.fspath(path)
    if not path.lower().endswith(".pvd"):
        raise ValueError(f"path: a series is a ParaView collection (.pvd), got {path!r}")
    check_folder(path)
    times = as_float_array(times, "times", shape=(None,))
    if len(states) != times.size:
        raise ValueError(f"states, times: {len(states)} states for {times.size} times")
    stem = os.path.splitext(path)[0]
    entries = []
    for k, (x, t) in enumerate(zip(states, times)):
        name = f"{stem}_{k:04d}.vtu"
        write_mesh(name, mesh, x, scene)
        entries.append(f'    <DataSet timestep="{t:.9g}" file="{os.path.basename(name)}"/>')
    text = ('<?xml version="1.0"?>\n<VTKFile type="Collection" version="0.1">\n  <Collection>\n'
            + "\n".join(entries) + "\n  </Collection>\n</VTKFile>\n")
    with atomic_path(path, ".pvd") as tmp:
        with open(tmp, "w") as f:
            f.write(text)
