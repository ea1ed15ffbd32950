"""Contact in a linear reduced model: the FEM's barrier and friction against rigid obstacles
(anisofem.physics.contact) evaluated at the surface nodes' positions x_s = x0_s + U_s q, their
gradient U_s^T g_s and Hessian sum_i U_i^T H_i U_i over the nodes within the barrier's reach
(the others contribute nothing: their distances are the broad phase), and the step's
continuous collision test along the reduced step, exact because the positions are linear in q:
a reduced step p moves each surface node by U_i p. Cost per evaluation: O(k r) for the k
surface nodes' positions, O(c r^2) for the c nodes in contact.

A reduced step minimizes the exact quartic plus these terms by Newton with a backtracking
search (ReducedModel._newton, extra terms), its first trial clipped to the collision-free
share of the step. Friction is lagged at the step's start, as in the FEM.
"""
import math

import numpy as np

from ..physics.contact import ContactTerm
from ..physics.scene import ROUNDOFF_FACTOR

#: The share of the contact's energy below which two of its values cannot be told apart.
NOISE = 1e-12


class ReducedContact:
    """The contact of a ReducedModel's scene over its surface nodes: term (the FEM's
    ContactTerm), U (k, 3, r) the nodes' basis rows, x0 (k, 3) their rest positions."""

    def __init__(self, scene, x0, basis):
        if scene.contact.pairs:
            raise ValueError("scene: the reduced model takes contact with planes, spheres, "
                             "boxes and capsules, not self-contact or surface obstacles; step "
                             "it with the FEM")
        self.term = ContactTerm(scene)
        nodes = self.term.nodes
        r = basis.shape[1]
        self.U = np.ascontiguousarray(basis.reshape(-1, 3, r)[nodes])
        self.x0 = x0[nodes]

    def positions(self, q):
        """(k, 3) the surface nodes at coordinates q (r,), m."""
        return self.x0 + self.U @ q

    def touching(self, q_lag=None, dt=None):
        """The Touching term of one solve: with dt, friction lagged at q_lag."""
        return Touching(self, self.term if dt is None
                        else self.term.lagged(self.positions(q_lag), dt))


class Touching:
    """The contact's part of one reduced solve, in the interface of ReducedModel's extra
    terms: derivatives, change, limit."""

    def __init__(self, contact, term):
        self.contact, self.term = contact, term
        self._at = (None, 0.0, None)     # (q, energy, slope) of the last derivatives

    def energy(self, q):
        """The barrier's and friction's energy at q, J (inf where a node reached an
        obstacle)."""
        return self.term.surface_energy(self.contact.positions(q))[0]

    def derivatives(self, q):
        """(dE/dq (r,) N, d2E/dq2 (r, r) N/m, the gradient's round-off floor N) at q: each
        node's exact Hessian block projected on its basis rows (the step clamps the whole
        Hessian's negative eigenvalues; clamping each block's, a curved obstacle's tangential
        curvature, left Newton crawling: 61 iterations for a step of the page's tentacle);
        the floor ROUNDOFF_FACTOR eps R |H| (R the largest coordinate), which float64 cannot
        resolve in a barrier's force."""
        x = self.contact.positions(q)
        energy, g = self.term.surface_energy(x)
        slope = np.einsum("kir,ki->r", self.contact.U, g)
        self._at = (q.copy(), energy, slope)
        live = np.flatnonzero(self.term.in_reach(x))
        U = self.contact.U[live]
        H = np.einsum("kir,kij,kjs->rs", U, self.term.surface_hessians(x[live], live),
                      U)
        floor = (ROUNDOFF_FACTOR * np.finfo(float).eps * float(np.abs(x).max())
                 * math.sqrt(float((H * H).sum())))
        return slope, H, floor

    def change(self, q, step):
        """E(q + step) - E(q), J; its first-order part g . step where the two differ by less
        than the energies' round-off (NOISE of them): a search near convergence compares the
        exact quartic's change with it, which round-off would otherwise swamp."""
        at, energy, slope = self._at
        if at is None or not np.array_equal(at, q):
            energy, slope = self.energy(q), None
        after = self.energy(q + step)
        linear = None if slope is None else float(slope @ step)
        if linear is not None and abs(after - energy - linear) <= NOISE * max(abs(after),
                                                                               abs(energy)):
            return linear
        return after - energy

    def limit(self, q, p):
        """The largest share in (0, 1] of the step p (r,) from q that keeps every surface
        node clear of the obstacles (anisofem.physics.obstacles.first_touch)."""
        return self.term.surface_max_step(self.contact.positions(q), self.contact.U @ p)
