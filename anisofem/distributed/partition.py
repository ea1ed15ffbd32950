"""The mesh split over MPI ranks: nodes by PETSc's partitioner (PT-Scotch through
MatPartitioning on the node graph), the free DOFs numbered rank by rank, and each rank's
elements.

Every rank holds the whole scene (mesh, material, loads); what is distributed is the work and
the matrix: rank r owns the free DOFs of its nodes (a contiguous range of the global
numbering, node by node, as PETSc's parallel vectors and matrices want) and evaluates every
element that touches one of its nodes. An element on the boundary between two ranks is so
evaluated on both, and each keeps the rows of its own DOFs: a rank's gradient and Hessian rows
are then complete without any message, and its energy counts the elements whose first node it
owns, so that each element counts once.
"""
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

#: PETSc's MatPartitioning type that splits the node graph (Debian's PETSc has PT-Scotch;
#: "parmetis" where PETSc was built with it)
PARTITIONER = "ptscotch"


@dataclass
class Partition:
    """How one rank sees the split (shapes: n nodes, m elements, N free DOFs in all)."""
    rank: int
    size: int
    owner: np.ndarray       # (n,) rank owning each node
    order: np.ndarray       # (n,) the nodes rank by rank, by index within a rank
    dof: np.ndarray         # (n, 3) global index of each free DOF, -1 where fixed
    start: int              # first global DOF this rank owns
    stop: int               # one past its last
    n_free: int             # N
    elements: np.ndarray    # (m_r,) the elements this rank evaluates (touching its nodes)
    counted: np.ndarray     # (m_r,) bool: their energy is counted here (first node owned)
    owned_nodes: np.ndarray  # (k,) this rank's nodes

    @property
    def n_owned(self):
        return self.stop - self.start


def node_graph(mesh):
    """(n, n) CSR adjacency of the nodes that share an element, without the diagonal."""
    cells = mesh.cells
    k = cells.shape[1]
    a, b = np.meshgrid(np.arange(k), np.arange(k), indexing="ij")
    off = a != b
    rows = cells[:, a[off]].ravel()
    cols = cells[:, b[off]].ravel()
    n = mesh.n_vertices
    graph = sp.csr_matrix((np.ones(rows.size), (rows, cols)), shape=(n, n))
    graph.sum_duplicates()
    graph.data[:] = 1.0
    return graph


def split_nodes(mesh, comm):
    """(n,) owner rank of each node: PT-Scotch's split of the node graph, every rank giving the
    rows of a contiguous block of nodes; the same answer on every rank."""
    from petsc4py import PETSc
    n, size = mesh.n_vertices, comm.getSize()
    if size == 1:
        return np.zeros(n, dtype=np.int64)
    rank = comm.getRank()
    lo, hi = n * rank // size, n * (rank + 1) // size
    rows = node_graph(mesh)[lo:hi]
    adjacency = PETSc.Mat().createAIJ(
        size=((hi - lo, n), (PETSc.DECIDE, n)), comm=comm,
        csr=(rows.indptr.astype(PETSc.IntType), rows.indices.astype(PETSc.IntType), rows.data))
    partitioning = PETSc.MatPartitioning().create(comm)
    partitioning.setAdjacency(adjacency)
    partitioning.setType(PARTITIONER)
    partitioning.setFromOptions()
    parts = PETSc.IS()
    partitioning.apply(parts)
    owner = np.concatenate(comm.tompi4py().allgather(parts.getIndices().astype(np.int64)))
    for obj in (parts, partitioning, adjacency):
        obj.destroy()
    return owner


def partition(scene, comm):
    """This rank's Partition of scene over the ranks of comm (a petsc4py Comm). ValueError
    when the mesh has fewer elements than there are ranks, or a rank would own no DOF."""
    mesh, size, rank = scene.mesh, comm.getSize(), comm.getRank()
    if mesh.n_tets < size:
        raise ValueError(f"mesh: {mesh.n_tets} elements cannot be split over {size} ranks "
                         f"(fewer elements than ranks)")
    owner = split_nodes(mesh, comm)
    free = np.zeros(3 * mesh.n_vertices, bool)
    free[scene.free_dofs] = True
    free = free.reshape(-1, 3)
    order = np.lexsort((np.arange(mesh.n_vertices), owner))  # nodes rank by rank
    numbered = free[order]
    dof = np.full((mesh.n_vertices, 3), -1, dtype=np.int64)
    nodes, components = np.nonzero(numbered)
    dof[order[nodes], components] = np.arange(nodes.size)
    per_rank = np.bincount(np.repeat(owner, 3)[free.ravel()], minlength=size)
    if (per_rank == 0).any():
        raise ValueError(f"mesh: the partition leaves rank {int(np.argmin(per_rank))} without a "
                         f"free DOF; run it on fewer ranks")
    start = int(per_rank[:rank].sum())
    mine = owner == rank
    touching = mine[mesh.cells].any(axis=1)
    elements = np.flatnonzero(touching)
    counted = mine[mesh.cells[elements, 0]]
    return Partition(rank, size, owner, order, dof, start, start + int(per_rank[rank]),
                     int(per_rank.sum()), elements, counted, np.flatnonzero(mine))
