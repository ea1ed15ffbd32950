"""Write the example scene files' meshes next to them, as Gmsh files with named physical groups
(what Gmsh's own Python API would write): actuator.msh (anisofem.physics.meshgen.actuator) and
part.msh (a 0.08 m beam in two halves, "left" and "right", with its ends named "base" and
"end").

    python examples/scenes/make_meshes.py
"""
import os

import numpy as np

from anisofem.io.meshes import write_tagged_mesh
from anisofem.physics.meshgen import actuator, box_beam

HERE = os.path.dirname(os.path.abspath(__file__))


def part_mesh():
    """(mesh, volumes, surfaces, names) of the two-region beam."""
    mesh = box_beam((0.08, 0.02, 0.02), (16, 4, 4))
    X, faces = mesh.vertices, mesh.boundary_faces
    volumes = np.where(X[mesh.tets].mean(axis=1)[:, 0] < 0.04, 1, 2)
    x = X[faces][:, :, 0]
    surfaces = {3: faces[(x < 1e-12).all(axis=1)], 4: faces[(x > 0.08 - 1e-12).all(axis=1)]}
    return mesh, volumes, surfaces, {"left": 1, "right": 2, "base": 3, "end": 4}


MESHES = {"actuator.msh": actuator, "part.msh": part_mesh}

if __name__ == "__main__":
    for name, make in MESHES.items():
        write_tagged_mesh(os.path.join(HERE, name), *make())
        print(f"wrote {os.path.join(HERE, name)}")
