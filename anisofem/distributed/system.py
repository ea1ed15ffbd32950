"""A scene's potential G (statics, or one backward-Euler step) on one rank: its elements through
anisofem's element loop, its rows of the gradient and Hessian as PETSc's parallel vector and
matrix, and the positions of the nodes its elements read from the other ranks.

Positions live in a full (n, 3) array on every rank, of which a rank keeps up to date the nodes
its elements read (its own and their neighbours across the split): a Newton step's direction
comes back from PETSc as the owned part of a parallel vector and is scattered to those nodes.
"""
import time
from dataclasses import replace

import numpy as np

from ..physics import kernels
from ..physics.assembly import CsrLayout
from ..physics.mesh import block_coloring


class RankSystem:
    """G of scene on this rank's part (anisofem.distributed.partition).

    x_hat, dt: a backward-Euler step's inertial target (n, 3) in m and step in s, or None for
    statics. The Hessian's sparsity (this rank's rows, all their columns) and the position of
    every element-matrix entry in it are worked out once here.
    """

    def __init__(self, scene, part, comm, x_hat=None, dt=None):
        from petsc4py import PETSc
        self.PETSc, self.comm, self.scene, self.part = PETSc, comm, scene, part
        e = part.elements
        full = scene.elements
        starts, ptr = block_coloring(scene.mesh.tets[e], scene.mesh.n_vertices)
        self.elements = replace(
            full, tets=full.tets[e], grads=full.grads[e], weights=full.weights[e],
            model=full.model[e], mu=full.mu[e], lam=full.lam[e], kappa=full.kappa[e],
            rest2=full.rest2[e], fiber=full.fiber[e], block_starts=starts, color_ptr=ptr)
        self.owned = part.owned_nodes
        self.owned_free = part.dof[self.owned] >= 0                  # (k, 3)
        #: (N_r,) the flat index 3 i + c of each free DOF this rank owns, in its vector's order
        self.owned_flat = (3 * self.owned[:, None] + np.arange(3))[self.owned_free]
        self.f_ext = np.ascontiguousarray(scene.external_force[self.owned])
        #: wall time spent in this rank's assembly (energies, gradients, Hessians), s
        self.assembly_seconds = 0.0
        self.at_step(x_hat, dt)
        self._layout()
        self._scatter_setup()
        bs_ok = (self.owned_free.all(axis=1) | ~self.owned_free.any(axis=1)).all()
        self.block_size = 3 if comm.tompi4py().allreduce(bool(bs_ok), op=_mpi_land()) else 1

    def at_step(self, x_hat, dt):
        """Make this G a backward-Euler step's (x_hat (n, 3) in m, dt in s), or statics'
        (both None)."""
        self.dynamic = dt is not None
        if self.dynamic:
            self.x_hat = np.ascontiguousarray(x_hat[self.owned])
            self.mass_over_dt2 = self.scene.masses[self.owned] / dt ** 2
            #: M / dt^2 on the owned free DOFs, the Hessian's inertia (N/m)
            self.inertia_diagonal = np.repeat(self.mass_over_dt2, 3)[self.owned_free.ravel()]
        else:
            self.x_hat, self.mass_over_dt2 = kernels.EMPTY_GRAD, np.empty(0)

    # ---- structure ------------------------------------------------------------------------
    def _layout(self):
        """This rank's CSR rows (indptr, global column indices), each element entry's position
        in its data (hess_map, -1 for rows of other ranks and fixed DOFs), the diagonal: the
        serial CsrLayout of this rank's elements, cut to the rows this rank owns. The layout
        is built on the nodes renumbered in the partition's order, in which the global DOF
        numbering rises with the node number as CsrLayout's rows need."""
        part = self.part
        renumber = np.empty_like(part.order)
        renumber[part.order] = np.arange(part.order.size)
        layout = CsrLayout(renumber[self.elements.tets], part.dof[part.order])
        lo, hi = layout.indptr[part.start], layout.indptr[part.stop]
        IntType = self.PETSc.IntType
        self.indptr = (layout.indptr[part.start:part.stop + 1] - lo).astype(IntType)
        self.indices = layout.indices[lo:hi].astype(IntType)
        mine = (layout.map >= lo) & (layout.map < hi)
        self.hess_map = np.where(mine, layout.map - lo, -1).astype(layout.map.dtype)
        self.diagonal = layout.diag[part.start:part.stop] - lo
        self._matrix = None

    def _scatter_setup(self):
        """The scatter of a parallel vector's entries to the DOFs this rank's elements read,
        and where those sit in the flat positions array."""
        PETSc, part = self.PETSc, self.part
        dof = part.dof.ravel()
        read = np.zeros(dof.size, bool)
        read[(3 * self.elements.tets[:, :, None] + np.arange(3)).ravel()] = True
        flat = np.flatnonzero(read & (dof >= 0))
        self.read_flat, read_dofs = flat, dof[flat]
        self.vector = PETSc.Vec().createMPI((part.n_owned, part.n_free), comm=self.comm)
        self.read_vector = PETSc.Vec().createSeq(flat.size, comm=PETSc.COMM_SELF)
        index = PETSc.IS().createGeneral(read_dofs.astype(PETSc.IntType), comm=PETSc.COMM_SELF)
        self.scatter = PETSc.Scatter().create(self.vector, index, self.read_vector, None)

    # ---- evaluation -----------------------------------------------------------------------
    def moved(self, x, p, t):
        """Positions x (n, 3) moved by t times the direction p (a parallel vector of free DOFs)
        at the nodes this rank reads; p must have been spread by spread(p) first."""
        y = x.copy()
        y.ravel()[self.read_flat] += t * self._spread
        return y

    def spread(self, p):
        """Fetch the entries of p (parallel vector) that this rank's elements read."""
        self.scatter.scatter(p, self.read_vector, addv=self.PETSc.InsertMode.INSERT_VALUES,
                             mode=self.PETSc.ScatterMode.FORWARD)
        self._spread = self.read_vector.getArray().copy()

    def energy_gradient(self, x, want_grad=True):
        """(G(x) in J, summed over ranks; the gradient as a parallel vector, or None)."""
        start = time.perf_counter()
        e_iso, e_fib, grad = kernels.assemble(x, self.elements, want_grad=want_grad)
        local = float((e_iso + e_fib)[self.part.counted].sum())
        grad_owned = grad[self.owned] if want_grad else kernels.EMPTY_GRAD
        external, kinetic = kernels.loads_and_inertia(
            np.ascontiguousarray(x[self.owned]), self.f_ext, self.mass_over_dt2, self.x_hat,
            grad_owned)
        self.assembly_seconds += time.perf_counter() - start
        total = self.comm.tompi4py().allreduce(local + external + kinetic)
        if not want_grad:
            return total, None
        g = self.vector.duplicate()
        g.setArray(grad_owned[self.owned_free])
        return total, g

    def hessian(self, x, project):
        """This rank's rows of d2G/dx2 at x (N/m) (PSD-projected element Hessians where
        project), as this system's one PETSc AIJ matrix: made with its sparsity at the first
        call, its values overwritten at the later ones."""
        PETSc = self.PETSc
        start = time.perf_counter()
        data = np.zeros(self.indices.size)
        kernels.assemble(x, self.elements, want_hess=True, project=project,
                         hess_map=self.hess_map, hess_data=data)
        if self.dynamic:
            data[self.diagonal] += self.inertia_diagonal
        if self._matrix is None:
            n_owned, n = self.part.n_owned, self.part.n_free
            self._matrix = PETSc.Mat().createAIJ(
                size=((n_owned, n), (n_owned, n)), bsize=self.block_size,
                csr=(self.indptr, self.indices, data), comm=self.comm)
            self._matrix.setOption(PETSc.Mat.Option.SYMMETRIC, True)
        else:
            self._matrix.setValuesCSR(self.indptr, self.indices, data)
            self._matrix.assemble()
        self.assembly_seconds += time.perf_counter() - start
        return self._matrix

    def rigid_body_modes(self, x):
        """PETSc's rigid-body near-null space at positions x (n, 3), or None where the DOFs do
        not come in whole nodes (block size 1)."""
        if self.block_size != 3:
            return None
        coordinates = self.vector.duplicate()
        coordinates.setBlockSize(3)
        coordinates.setArray(x[self.owned][self.owned_free])
        return self.PETSc.NullSpace().createRigidBody(coordinates)

    def force_scale(self, x_start):
        """Newton's force scale (anisofem.physics.potential.Potential.force_scale) at x_start, N:
        the norms over free DOFs of the external, elastic and inertial forces, summed."""
        _, _, elastic = kernels.assemble(x_start, self.elements, want_grad=True)
        parts = [self.f_ext, elastic[self.owned]]
        if self.dynamic:
            parts.append(self.mass_over_dt2[:, None] * (x_start[self.owned] - self.x_hat))
        squares = [float(np.sum(p[self.owned_free] ** 2)) for p in parts]
        return float(np.sum(np.sqrt(self.comm.tompi4py().allreduce(np.array(squares)))))

    def gather(self, x):
        """The full positions (n, 3) on every rank: each rank's owned free DOFs of x, the
        fixed ones at their prescribed positions."""
        values = np.concatenate(self.comm.tompi4py().allgather(x[self.owned][self.owned_free]))
        dof = self.part.dof.ravel()
        out = self.scene.initial_positions()
        free = np.flatnonzero(dof >= 0)
        out.ravel()[free] = values[dof[free]]
        return out


def _mpi_land():
    from mpi4py import MPI
    return MPI.LAND
