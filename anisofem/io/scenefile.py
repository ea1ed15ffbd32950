"""Scenes from files: a TOML scene file names a mesh file, the materials and fibers of its
regions, what is held, moved and loaded on its named surfaces, its controls (named pressures
and fiber activations), and the curves loads and controls follow in time.

Names come from the mesh file (Gmsh's physical volumes and surfaces); an unknown name is an
error that lists the ones the file has, and an unknown key names the nearest valid one. The
keys and what they mean: anisofem.io.scene_schema (docs/scenes.md is made from it); a table
written back as TOML: anisofem.io.toml_writer.
"""
import difflib
import inspect
import math
import os
import tomllib
import warnings

import numpy as np

from ..physics.cables import Cable
from ..physics.contact import Contact
from ..physics.controls import Activation
from ..physics.curves import LoadCurve, Timed
from ..physics.fibers import helix_directions, helix_frame, segments
from ..physics.material import MODELS, Material
from ..physics.meshgen import of_order
from ..physics.obstacles import KINDS
from ..physics.pressure import Pressure
from ..physics.scene import Scene, traction_force
from .meshes import read_surface, read_tagged_mesh
from .scene_schema import SCHEMA

#: Sides a boundary entry may name: axis and end.
SIDES = {f"{a}-{e}": (i, e) for i, a in enumerate("xyz") for e in ("min", "max")}

#: A vertex lies on a side or in a box within this share of the mesh's size.
PLACE_TOLERANCE = 1e-9

#: Fiber directions of a cell field are unit length within this.
UNIT_TOLERANCE = 1e-6


class SceneFileError(ValueError):
    """A scene file that cannot be read as a scene: the message names the file and the key."""


def load_scene(path):
    """The Scene a TOML scene file describes (SCHEMA; docs/scenes.md)."""
    return SceneFile(path).scene


class SceneFile:
    """A scene file read: path, table (tomllib's dict), scene (the Scene), control_ranges
    ({name: (low, high)} of the controls that give a range), and the names it uses:
    region(name) the (m,) bool mask of a physical volume's tets, vertices(where) the
    vertices of a place (a surface, a side or a box, as a [[boundary]] entry names it)."""

    def __init__(self, path):
        self.path = os.fspath(path)
        if not os.path.isfile(self.path):
            raise FileNotFoundError(f"path: no such scene file {self.path!r}")
        with open(self.path, "rb") as f:
            try:
                self.table = tomllib.load(f)
            except (tomllib.TOMLDecodeError, UnicodeDecodeError) as err:
                why = ("not text" if isinstance(err, UnicodeDecodeError) else f"not TOML ({err})")
                raise SceneFileError(f"{self.path}: {why}: a scene file is TOML text that names "
                                     f"its mesh (mesh = \"part.msh\", docs/scenes.md); a mesh "
                                     f"file goes there, or where a command takes a mesh") \
                    from None
        self._reader = _Reader(self.path)
        self.scene = self._reader.scene(self.table)
        self.control_ranges = self._reader.ranges

    def region(self, name):
        return self._reader.region(name, name)

    def helix(self, region):
        """(unit axis (3,), origin (3,) m, crossed, the winding angle in degrees: angle, or the
        mean of segments) of the helix fibers of a region (its own fiber key, else
        [material]'s); ValueError where they are not a helix."""
        self.region(region)  # a name the mesh lacks: the error lists the ones it has
        for where in (self.table.get("regions", {}).get(region, {}),
                      self.table.get("material", {})):
            if "fiber" in where:
                fiber = where["fiber"]
                if isinstance(fiber, dict) and "helix" in fiber:
                    spec = fiber["helix"]
                    angle = (float(np.mean(spec["segments"])) if "segments" in spec else
                             spec["angle"])
                    axis, origin, _ = self._reader.turn(spec | {"angle": angle}, region)
                    return axis, origin, bool(spec.get("crossed", False)), angle
                break
        raise ValueError(f"region: the fibers of {region!r} are not a helix (fiber = {{helix "
                         f"= {{...}}}}); design changes a helix's winding angles")

    def vertices(self, where):
        return self._reader.vertices(where, where)


class _Reader:
    """Builds a Scene from a scene file's table, naming the file and key of each error."""

    def __init__(self, path):
        self.path = path
        self.folder = os.path.dirname(os.path.abspath(path))

    def error(self, key, message):
        return SceneFileError(f"{self.path}: {key}: {message}")

    def scene(self, table):
        _keys(self, table, "scene", "")
        if "mesh" not in table:
            raise self.error("mesh", "required: the mesh file")
        mesh_path = _string(self, table["mesh"], "mesh")
        full = os.path.join(self.folder, mesh_path)
        if not os.path.isfile(full):
            raise self.error("mesh", f"no such file {mesh_path!r} (looked for {full})")
        try:
            mesh, tags = read_tagged_mesh(full)
        except ValueError as err:
            raise self.error("mesh", str(err)) from None
        order = table.get("order", 1)
        if order not in (1, 2) or isinstance(order, bool):
            raise self.error("order", f"1 or 2, got {order!r}")
        self.mesh, self.tags = of_order(mesh, order), tags
        curves = self.curves(table.get("curves", {}))
        material = self.material(table)
        held, positions, parts, loads = self.boundaries(table, curves)
        pressures, activations, cables, timed = self.controls(table.get("controls", {}),
                                                              curves)
        parts += timed
        gravity = _vector(self, table["gravity"], "gravity") if "gravity" in table else None
        body = _vector(self, table["body_force"], "body_force") if "body_force" in table else None
        contact, moving = (self.contact(table["contact"], curves) if "contact" in table
                           else (None, []))
        parts += moving
        try:
            scene = Scene(self.mesh, material, fixed=held, fixed_positions=positions,
                          gravity=gravity, body_force=body,
                          pressure=loads["pressure"] + pressures, activation=activations,
                          cable=cables, nodal_force=loads["force"], contact=contact)
        except ValueError as err:
            said = str(err)
            if said.startswith("contact: "):
                raise self.error("contact", said.removeprefix("contact: ")) from None
            raise self.error("controls" if said.startswith(("activation", "controls", "cable"))
                             else "boundary", said) from None
        return scene.following(parts) if parts else scene

    # materials and fibers

    def material(self, table):
        """The Material of every tet: [material], then each region's changes."""
        m = self.mesh.n_tets
        base = table.get("material", {})
        _keys(self, base, "material", "material")
        default = {k: p.default for k, p in inspect.signature(Material).parameters.items()}
        values = {"law": np.full(m, default["model"], dtype=object),
                  "fiber": np.tile(np.array(default["fiber_direction"], float), (m, 1)),
                  "fiber_stiffness": np.full(m, float(default["fiber_stiffness"]))}
        values |= {k: np.full(m, float(default[k]))
                   for k in ("young", "poisson", "density", "activation")}
        self.assign(values, base, np.ones(m, bool), "material")
        regions = table.get("regions", {})
        if not isinstance(regions, dict):
            raise self.error("regions", "expected [regions.NAME] tables")
        for name, changes in regions.items():
            key = f"regions.{name}"
            if not isinstance(changes, dict):
                raise self.error(key, "expected a table of material keys")
            _keys(self, changes, "material", key)
            self.assign(values, changes, self.region(name, key), key)
        kappa = values["fiber_stiffness"]
        fiber = values["fiber"]
        fiber[kappa == 0] = default["fiber_direction"]  # unused where there is no fiber term
        try:
            return Material(values["young"], values["poisson"], values["density"], fiber, kappa,
                            model=list(values["law"]), activation=values["activation"])
        except ValueError as err:
            raise self.error("material", str(err)) from None

    def region(self, name, key):
        """(m,) bool: the tets of the physical volume called name (or numbered so)."""
        volumes = self.tags.volumes
        known = {n: tag for n, (tag, dim) in self.tags.names.items() if dim == 3}
        tag = known.get(name, int(name) if name.isdigit() else None)
        have = sorted(known) or sorted({str(v) for v in np.unique(volumes)} if volumes is not None
                                       else [])
        if volumes is None or tag is None or not (volumes == tag).any():
            raise self.error(key, f"the mesh has no physical volume {name!r}; it has: "
                                  f"{', '.join(have) if have else 'none'}")
        return volumes == tag

    def assign(self, values, changes, tets, key):
        """Write a material table's changes into the per-tet values on tets (m,) bool."""
        for name, value in changes.items():
            where = f"{key}.{name}"
            if name == "law":
                if value not in MODELS:
                    raise self.error(where, f"expected {' or '.join(MODELS)}, got {value!r}")
                values["law"][tets] = value
            elif name == "fiber":
                values["fiber"][tets] = self.fiber(value, tets, where)
            else:
                values[name][tets] = _number(self, value, where)

    def fiber(self, spec, tets, key):
        """(k, 3) unit fiber directions of the tets (m,) bool from a fiber spec."""
        if isinstance(spec, list):
            d = _vector(self, spec, key)
            norm = np.linalg.norm(d)
            if not norm > 0:
                raise self.error(key, "a direction needs a nonzero vector")
            return d / norm
        if not isinstance(spec, dict) or len(spec) != 1 or \
                next(iter(spec)) not in ("cell_data", "helix"):
            raise self.error(key, "expected [dx, dy, dz], {cell_data = NAME} or "
                                  "{helix = {...}}")
        kind, value = next(iter(spec.items()))
        if kind == "cell_data":
            return self.cell_fiber(_string(self, value, f"{key}.cell_data"), tets,
                                   f"{key}.cell_data")
        if not isinstance(value, dict):
            raise self.error(f"{key}.helix", "expected a table")
        _keys(self, value, "helix", f"{key}.helix")
        return self.helix(value, tets, f"{key}.helix")

    def cell_fiber(self, name, tets, key):
        fields = self.tags.cell_data
        if name not in fields:
            raise self.error(key, f"the mesh file has no cell field {name!r}; it has: "
                                  f"{', '.join(sorted(fields)) or 'none'}")
        field = np.asarray(fields[name], dtype=float)
        if field.shape != (self.mesh.n_tets, 3):
            raise self.error(key, f"a fiber field has one 3-vector per tet, shape "
                                  f"({self.mesh.n_tets}, 3); {name!r} has {field.shape}")
        d = field[tets]
        norms = np.linalg.norm(d, axis=1)
        bad = ~(norms > 0) | ~np.isfinite(norms)
        if bad.any():
            at = int(np.flatnonzero(tets)[np.flatnonzero(bad)[0]])
            raise self.error(key, f"zero or NaN direction at tet {at}")
        off = np.abs(norms - 1.0) > UNIT_TOLERANCE
        if off.any():
            warnings.warn(f"{self.path}: {key}: {int(off.sum())} directions are not unit length "
                          f"(|d| from {norms.min():.3g} to {norms.max():.3g}); normalized",
                          stacklevel=4)
        return d / norms[:, None]

    def helix(self, spec, tets, key):
        """Fibers wound about an axis (anisofem.physics.fibers): the winding angle linear from angle
        to angle_end along the axis over the tets, or constant in each of equal segments."""
        if "segments" in spec:
            if "angle" in spec or "angle_end" in spec:
                raise self.error(key, "give segments, or angle (and angle_end), not both")
            angles = spec["segments"]
            if not isinstance(angles, list) or not angles or \
                    not all(isinstance(a, (int, float)) and not isinstance(a, bool)
                            and math.isfinite(a) for a in angles):
                raise self.error(f"{key}.segments", f"expected a list of angles in degrees, "
                                                    f"got {angles!r}")
            axis, origin, _ = self.turn(spec | {"angle": 0.0}, key)
        else:
            axis, origin, start = self.turn(spec, key)
            end = _number(self, spec.get("angle_end", start), f"{key}.angle_end")
        try:
            s, around = helix_frame(self.mesh.vertices[self.mesh.tets[tets]].mean(axis=1), axis,
                                    origin)
        except ValueError as err:
            raise self.error(key, str(err)) from None
        if "segments" in spec:
            angle = np.radians(np.asarray(angles, dtype=float)[segments(s, len(angles))])
        else:
            span = np.ptp(s)
            share = (s - s.min()) / span if span > 0 else np.zeros_like(s)
            angle = np.radians(start + (end - start) * share)
        crossed = spec.get("crossed", False)
        if not isinstance(crossed, bool):
            raise self.error(f"{key}.crossed", f"true or false, got {crossed!r}")
        return helix_directions(axis, around, angle, crossed)

    # boundary conditions and loads

    def boundaries(self, table, curves):
        """(held (n, 3) bool, positions (n, 3), timed parts, loads {"force", "pressure"})."""
        n = self.mesh.n_vertices
        X = self.mesh.vertices
        held, positions = np.zeros((n, 3), bool), X.copy()
        moved_by = np.full(n, -1)
        force, pressures, parts = np.zeros((n, 3)), [], []
        entries = table.get("boundary", [])
        if not isinstance(entries, list):
            raise self.error("boundary", "expected [[boundary]] tables")
        for k, entry in enumerate(entries):
            key = f"boundary[{k}]"
            if not isinstance(entry, dict):
                raise self.error(key, "expected a table")
            _keys(self, entry, "boundary", key)
            if "where" not in entry:
                raise self.error(key, "where: required (a surface, a side or a box)")
            actions = [a for a in ("held", "traction", "pressure") if a in entry]
            if not actions:
                raise self.error(key, "nothing is done there: give held, traction or pressure")
            curve = None
            if "curve" in entry:
                curve = self.curve_named(entry["curve"], curves, f"{key}.curve")
            where = entry["where"]
            if "held" in entry:
                vertices = self.vertices(where, f"{key}.where")
                axes = self.axes(entry["held"], f"{key}.held")
                held[np.ix_(vertices, axes)] = True
                motion = self.motion(entry, vertices, key)
                if motion is not None:
                    again = moved_by[vertices] >= 0
                    if again.any():
                        raise self.error(key, f"its vertices are moved by boundary"
                                              f"[{moved_by[vertices][again][0]}] too")
                    moved_by[vertices] = k
                    u = np.zeros((n, 3))
                    u[vertices] = motion(1.0)
                    mask = np.zeros((n, 3), bool)
                    mask[np.ix_(vertices, axes)] = True
                    positions[mask] += u[mask]
                    if curve is not None:
                        parts.append(Timed(curve, motion=_masked(motion, vertices, mask)))
            elif any(m in entry for m in ("displacement", "rotation")):
                raise self.error(key, "displacement and rotation move held vertices: add held")
            if "traction" in entry:
                faces = self.faces(where, f"{key}.where")
                t = _vector(self, entry["traction"], f"{key}.traction")
                f = traction_force(self.mesh, t, faces)
                force += f
                if curve is not None:
                    parts.append(Timed(curve, force=f))
            if "pressure" in entry:
                faces = self.faces(where, f"{key}.where")
                pressures.append(Pressure(faces, _number(self, entry["pressure"],
                                                         f"{key}.pressure")))
                if curve is not None:
                    parts.append(Timed(curve, pressure=len(pressures) - 1))
        return held, positions, parts, {"force": force, "pressure": pressures}

    def controls(self, table, curves):
        """([controls.NAME] tables) -> (named Pressures, Activations, Cables, Timed parts of
        the controls that follow a curve)."""
        if not isinstance(table, dict):
            raise self.error("controls", "expected [controls.NAME] tables")
        pressures, activations, cables, parts = [], [], [], []
        self.ranges = {}
        for name, spec in table.items():
            key = f"controls.{name}"
            if not isinstance(spec, dict):
                raise self.error(key, "expected a table: pressure or activation, and value")
            _keys(self, spec, "controls", key)
            kinds = [k for k in ("pressure", "activation", "cable") if k in spec]
            if len(kinds) != 1:
                raise self.error(key, "give one of pressure (a place: the cavity's walls), "
                                      "activation (a region: its fibers) or cable (its points)")
            value = _number(self, spec.get("value", 0.0), f"{key}.value")
            if kinds == ["pressure"]:
                faces = self.faces(spec["pressure"], f"{key}.pressure")
                pressures.append(Pressure(faces, value, name=name))
            elif kinds == ["cable"]:
                points = spec["cable"]
                if not isinstance(points, list) or len(points) < 2:
                    raise self.error(f"{key}.cable", "expected a list of at least two points "
                                                     "[x, y, z], m")
                points = [_vector(self, p, f"{key}.cable[{i}]") for i, p in enumerate(points)]
                try:
                    cables.append(Cable(points, value, name=name))
                except ValueError as err:
                    raise self.error(f"{key}.value", str(err)) from None
            else:
                region = _string(self, spec["activation"], f"{key}.activation")
                try:
                    activations.append(Activation(self.region(region, f"{key}.activation"),
                                                  value, name=name))
                except ValueError as err:
                    raise self.error(f"{key}.value", str(err)) from None
            if "curve" in spec:
                parts.append(Timed(self.curve_named(spec["curve"], curves, f"{key}.curve"),
                                   control=name))
            if "range" in spec:
                low, high = _vector(self, spec["range"], f"{key}.range", 2)
                if not low < high or (kinds == ["activation"] and not 0 <= low < high < 1):
                    raise self.error(f"{key}.range", f"expected [low, high] with low < high"
                                     f"{' in [0, 1)' if kinds == ['activation'] else ''}, got "
                                     f"{spec['range']!r}")
                self.ranges[name] = (float(low), float(high))
        return pressures, activations, cables, parts

    def curve_named(self, value, curves, key):
        """The LoadCurve a key names; SceneFileError listing the file's curves otherwise."""
        name = _string(self, value, key)
        if name not in curves:
            raise self.error(key, f"no curve {name!r}; the file has: "
                                  f"{', '.join(sorted(curves)) or 'none'}")
        return curves[name]

    def motion(self, entry, vertices, key):
        """motion(c) -> (k, 3) displacement of the vertices at factor c of the entry's
        displacement or rotation, or None."""
        if "displacement" in entry and "rotation" in entry:
            raise self.error(key, "give displacement or rotation, not both")
        if "displacement" in entry:
            u = _vector(self, entry["displacement"], f"{key}.displacement")
            return lambda c: np.broadcast_to(c * u, (len(vertices), 3))
        if "rotation" not in entry:
            return None
        spec, where = entry["rotation"], f"{key}.rotation"
        if not isinstance(spec, dict):
            raise self.error(where, "expected {axis = [...], origin = [...], angle = degrees}")
        _keys(self, spec, "rotation", where)
        axis, origin, degrees = self.turn(spec, where)
        angle = math.radians(degrees)
        arm = self.mesh.vertices[vertices] - origin
        return lambda c: _rotated(arm, axis, c * angle) - arm

    def turn(self, spec, key):
        """(unit axis (3,), origin (3,) m, angle in degrees) of a table with axis, angle and
        an optional origin (a helix, a rotation)."""
        for needed in ("axis", "angle"):
            if needed not in spec:
                raise self.error(key, f"{needed}: required")
        axis = _vector(self, spec["axis"], f"{key}.axis")
        if not np.linalg.norm(axis) > 0:
            raise self.error(f"{key}.axis", "a direction needs a nonzero vector")
        origin = _vector(self, spec.get("origin", [0.0, 0.0, 0.0]), f"{key}.origin")
        return axis / np.linalg.norm(axis), origin, _number(self, spec["angle"], f"{key}.angle")

    def contact(self, table, curves):
        """The [contact] table -> (an anisofem.Contact, the Timed parts of the obstacles that
        move along a curve)."""
        _keys(self, table, "contact", "contact")
        itself = table.get("self_contact", False)
        if not isinstance(itself, bool):
            raise self.error("contact.self_contact", f"expected true or false, got {itself!r}")
        obstacles = table.get("obstacles", {})
        if not isinstance(obstacles, dict) or not (obstacles or itself):
            raise self.error("contact.obstacles", "expected [contact.obstacles.NAME] tables, "
                                                  "at least one (or self_contact = true)")
        given = {k: _number(self, table[k], f"contact.{k}")
                 for k in ("distance", "friction", "stiffness", "smoothing") if k in table}
        parts = []
        for name, spec in obstacles.items():
            key = f"contact.obstacles.{name}"
            if ("move" in spec) != ("curve" in spec):
                raise self.error(key, "give move (how far, m) and curve (when) together")
            if "move" in spec:
                parts.append(Timed(self.curve_named(spec["curve"], curves, f"{key}.curve"),
                                   obstacle=(name, _vector(self, spec["move"], f"{key}.move"))))
        try:
            return Contact([self.obstacle(name, spec) for name, spec in obstacles.items()],
                           self_contact=itself, **given), parts
        except ValueError as err:
            raise self.error("contact", str(err).removeprefix("contact: ")) from None

    def obstacle(self, name, spec):
        """A [contact.obstacles.NAME] table -> its anisofem obstacle."""
        key = f"contact.obstacles.{name}"
        _keys(self, spec, "obstacle", key)
        shapes = [k for k in KINDS if k in spec]
        if len(shapes) != 1:
            raise self.error(key, f"give one of {', '.join(KINDS)}")
        shape = shapes[0]
        where = f"{key}.{shape}"
        geometry = spec[shape]
        friction = (_number(self, spec["friction"], f"{key}.friction") if "friction" in spec
                    else None)
        if shape == "surface":
            if not isinstance(geometry, dict) or set(geometry) != {"file"} or \
                    not isinstance(geometry["file"], str):
                raise self.error(where, f"expected {{file = \"NAME.stl\"}}, got {geometry!r}")
            path = os.path.join(os.path.dirname(self.path), geometry["file"])
            try:
                return read_surface(path, name=name, friction=friction)
            except (OSError, ValueError) as err:
                raise self.error(f"{where}.file", str(err).removeprefix("path: ")) from None
        # a box's axes are the world's in a scene file: its rotation is no key
        keys = [k for k in KINDS[shape].parameters if k != "rotation"]
        if not isinstance(geometry, dict) or set(geometry) != set(keys):
            raise self.error(where, f"expected {{{', '.join(keys)}}}, got {geometry!r}")
        values = [(_number if k == "radius" else _vector)(self, geometry[k], f"{where}.{k}")
                  for k in keys]
        try:
            return KINDS[shape](*values, name=name, friction=friction)
        except ValueError as err:
            raise self.error(where, str(err)) from None

    def curves(self, table):
        if not isinstance(table, dict):
            raise self.error("curves", "expected [curves.NAME] tables")
        out = {}
        for name, spec in table.items():
            key = f"curves.{name}"
            if not isinstance(spec, dict):
                raise self.error(key, "expected a table with times and values")
            _keys(self, spec, "curves", key)
            for needed in ("times", "values"):
                if needed not in spec:
                    raise self.error(key, f"{needed}: required")
            try:
                out[name] = LoadCurve(spec["times"], spec["values"], name=key)
            except (ValueError, TypeError) as err:
                raise SceneFileError(f"{self.path}: {err}") from None
        return out

    def axes(self, spec, key):
        if spec is True:
            return [0, 1, 2]
        if isinstance(spec, list) and spec and all(a in ("x", "y", "z") for a in spec):
            return sorted({"xyz".index(a) for a in spec})
        raise self.error(key, f"true or a list of axes like [\"x\", \"z\"], got {spec!r}")

    def vertices(self, where, key):
        """(k,) the vertices of a place (a surface's, a side's or a box's)."""
        if isinstance(where, str) and where not in SIDES:
            faces = self.surface(where, key)
            if self.mesh.order == 2:  # and the midside nodes of the faces' edges
                faces = np.concatenate([faces.ravel(), self.mesh.edge_nodes(
                    faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2))])
            return np.unique(faces)
        inside = self.place(where, key)
        found = np.flatnonzero(inside(self.mesh.vertices))
        if found.size == 0:
            raise self.error(key, f"no vertex lies at {where!r}")
        return found

    def faces(self, where, key):
        """(k, 3) the boundary faces of a place: a surface's triangles, or the boundary faces
        whose corners all lie on a side or in a box."""
        if isinstance(where, str) and where not in SIDES:
            return self.surface(where, key)
        inside = self.place(where, key)
        faces = self.mesh.boundary_faces
        keep = inside(self.mesh.vertices[faces].reshape(-1, 3)).reshape(-1, 3).all(axis=1)
        if not keep.any():
            raise self.error(key, f"no boundary face lies at {where!r}")
        return faces[keep]

    def surface(self, name, key):
        """(k, 3) the triangles of the physical surface called name (or numbered so)."""
        known = {n: tag for n, (tag, dim) in self.tags.names.items() if dim == 2}
        tag = known.get(name, int(name) if name.isdigit() else None)
        if tag not in self.tags.surfaces:
            have = sorted(known) or sorted(str(t) for t in self.tags.surfaces)
            raise self.error(key, f"the mesh has no physical surface {name!r}; it has: "
                                  f"{', '.join(have) if have else 'none'} (or use a side, "
                                  f"{', '.join(SIDES)}, or a box)")
        return self.tags.surfaces[tag]

    def place(self, where, key):
        """inside(points (k, 3)) -> (k,) bool of a side or a box."""
        X = self.mesh.vertices
        tol = PLACE_TOLERANCE * self.mesh.size
        if isinstance(where, str):
            axis, end = SIDES[where]
            edge = X[:, axis].min() if end == "min" else X[:, axis].max()
            return lambda p: np.abs(p[:, axis] - edge) <= tol
        if isinstance(where, dict) and list(where) == ["box"]:
            box = np.asarray(where["box"], dtype=float) if _numeric(where["box"]) else None
            if box is None or box.shape != (2, 3) or (box[0] > box[1]).any():
                raise self.error(key, "box: expected [[x0, y0, z0], [x1, y1, z1]] with x0 <= "
                                      "x1, y0 <= y1, z0 <= z1")
            return lambda p: ((p >= box[0] - tol) & (p <= box[1] + tol)).all(axis=1)
        raise self.error(key, f"a physical surface, a side ({', '.join(SIDES)}) or "
                              f"{{box = [[...], [...]]}}, got {where!r}")


def _masked(motion, vertices, mask):
    """motion as (n, 3) displacements on the masked components, for Timed."""
    n = mask.shape[0]

    def full(c):
        u = np.zeros((n, 3))
        u[vertices] = motion(c)
        u[~mask] = 0.0
        return u
    return full


def _rotated(arm, axis, angle):
    """arm (k, 3) turned by angle (radians) about the unit axis (Rodrigues)."""
    c, s = math.cos(angle), math.sin(angle)
    return (arm * c + np.cross(axis, arm) * s
            + np.outer(arm @ axis, axis) * (1.0 - c))


def _keys(reader, table, kind, key):
    """SceneFileError for a key of table that SCHEMA[kind] does not hold, naming the nearest."""
    if not isinstance(table, dict):
        raise reader.error(key or kind, "expected a table")
    for name in table:
        if name not in SCHEMA[kind]:
            near = difflib.get_close_matches(name, SCHEMA[kind], n=1)
            hint = f"; did you mean {near[0]!r}?" if near else \
                f"; valid: {', '.join(SCHEMA[kind])}"
            raise reader.error(f"{key}.{name}" if key else name, f"unknown key{hint}")


def _numeric(value):
    try:
        return np.asarray(value).dtype.kind in "fiu"
    except (ValueError, TypeError):
        return False


def _number(reader, value, key):
    if isinstance(value, bool) or not isinstance(value, (int, float)) or \
            not math.isfinite(value):
        raise reader.error(key, f"expected a finite number, got {value!r}")
    return float(value)


def _vector(reader, value, key, size=3):
    """value as a finite (size,) float array: a list of `size` numbers."""
    if not isinstance(value, list) or len(value) != size or \
            any(isinstance(v, bool) or not isinstance(v, (int, float)) for v in value):
        shown = "[x, y, z]" if size == 3 else f"{size}"
        raise reader.error(key, f"expected {shown} numbers, got {value!r}")
    v = np.array(value, dtype=float)
    if not np.isfinite(v).all():
        raise reader.error(key, f"must be finite, got {value!r}")
    return v


def _string(reader, value, key):
    if not isinstance(value, str):
        raise reader.error(key, f"expected a string, got {value!r}")
    return value


