"""Contact in a linear reduced model: the FEM's barrier and friction against rigid obstacles
(anisofem.physics.contact) evaluated at the surface nodes' positions x_s = x0_s + U_s q, their
gradient U_s^T g_s and Hessian sum_i U_i^T H_i U_i over the nodes within the barrier's reach
(the others contribute nothing: their distances are the broad phase), and the step's
continuous collision test along the reduced step, exact because the positions are linear in q:
a reduced step p moves each surface node by U_i p. Cost per evaluation: O(k r) for the k
surface nodes' positions, O(c r^2) for the c nodes in contact.

Self-contact (and contact between the bodies of one mesh) is subspace self-contact (Teng,
Otaduy and Kim 2014) by the FEM's ipctk pairs (anisofem.physics.self_contact) at x0 + U q:
gradient U^T g, Hessian U_c^T H_c U_c over the c nodes of the pairs within dhat, the
collision test ipctk's along the reduced step's straight move. Its broad phase runs once for
as long as the surface's shape changes by less than a margin (NearPairs): a carried gripper
moves centimetres with its pairs found a few times.

A reduced step minimizes the exact quartic plus these terms by Newton with a backtracking
search (ReducedModel._newton, extra terms), its first trial clipped to the collision-free
share of the step. Friction is lagged at the step's start, as in the FEM.
"""
import math

import numpy as np

from ..physics.contact import ContactTerm
from ..physics.obstacles import SHAPES
from ..physics.scene import ROUNDOFF_FACTOR
from ..physics.self_contact import NearPairs, SelfContact, collision_mesh

#: The share of the contact's energy below which two of its values cannot be told apart.
NOISE = 1e-12

#: NearPairs' margin over the contact distance: the surface's shape may change by this much
#: before its broad phase runs again.
MARGIN_SHARE = 4.0


class ReducedContact:
    """The contact of a ReducedModel's scene: term (the FEM's ContactTerm), U (k, 3, r) the
    surface nodes' basis rows, x0 (k, 3) their rest positions, and with self-contact the
    basis (n, 3, r), the rest positions (n, 3) and the NearPairs of the whole mesh. carrying
    (n,) bool: the vertices a translation of the held vertices carries (ReducedModel.step's
    carried)."""

    def __init__(self, scene, x0, basis, carrying):
        if any(not isinstance(o, SHAPES) for o in scene.contact.obstacles):
            raise ValueError("scene: the reduced model takes contact with planes, spheres, "
                             "boxes, capsules and itself, not surface obstacles; step it with "
                             "the FEM")
        self.term = ContactTerm(scene)
        nodes = self.term.nodes
        r = basis.shape[1]
        self.basis = basis.reshape(-1, 3, r)
        self.U = np.ascontiguousarray(self.basis[nodes])
        self.U2 = self.U.reshape(-1, r)
        self.x0 = x0[nodes]
        self.nodes_carried = carrying[nodes, None].astype(float)
        self.rest, self.carrying, self.mesh, self.near = x0, carrying, scene.mesh, None
        if scene.contact.self_contact:
            cm, _, full = collision_mesh(scene.mesh)
            self.near = NearPairs(cm, self.term.dhat, MARGIN_SHARE * self.term.dhat)
            self.surface_rest, self.surface_carried = x0[full], carrying[full]
            self.surface_basis = np.ascontiguousarray(self.basis[full].reshape(-1, r))

    def positions(self, q, shift=None):
        """(k, 3) the surface nodes at coordinates q (r,), the carried ones moved by shift
        (3,), m."""
        x = self.x0 + (self.U2 @ q).reshape(-1, 3)
        return x if shift is None else x + self.nodes_carried * shift

    def surface(self, q, shift=None):
        """(v, 3) the collision mesh's vertices at coordinates q, the carried ones moved by
        shift, m (Fortran order, as ipctk takes them)."""
        V = self.surface_rest + (self.surface_basis @ q).reshape(-1, 3)
        if shift is not None:
            V += self.surface_carried[:, None] * shift
        return np.asfortranarray(V)

    def touching(self, q_lag=None, dt=None, shift=None, lag_shift=None):
        """The terms of one solve (a Touching for the obstacles, a TouchingPairs for
        self-contact), the carried vertices moved by shift (3,) m: with dt, friction lagged at
        q_lag, the carried vertices then moved by lag_shift."""
        terms = []
        if self.term.obstacles:
            terms.append(Touching(self, self.term if dt is None else self.term.lagged(
                self.positions(q_lag, lag_shift), dt), shift))
        if self.near is not None:
            term, contact = self.term, self.term.contact
            lagged = dt is not None and contact.friction > 0
            lag = None
            if lagged:
                lag = self.rest + (self.basis @ q_lag)
                if lag_shift is not None:
                    lag += self.carrying[:, None] * lag_shift
            terms.append(TouchingPairs(self, SelfContact(
                self.mesh, term.dhat, term.kappa, x_lag=lag,
                mu=contact.friction, eps=term.smoothing(dt) if lagged else None,
                near=self.near), shift))
        return terms


class Touching:
    """The contact's part of one reduced solve, in the interface of ReducedModel's extra
    terms: gradient, hessian, change, limit."""

    def __init__(self, contact, term, shift=None):
        self.contact, self.term, self.shift = contact, term, shift
        self._at = (None, 0.0, None)     # (q, energy, slope) of the last derivatives

    def where(self, q):
        """(k, 3) the surface nodes at coordinates q, m."""
        return self.contact.positions(q, self.shift)

    def placed(self, q):
        """where(q), from the last gradient's when q is its q."""
        at = self._at[0]
        return self._x if at is not None and np.array_equal(at, q) else self.where(q)

    def energy(self, q):
        """The contact's energy at q, J (inf where a node reached an obstacle, or the surface
        met itself)."""
        return self.term.surface_energy(self.where(q))[0]

    def gradient(self, q):
        """dE/dq (r,), N, at q (kept for hessian and change at the same q)."""
        x = self.where(q)
        energy, g = self.term.surface_energy(x)
        slope = self.contact.U2.T @ g.ravel()
        self._at = (q.copy(), energy, slope)
        self._x = x
        return slope

    def hessian(self, q):
        """(d2E/dq2 (r, r) N/m, the gradient's round-off floor N) at q, the q of the last
        gradient: each node's exact Hessian block projected on its basis rows (the step clamps
        the whole Hessian's negative eigenvalues; clamping each block's, a curved obstacle's
        tangential curvature, left Newton crawling: 61 iterations for a step of the page's
        tentacle); the floor ROUNDOFF_FACTOR eps R |H| (R the largest coordinate), which
        float64 cannot resolve in a barrier's force."""
        x = self._x
        live = np.flatnonzero(self.term.in_reach(x))
        U = self.contact.U[live]
        H = np.einsum("kir,kij,kjs->rs", U, self.term.surface_hessians(x[live], live),
                      U)
        return H, _floor(x, H)

    def change(self, q, step):
        """E(q + step) - E(q), J; its first-order part g . step where the two differ by less
        than the energies' round-off (NOISE of them): a search near convergence compares the
        exact quartic's change with it, which round-off would otherwise swamp."""
        at, energy, slope = self._at
        if at is None or not np.array_equal(at, q):
            energy, slope = self.energy(q), None
        after = self.energy(q + step)
        linear = None if slope is None else float(slope @ step)
        if (linear is not None and np.isfinite(after)      # inf: the step reached an obstacle
                and abs(after - energy - linear) <= NOISE * max(abs(after), abs(energy))):
            return linear
        return after - energy

    def limit(self, q, p):
        """The largest share in (0, 1] of the step p (r,) from q that keeps every surface
        node clear of the obstacles (anisofem.physics.obstacles.first_touch)."""
        return self.term.surface_max_step(self.placed(q), self.contact.U @ p)

    def moved_share(self, q_from, before, q_to):
        """The share in (0, 1] of the straight move from q_from, the carried vertices at shift
        `before` (3,), to q_to at this solve's shift that keeps every surface node clear of
        the obstacles."""
        start = self.contact.positions(q_from, before)
        return self.term.surface_max_step(start, self.contact.positions(q_to, self.shift) - start)


class TouchingPairs(Touching):
    """Self-contact's part of one reduced solve: term a SelfContact (ipctk's pairs, with the
    solve's lagged friction) over the collision mesh's vertices at x0_c + U_c q (where)."""

    def where(self, q):
        """(v, 3) the collision mesh's vertices at coordinates q, m."""
        return self.contact.surface(q, self.shift)

    def gradient(self, q):
        """dE/dq (r,), N, at q (its pairs kept for hessian at the same q)."""
        V = self.where(q)
        self._pairs = self.term.collisions(V)
        energy, g = self.term.surface_energy(V, self._pairs)
        slope = self.contact.surface_basis.T @ g
        self._at = (q.copy(), energy, slope)
        self._x = V
        return slope

    def hessian(self, q):
        """(d2E/dq2 (r, r) N/m, the gradient's round-off floor N) at q, the q of the last
        gradient: the pairs' Hessian projected on the basis rows of the nodes they join."""
        V = self._x
        B = self.contact.surface_basis
        H = np.zeros((B.shape[1], B.shape[1]))
        for part in self.term.hessian_parts(V, self._pairs):   # over its entries (CSC)
            col = np.repeat(np.arange(part.shape[1]), np.diff(part.indptr))
            H += B[part.indices].T @ (part.data[:, None] * B[col])
        return H, _floor(V, H)

    def limit(self, q, p):
        """The largest share in (0, 1] of the step p (r,) from q along which no two parts of
        the surface come nearer than a tenth of their nearest distance now (ipctk)."""
        V = self.placed(q)
        return self.term.surface_max_step(V, V + (self.contact.surface_basis @ p).reshape(
            V.shape))

    def moved_share(self, q_from, before, q_to):
        """1: the carried move is taken with the whole mesh translated (ReducedModel._newton),
        which changes no distance between its parts."""
        return 1.0


def _floor(x, H):
    """The round-off floor of a contact gradient, N: ROUNDOFF_FACTOR eps R |H|, R the largest
    coordinate of the positions x (m), |H| the Frobenius norm of its reduced Hessian."""
    return (ROUNDOFF_FACTOR * np.finfo(float).eps * float(np.abs(x).max())
            * math.sqrt(float((H * H).sum())))
