"""Write the example scene files' meshes next to them, as Gmsh files with named physical groups
(what Gmsh's own Python API would write): actuator.msh (anisofem.physics.meshgen.actuator),
gripper.msh (two of those actuators hanging on either side of a box), fingers.msh (the two
actuators alone), tee.msh (the T of
anisofem.physics.meshgen.t_shape), part.msh (a 0.08 m beam in two halves, "left" and
"right", with its ends named "base" and "end") and tentacle.msh (a 0.2 m cylinder in four bands around its axis, "up", "down",
"left" and "right", with its ends named "base" and "tip").

    python examples/scenes/make_meshes.py
"""
import os

import numpy as np

from anisofem.io.meshes import write_tagged_mesh
from anisofem.physics.mesh import TetMesh
from anisofem.physics.meshgen import actuator, box_beam, cylinder_beam, t_shape

HERE = os.path.dirname(os.path.abspath(__file__))


def part_mesh():
    """(mesh, volumes, surfaces, names) of the two-region beam."""
    mesh = box_beam((0.08, 0.02, 0.02), (16, 4, 4))
    X, faces = mesh.vertices, mesh.boundary_faces
    volumes = np.where(X[mesh.tets].mean(axis=1)[:, 0] < 0.04, 1, 2)
    x = X[faces][:, :, 0]
    surfaces = {3: faces[(x < 1e-12).all(axis=1)], 4: faces[(x > 0.08 - 1e-12).all(axis=1)]}
    return mesh, volumes, surfaces, {"left": 1, "right": 2, "base": 3, "end": 4}


#: The tentacle's bands: name -> the angle of its middle from +y toward +z, degrees.
BANDS = {"up": 90.0, "down": -90.0, "left": 0.0, "right": 180.0}


def tentacle_mesh():
    """(mesh, volumes, surfaces, names) of the tentacle: a cylinder along x, 0.2 m long and
    15 mm in radius, each tet in the band whose middle is nearest its centroid's angle about
    the axis."""
    mesh = cylinder_beam(length=0.2, radius=0.015, cells_along=16, section_cells=2)
    X, faces = mesh.vertices, mesh.boundary_faces
    center = X[mesh.tets].mean(axis=1)
    angle = np.degrees(np.arctan2(center[:, 2], center[:, 1]))
    apart = np.abs((angle[:, None] - np.array(list(BANDS.values())) + 180.0) % 360.0 - 180.0)
    volumes = 1 + np.argmin(apart, axis=1)
    x = X[faces][:, :, 0]
    surfaces = {5: faces[(x < 1e-12).all(axis=1)], 6: faces[(x > 0.2 - 1e-12).all(axis=1)]}
    names = {name: k + 1 for k, name in enumerate(BANDS)} | {"base": 5, "tip": 6}
    return mesh, volumes, surfaces, names


#: The gripper's box, m: its size along x, y, z; its bottom this far above the ground z = 0.
BOX, LIFTED = (0.03, 0.03, 0.04), 5e-5
#: The gripper's fingers: the gap between each finger's inner face and the box, m; their tips'
#: height above the ground, m.
GAP, TIP = 0.005, 0.012


def fingers_mesh():
    """(mesh, volumes, surfaces, names) of the gripper's fingers alone (meshgen.actuator, 8 cm,
    hanging down, their strain-limiting layers facing each other across the gap the box
    fills, so pressure in their cavities bends them together). Groups: the fingers' bodies
    "left" (y < 0) and "right", their "layer"s, their "cavity" and "base" surfaces."""
    finger, volumes, surfaces, _ = actuator(cells=(8, 4, 12))
    X = finger.vertices * [1.0, -1.0, -1.0]      # turned about x: tip down, layer toward +y
    X += [0.0, -BOX[1] / 2 - GAP - X[:, 1].max(), TIP - X[:, 2].min()]
    turned = X * [-1.0, -1.0, 1.0]                 # the other finger: turned about z
    n = finger.n_vertices
    mesh = TetMesh(np.vstack([X, turned]), np.vstack([finger.tets, finger.tets + n]))
    tags = np.concatenate([volumes, np.where(volumes == 1, 7, volumes)])
    both = {g: np.vstack([surfaces[g], surfaces[g] + n]) for g in (3, 4)}
    return mesh, tags, both, {"left": 1, "layer": 2, "right": 7, "cavity": 3, "base": 4}


def gripper_mesh():
    """(mesh, volumes, surfaces, names) of the gripper: the fingers of fingers_mesh on either
    side of a box standing on the ground z = 0. Groups: fingers_mesh's and the "box"."""
    fingers, tags, surfaces, names = fingers_mesh()
    box = box_beam(BOX, (3, 3, 4))
    B = box.vertices - box.vertices.min(axis=0) + [-BOX[0] / 2, -BOX[1] / 2, LIFTED]
    mesh = TetMesh(np.vstack([fingers.vertices, B]),
                   np.vstack([fingers.tets, box.tets + fingers.n_vertices]))
    return (mesh, np.concatenate([tags, np.full(box.n_tets, 6)]), surfaces,
            dict(names, box=6))


def tee_mesh():
    """(mesh, volumes, surfaces, names) of the T (meshgen.t_shape: 10 cm wide, 8 cm tall,
    standing on z = 0 in the x-z plane), one group "tee"."""
    mesh = t_shape()
    return mesh, np.ones(mesh.n_tets, int), {}, {"tee": 1}


MESHES = {"actuator.msh": actuator, "gripper.msh": gripper_mesh, "fingers.msh": fingers_mesh,
          "tee.msh": tee_mesh, "part.msh": part_mesh, "tentacle.msh": tentacle_mesh}

if __name__ == "__main__":
    for name, make in MESHES.items():
        write_tagged_mesh(os.path.join(HERE, name), *make())
        print(f"wrote {os.path.join(HERE, name)}")
