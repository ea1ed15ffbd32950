"""Write tests/data's curved meshes, made by Gmsh: an octant of a thick hollow sphere (inner
radius 10 mm, outer 20 mm) at element size 3 mm, shell_octant_1.msh (linear tets) and
shell_octant_2.msh (the same at second order: Gmsh's midside nodes on the curved surfaces,
so its quadratic tets are curved), where tests/test_curved.py checks Lame's solution; and
hemisphere_quarter_2.msh, the quarter x, y >= 0 of the lower half of a 10 mm ball at second
order, its elements 0.15 mm at the bottom pole growing to 2 mm a radius away, where
tests/test_contact.py checks Hertz. Gmsh is not one of the library's dependencies: pip
install gmsh to run this.

    python scripts/make_curved_meshes.py
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


def hemisphere(path, fine=1.5e-4, coarse=2e-3):
    """The quarter x, y >= 0 of the ball of radius INNER about (0, 0, INNER) below its centre,
    at second order, its element size fine at the bottom pole growing to coarse a radius
    away."""
    gmsh.initialize()
    gmsh.option.setNumber("General.Terminal", 0)
    gmsh.model.add("hemisphere quarter")
    ball = gmsh.model.occ.addSphere(0, 0, INNER, INNER)
    box = gmsh.model.occ.addBox(0, 0, 0, INNER, INNER, INNER)
    gmsh.model.occ.intersect([(3, ball)], [(3, box)])
    gmsh.model.occ.synchronize()
    size = gmsh.model.mesh.field.add("MathEval")
    gmsh.model.mesh.field.setString(size, "F", f"{fine} + ({coarse} - {fine}) * "
                                               f"Min(1, Sqrt(x*x + y*y + z*z) / {INNER})")
    gmsh.model.mesh.field.setAsBackgroundMesh(size)
    for option in ("Mesh.MeshSizeExtendFromBoundary", "Mesh.MeshSizeFromPoints",
                   "Mesh.MeshSizeFromCurvature"):
        gmsh.option.setNumber(option, 0)
    gmsh.model.mesh.generate(3)
    gmsh.model.mesh.setOrder(2)
    gmsh.write(path)
    gmsh.finalize()
    print(f"wrote {path}")


def main():
    folder = os.path.join(HERE, "..", "tests", "data")
    os.makedirs(folder, exist_ok=True)
    for order in (1, 2):
        octant(order, os.path.join(folder, f"shell_octant_{order}.msh"))
    hemisphere(os.path.join(folder, "hemisphere_quarter_2.msh"))


if __name__ == "__main__":
    main()
