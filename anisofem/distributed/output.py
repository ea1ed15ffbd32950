"""A distributed result written by every rank: XDMF (the light XML, rank 0) over one HDF5 file
(PETSc's parallel HDF5 viewer) holding the rest positions and displacements of each rank's own
nodes and the cells whose energy it counts, nodes numbered rank by rank (the partition's
order)."""
import os

import numpy as np

from ..io.output import atomic_path

XDMF = """<?xml version="1.0"?>
<Xdmf Version="3.0">
  <Domain>
    <Grid Name="anisofem" GridType="Uniform">
      <Topology TopologyType="{topology}" NumberOfElements="{m}">
        <DataItem Dimensions="{m} {k}" NumberType="Int" Precision="{int_bytes}" Format="HDF">{h5}:/cells</DataItem>
      </Topology>
      <Geometry GeometryType="XYZ">
        <DataItem Dimensions="{n} 3" NumberType="Float" Precision="8" Format="HDF">{h5}:/geometry</DataItem>
      </Geometry>
      <Attribute Name="displacement" AttributeType="Vector" Center="Node">
        <DataItem Dimensions="{n} 3" NumberType="Float" Precision="8" Format="HDF">{h5}:/displacement</DataItem>
      </Attribute>
    </Grid>
  </Domain>
</Xdmf>
"""


def write_xdmf(path, scene, part, comm, x):
    """Write positions x (n, 3) of scene as path (.xdmf) and its .h5 beside it, every rank
    writing its part (part: this rank's Partition)."""
    from petsc4py import PETSc
    mesh = scene.mesh
    h5 = os.path.splitext(path)[0] + ".h5"
    renumbered = np.empty(mesh.n_vertices, dtype=np.int64)
    renumbered[part.order] = np.arange(mesh.n_vertices)
    mine = part.owned_nodes
    viewer = PETSc.Viewer().createHDF5(h5, mode=PETSc.Viewer.Mode.WRITE, comm=comm)
    for name, values in (("geometry", mesh.vertices[mine]),
                         ("displacement", x[mine] - mesh.vertices[mine])):
        vec = PETSc.Vec().createMPI((3 * mine.size, 3 * mesh.n_vertices), bsize=3, comm=comm)
        vec.setArray(values.ravel())
        vec.setName(name)
        vec.view(viewer)
        vec.destroy()
    cells = renumbered[mesh.cells[part.elements[part.counted]]]
    index = PETSc.IS().createGeneral(cells.ravel().astype(PETSc.IntType), comm=comm)
    index.setBlockSize(mesh.cells.shape[1])
    index.setName("cells")
    index.view(viewer)
    index.destroy()
    viewer.destroy()
    if comm.getRank() == 0:
        text = XDMF.format(topology="Tetrahedron" if mesh.order == 1 else "Tetrahedron_10",
                           m=mesh.n_tets, k=mesh.cells.shape[1], n=mesh.n_vertices,
                           int_bytes=PETSc.IntType(0).itemsize, h5=os.path.basename(h5))
        with atomic_path(path) as tmp:
            with open(tmp, "w") as f:
                f.write(text)
    comm.barrier()
