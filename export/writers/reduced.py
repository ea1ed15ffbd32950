"""`python -m export reduced SCENE -o PATH`: a scene's reduced model (anisofem.reduced) written
as PATH.json + PATH.bin (export.writers.bake.write_arrays), which runtime.ReducedSimulator steps
with numpy alone.

The arrays (float64 unless said): rest_positions (n, 3) m, the positions the basis moves;
basis (n, 3, r) m per unit of q, 0 on held components; c1 (r,), C2 (r, r), S3 (r, r, r) and
W4 (T, r), T = r (r + 1) (r + 2) / 6, the coefficients of the energy (runtime.ReducedSimulator);
masses (n,) kg; held (n, 3) uint8; tets (m, 4) int32, the mesh it was built on; surface (k, 3)
int32, the boundary triangles; with a display mesh, the basis interpolated at its vertices
(physics on the model's mesh, drawing on the display's). A model with controls (named
pressures, activations, cables; anisofem.reduced.controls) adds control_kinds (k,) uint8 (0
a pressure, 1 an activation, 2 a cable, in that order), control_values (k,) their values as
the scene wrote them, control_c1 (k, r), control_C2 (k, r, r) and control_S3 (p, r, r, r), p
the pressures: each control's part of the energy per unit of its coefficient (a pressure's
value, an activation a's a (2 - a); zero for a cable), and with cables cable_segments (c,)
int32, each cable's segment count, cable_a (S, 3) the segments at rest, m, and cable_D (S, 3,
r) their rate in q (a cable's energy T sum_j |a_j + D_j q|); the header's controls lists the
names. The header:
model_format
REDUCED_FORMAT, title, n, m, r, modes, snapshots (the principal directions fitted to declared
loads, 0 for a modal basis), frequencies (Hz), c0 (J), build_seconds, dt (the time step it was
validated at, s), validation
(anisofem.reduced.model.Validation: the tip and field errors against the full FEM, statically
or on `cases` unseen loads), gravity (m/s^2) and material.

`--framed` writes a FramedModel instead (write_framed; format FRAMED_FORMAT, stepped by
framed_runtime.FramedSimulator and the C runtime's af_framed_step; export/README.md), for a
display mesh too.

`python -m export bake-reduced SCENE -o PATH` writes the models of a baked scene
(export.writers.bake) at several fiber angles in one pair of files, for the browser page: the arrays
that depend on the fiber once per angle A as NAME@A (runtime.ReducedSimulator(path, angle=A) reads
them); with --framed the framed models (bake_framed).
"""
import dataclasses

import numpy as np

from anisofem import Material, Scene, TetMesh
from anisofem.reduced import FramedModel, ReducedModel
from anisofem.reduced.model import VALIDATION_DT
from anisofem.physics.points import node_weights
from anisofem.physics.scene import GRAVITY

from .. import runtime
from ..framed_runtime import FRAMED_FORMAT
from .bake import SCENES, fiber_direction, scene_mesh, write_arrays

#: The time step the page steps a baked reduced model with, s (the shipped networks' dt).
DT = 0.02


def write(model, path, title="", gravity=None, display=None):
    """Write the ReducedModel `model` as path.json and path.bin; returns the header. gravity
    (3,) m/s^2: the scene's, recorded for a viewer (the runtime takes forces per step).
    display: a coarser TetMesh of the same body whose vertices the file moves instead of the
    model's (its basis interpolated there, its own lumped masses and surface): the model's
    accuracy at the display mesh's cost."""
    scene, P = model.scene, model.polynomial
    r = model.r
    mesh = scene.mesh if display is None else display
    if display is None:
        rest, basis, masses = model.x0, model.basis.reshape(-1, 3, r), scene.masses
        held = scene.fixed_mask
    else:
        rest, basis, masses = display.vertices, model.basis_at(display.vertices), \
            _display_masses(scene, display)
        held = np.all(basis == 0.0, axis=2)
    arrays = {"rest_positions": rest, "basis": basis,
              "c1": P.c1, "C2": P.C2, "S3": P.S3, "W4": P.W4,
              "masses": np.asarray(masses, dtype=np.float64),
              "held": held.astype(np.uint8),
              "tets": mesh.tets.astype(np.int32),
              "surface": runtime.surface_triangles(mesh.vertices, mesh.tets).astype(np.int32)}
    arrays.update(control_arrays(model.parts, r))
    contact, touching = contact_arrays(model)
    arrays.update(touching)
    header = {"model_format": runtime.REDUCED_FORMAT, "title": title, "n": mesh.n_vertices,
              "controls": [p.name for p in model.parts], "contact": contact,
              "obstacles": [o["name"] for o in contact["obstacles"]] if contact else [],
              "m": mesh.n_tets, "physics_tets": scene.mesh.n_tets, "r": r,
              "modes": len(model.frequencies), "snapshots": model.fitted,
              "frequencies": [float(f) for f in model.frequencies], "c0": float(P.c0),
              **checked_header(model, gravity)}
    write_arrays(path, arrays, header)
    return header


def checked_header(model, gravity):
    """The header entries both kinds of model file carry: build_seconds, validation, the time
    step it was validated at (dt, s), the loads it was built for, gravity (m/s^2, or None) and
    the material's young, poisson and density."""
    return {"build_seconds": model.build_seconds,
            "validation": (None if model.validation is None
                           else dataclasses.asdict(model.validation)),
            "dt": VALIDATION_DT,
            "loads": declared(model.loads),
            "gravity": None if gravity is None else [float(g) for g in gravity],
            "material": {key: np.asarray(getattr(model.scene.material, key)).tolist()
                         for key in ("young", "poisson", "density")}}


def control_arrays(parts, r):
    """The control arrays of a model's ControlParts (module docstring); none without."""
    if not parts:
        return {}
    pressures = [p for p in parts if p.kind == "pressure"]
    cables = [p for p in parts if p.kind == "tension"]
    zero = (np.zeros(r), np.zeros((r, r)))
    arrays = {"control_kinds": np.array([KIND_CODES[p.kind] for p in parts], np.uint8),
              "control_values": np.array([p.value for p in parts], np.float64),
              "control_c1": np.array([zero[0] if p.kind == "tension" else p.c1 for p in parts]),
              "control_C2": np.array([zero[1] if p.kind == "tension" else p.C2 for p in parts]),
              "control_S3": np.array([p.S3 for p in pressures]).reshape(len(pressures), r, r,
                                                                         r)}
    if cables:
        arrays.update({"cable_segments": np.array([len(c.a) for c in cables], np.int32),
                       "cable_a": np.concatenate([c.a for c in cables]),
                       "cable_D": np.concatenate([c.D for c in cables])})
    return arrays


def contact_arrays(model):
    """(the header's contact entry or None, the contact arrays) of a model with obstacles:
    contact_rest (k, 3) m and contact_basis (k, 3, r) the surface nodes of the physics mesh,
    contact_area (k,) m^2 their shares of its surface, contact_constants (4,): the distance
    dhat (m), stiffness kappa (N/m^3), friction and smoothing velocity (m/s); obstacle_kinds
    (o,) uint8 (OBSTACLE_CODES), obstacle_geometry (o, 15) m (each kind's Obstacle.parameters in
    order, zero-padded; a box's rotation row-major), obstacle_friction (o,) (-1: the
    contact's). The header's contact entry names the obstacles and repeats their geometry."""
    if model.contact is None:
        return None, {}
    term, contact = model.contact.term, model.scene.contact
    if contact.self_contact:
        raise ValueError("model: the runtimes take contact with planes, spheres, boxes and "
                         "capsules, not self-contact (the library's ReducedModel steps it)")
    rows, entries = [], []
    for o in term.obstacles:
        values = [np.asarray(getattr(o, key), dtype=float).ravel()
                  for key in o.parameters]
        row = np.concatenate(values)
        rows.append(np.concatenate([row, np.zeros(15 - row.size)]))
        entries.append({"kind": o.kind, "name": o.name, "friction": o.friction,
                        **{key: v.tolist() for key, v in zip(o.parameters,
                                                              values)}})
    header = {"distance": term.dhat, "stiffness": term.kappa, "friction": contact.friction,
              "smoothing": term.smoothing(1.0), "obstacles": entries}
    arrays = {"contact_rest": model.contact.x0, "contact_basis": model.contact.U,
              "contact_area": term.area,
              "contact_constants": np.array([term.dhat, term.kappa, contact.friction,
                                             term.smoothing(1.0)]),
              "obstacle_kinds": np.array([OBSTACLE_CODES[o.kind] for o in term.obstacles],
                                         np.uint8),
              "obstacle_geometry": np.array(rows),
              "obstacle_friction": np.array([-1.0 if o.friction is None else o.friction
                                             for o in term.obstacles])}
    return header, arrays


#: Each obstacle kind's code in obstacle_kinds.
OBSTACLE_CODES = {"plane": 0, "sphere": 1, "box": 2, "capsule": 3}


#: control_kinds' code of each kind of control (pressures, activations, cables: in that order).
KIND_CODES = {"pressure": 0, "activation": 1, "tension": 2}


def declared(loads):
    """The loads a model was built and validated for (a Loads, or None: the scene's own), as
    the header records them: each drag's vertex count, magnitude (N) and directions (None: any),
    the gravity cone (degrees), the carry (turn in degrees, move in m, seconds) and the
    controls' ranges."""
    if loads is None:
        return None
    return {"drags": [{"vertices": len(d.vertices), "magnitude": d.magnitude,
                       "directions": None if d.directions is None else
                       [list(map(float, v)) for v in d.directions]} for d in loads.drags],
            "cone": loads.cone,
            "carry": None if loads.carry is None else dataclasses.asdict(loads.carry),
            "controls": {name: list(span) for name, span in loads.controls}}


def _display_masses(scene, display):
    """(n,) kg: the display mesh's lumped masses in the scene's (uniform) density."""
    density = np.asarray(scene.material.density)
    if density.size != 1:
        raise ValueError("display: the material's density must be uniform (per-tet values "
                         "belong to the model's own mesh)")
    volumes = display.rest_volumes * float(density.ravel()[0]) / 4.0
    return np.bincount(display.tets.ravel(), np.repeat(volumes, 4), display.n_vertices)


def _angle_scenes(name, angles):
    """(angles as floats, the baked scene `name` (export.writers.bake.SCENES) with the trained
    material (Material.paper, fiber stiffness E) and gravity at each fiber angle, degrees from x
    towards z); ValueError naming the scene or the angles."""
    if name not in SCENES:
        raise ValueError(f"scene: expected one of {sorted(SCENES)}, got {name!r}")
    angles = [float(a) for a in angles]
    if not angles:
        raise ValueError("angles: give at least one fiber angle")
    vertices, tets, held = scene_mesh(name)
    mesh = TetMesh(vertices, tets)
    return angles, [Scene(mesh, Material.paper(fiber_direction(a), Material.paper().young),
                          fixed=held, gravity=GRAVITY) for a in angles]


def bake(name, out, modes, angles, snapshots=0):
    """Write the reduced models of the baked scene `name` (export.writers.bake.SCENES; the trained
    material: Material.paper with fiber stiffness E, gravity) at each fiber angle (degrees from
    x towards z) as out.json and out.bin: the mesh arrays once, the model arrays (basis, c1,
    C2, S3, W4) once per angle as NAME@A; the header lists fiber_angles and r per angle.
    snapshots: principal directions fitted to the scene's default declared loads (a drag of
    half the body's weight at each free end) added to the modes (0: modes and their modal
    derivatives). Returns the header."""
    angles, scenes = _angle_scenes(name, angles)
    arrays, ranks, checks = {}, [], []
    for angle, scene in zip(angles, scenes):
        model = ReducedModel(scene, modes=modes, snapshots=snapshots)
        P, tag = model.polynomial, f"@{angle:g}"
        arrays.update({"basis" + tag: model.basis.reshape(-1, 3, model.r), "c1" + tag: P.c1,
                       "C2" + tag: P.C2, "S3" + tag: P.S3, "W4" + tag: P.W4})
        ranks.append(model.r)
        checks.append(dataclasses.asdict(model.validation))
    arrays.update(_mesh_arrays(model.scene))
    mesh = model.scene.mesh
    header = {"model_format": runtime.REDUCED_FORMAT, "scene": name, "title": SCENES[name][0],
              "n": mesh.n_vertices, "m": mesh.n_tets, "modes": modes,
              "snapshots": snapshots,
              "fiber_angles": angles, "r": ranks, "validation": checks, "dt": DT,
              "gravity": list(GRAVITY)}
    write_arrays(out, arrays, header)
    return header


def write_framed(model, path, title="", gravity=None, display=None):
    """Write the FramedModel `model` as path.json and path.bin for
    framed_runtime.FramedSimulator; returns the header. gravity (3,) m/s^2: the scene's,
    recorded for a viewer (the runtime takes every force per step). display: a coarser
    TetMesh of the same body whose vertices the file moves instead of the model's, each a
    weighted sum of the model's nodes in the element holding it (display_nodes (p, k) int32,
    display_weights (p, k); the model's own rest positions as physics_rest (N, 3)): the
    model's accuracy at the display mesh's cost."""
    scene = model.scene
    arrays = {**_mesh_arrays(scene), **framed_arrays(model)}
    mesh = scene.mesh
    if display is not None:
        arrays.update(_framed_display(model, display))
        mesh = display
    joints = model._joint_elements
    header = {"model_format": FRAMED_FORMAT, "title": title, "n": mesh.n_vertices,
              "m": mesh.n_tets, "physics_tets": scene.mesh.n_tets,
              "domains": len(model.domains),
              "r": [d.r for d in model.domains], "unknowns": model.r,
              "joint_elements": int(joints.tets.shape[0]),
              "joint_layer": int(joints.tets.shape[0] if model.cubature is None
                                 else model.cubature.of),
              "size": model.size,
              **checked_header(model, gravity)}
    write_arrays(path, arrays, header)
    return header


def _mesh_arrays(scene, mesh=None, masses=None, held=None):
    """The arrays of the mesh a file moves: the scene's, or a display `mesh` with its
    `masses` (n,) kg and `held` (n, 3) flags."""
    if mesh is None:
        mesh, masses, held = scene.mesh, scene.masses, scene.fixed_mask
    return {"rest_positions": mesh.vertices, "masses": np.asarray(masses, np.float64),
            "held": held.astype(np.uint8), "tets": mesh.tets.astype(np.int32),
            "surface": runtime.surface_triangles(mesh.vertices, mesh.tets).astype(np.int32)}


def _framed_display(model, display):
    """The arrays of write_framed for a display mesh: its own mesh arrays (lumped masses in
    the scene's density; a vertex held where every node that weighs in it is held), each
    vertex's model nodes and weights, and the model's rest positions."""
    scene = model.scene
    nodes, weights = node_weights(scene.mesh, display.vertices)
    weighs = np.abs(weights) > 1e-12
    held = np.all(~weighs | (model.labels[nodes] < 0), axis=1)
    return {**_mesh_arrays(scene, display, _display_masses(scene, display),
                           np.repeat(held[:, None], 3, axis=1)),
            "display_nodes": nodes.astype(np.int32), "display_weights": weights,
            "physics_rest": model.x0}


def framed_arrays(model, tag=""):
    """The arrays of a FramedModel that framed_runtime.FramedSimulator steps (names + tag):
    its domains' labels, rest offsets Y, bases U, moments and polynomials, its kinematic tree
    and its joint elements (module framed_runtime)."""
    D, joints = model.domains, model._joint_elements
    P = [d.polynomial for d in D]
    sizes = np.array([[p.C2.size, p.S3.size, p.W4.size] for p in P])
    arrays = {
        "labels": model.labels.astype(np.int32), "Y": model._Y, "U": model._U,
        "r": np.array([d.r for d in D], np.int32), "centre": np.array([d.centre for d in D]),
        "mass": model._mass, "a": model._a, "J": model._J, "A": model._A, "B": model._B,
        "radius": model._radius, "reach": model._reach,
        "c0": np.array([p.c0 for p in P]), "c1": np.concatenate([p.c1 for p in P]),
        "C2": np.concatenate([p.C2.ravel() for p in P]),
        "S3": np.concatenate([p.S3.ravel() for p in P]),
        "W4": np.concatenate([p.W4.ravel() for p in P]),
        "poly_offsets": np.vstack([np.zeros((1, 3), np.int64),
                                   np.cumsum(sizes, axis=0)[:-1]]).astype(np.int32),
        "parent": model.parent.astype(np.int32), "order": model._order.astype(np.int32),
        "arm_parent": model._arm_parent, "arm_own": model._arm_own,
        "chain": model._chain.astype(np.int32), "arms": model._arms,
        "joint_tets": model.joint_nodes[joints.tets].astype(np.int32),
        "joint_grads": joints.grads, "joint_weights": joints.weights,
        "mu": joints.mu, "lam": joints.lam, "kappa": joints.kappa, "fiber": joints.fiber}
    return {name + tag: value for name, value in arrays.items()}


def bake_framed(name, out, angles):
    """Write the framed models (anisofem.reduced.FramedModel) of the baked scene `name` at each
    fiber angle (degrees from x towards z) as out.json and out.bin, for the browser page: the
    mesh arrays once, framed_arrays once per angle as NAME@A. Returns the header."""
    angles, scenes = _angle_scenes(name, angles)
    arrays, checks, unknowns = {}, [], []
    for angle, scene in zip(angles, scenes):
        model = FramedModel(scene)
        arrays.update(framed_arrays(model, f"@{angle:g}"))
        checks.append(dataclasses.asdict(model.validation))
        unknowns.append(model.r)
    arrays.update(_mesh_arrays(model.scene))
    mesh = model.scene.mesh
    header = {"model_format": FRAMED_FORMAT, "scene": name, "title": SCENES[name][0],
              "n": mesh.n_vertices, "m": mesh.n_tets, "domains": len(model.domains),
              "fiber_angles": angles, "r": unknowns, "size": model.size,
              "validation": checks, "dt": DT, "gravity": list(GRAVITY)}
    write_arrays(out, arrays, header)
    return header
