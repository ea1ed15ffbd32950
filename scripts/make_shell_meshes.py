"""Write tests/data's meshes of an octant of a thick hollow sphere (inner radius 10 mm, outer
20 mm), meshed by Gmsh at element size 3 mm: shell_octant_1.msh (linear tets) and
shell_octant_2.msh (the same geometry at second order: Gmsh's midside nodes on the curved
surfaces, so its quadratic tets are curved). tests/test_curved.py checks Lame's solution on
them. Gmsh is not one of the library's dependencies: pip install gmsh to run this.

    python scripts/make_shell_meshes.py
"""
import os

import gmsh

HERE = os.path.dirname(os.path.abspath(__file__))
INNER, OUTER, SIZE = 0.01, 0.02, 0.003


def octant(order, path):
    """The shell's octant x, y, z >= 0 meshed at SIZE, at `order`, written to path."""
    gmsh.initialize()
    gmsh.option.setNumber("General.Terminal", 0)
    gmsh.model.add("shell octant")
    outer = gmsh.model.occ.addSphere(0, 0, 0, OUTER)
    inner = gmsh.model.occ.addSphere(0, 0, 0, INNER)
    shell = gmsh.model.occ.cut([(3, outer)], [(3, inner)])[0]
    box = gmsh.model.occ.addBox(0, 0, 0, 1.5 * OUTER, 1.5 * OUTER, 1.5 * OUTER)
    gmsh.model.occ.intersect(shell, [(3, box)])
    gmsh.model.occ.synchronize()
    gmsh.option.setNumber("Mesh.MeshSizeMax", SIZE)
    gmsh.option.setNumber("Mesh.MeshSizeMin", SIZE)
    gmsh.model.mesh.generate(3)
    if order == 2:
        gmsh.model.mesh.setOrder(2)
    gmsh.write(path)
    gmsh.finalize()
    print(f"wrote {path}")


def main():
    folder = os.path.join(HERE, "..", "tests", "data")
    os.makedirs(folder, exist_ok=True)
    for order in (1, 2):
        octant(order, os.path.join(folder, f"shell_octant_{order}.msh"))


if __name__ == "__main__":
    main()
