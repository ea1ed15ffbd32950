"""The scenes the distributed tests solve, built the same way by the test (serially) and by
run_case.py (under mpirun)."""
import math
import os

import meshio
import numpy as np

import anisofem as af
from anisofem.studies.convergence import cantilever

FIBER = (math.cos(math.radians(40)), 0.0, math.sin(math.radians(40)))


def _held(mesh, material):
    return af.Scene(mesh, material, fixed=af.metrics.end_vertices(mesh, 0, "min"),
                    gravity=(0.0, 0.0, -9.81))


def gmsh_part(folder):
    """A gmsh .msh file of the 8 x 2 x 2 box whose tets are in two regions (physical groups 1
    and 2: the near and the far half), as gmsh writes a part of two volumes. Each rank writes
    it under its own name and renames it into place: a rank never reads another's half-written
    file."""
    mesh = af.box_beam(cells=(8, 2, 2))
    near = mesh.vertices[mesh.tets].mean(axis=1)[:, 0] < 0.05
    path = f"{folder}/part.msh"
    mine = f"{folder}/part-{os.getpid()}.msh"
    blocks = [("tetra", mesh.tets[near]), ("tetra", mesh.tets[~near])]
    tags = [np.full(near.sum(), 1), np.full((~near).sum(), 2)]
    meshio.write(mine, meshio.Mesh(mesh.vertices, blocks,
                                   cell_data={"gmsh:physical": tags, "gmsh:geometrical": tags}),
                 file_format="gmsh22", binary=False)
    os.replace(mine, path)
    return path


def scene(name, folder="."):
    """The scene called name."""
    fibers = af.Material(1e5, 0.48, 1000.0, FIBER, 1e5)
    if name == "cantilever":
        return cantilever((10, 2, 2), 1)
    if name == "quadratic":
        return cantilever((6, 2, 2), 2)
    if name == "t":
        return _held(af.t_shape(), fibers)
    if name == "cylinder":
        return _held(af.cylinder_beam(0.1, 0.01, 6, 2, 1), fibers)
    if name == "neohookean":
        return _held(af.box_beam(cells=(8, 2, 2)), af.Material(1e5, 0.45, 1000.0, FIBER, 1e5,
                                                               model="neohookean"))
    if name == "part":
        return _held(af.read_mesh(gmsh_part(folder)), fibers)
    raise ValueError(name)
