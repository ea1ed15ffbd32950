"""Each vertex's rotation from the rest shape, which carries a kept multigrid hierarchy to a
rotated state (anisofem.solvers.methods.NewtonCG with preconditioner "amg").

A vertex's rotation R_i is the orthogonal polar factor of A_i = sum over its edges e of
d_e D_e^T (current and rest edge vectors, m^2): the rotation that best maps the vertex's rest
star onto its current one (shape matching). Where a neighbourhood turns without straining
much, the Hessian turns with it, H(x) ~ W H(b) W^T with W the block rotation
R_i(x) R_i(b)^T, so a hierarchy built for H(b) serves H(x) as r -> W M_b^-1 (W^T r): a
bending cantilever (tip sag half its length) needed 294 CG iterations to 1e-8 with the
hierarchy built at rest, 47 with it carried so and 39 with a fresh one (docs/experiments.md).
W is orthogonal, so the carried preconditioner stays symmetric positive definite.
"""
import math

import numpy as np
from numba import njit

from ..physics.sym3 import eigen


class VertexFrames:
    """The rotations of a mesh's vertices, and the preconditioners carried by them.

    mesh: the anisofem.TetMesh; free (k,): the free DOFs (flat indices 3 i + c). A vertex with
    only some components free (a roller) keeps the identity: its DOFs do not form a 3-vector."""

    def __init__(self, mesh, free):
        edges = mesh.edges
        self.first, self.second = edges[:, 0], edges[:, 1]
        self.rest_edges = mesh.vertices[self.second] - mesh.vertices[self.first]
        self.n_vertices = mesh.n_vertices
        free = np.asarray(free)
        counts = np.bincount(free // 3, minlength=self.n_vertices)
        self.whole = np.flatnonzero(counts == 3)
        position = np.full(3 * self.n_vertices, -1)
        position[free] = np.arange(free.size)
        #: (w, 3) where the three components of each wholly free vertex sit among the free DOFs
        self.slots = position[3 * self.whole[:, None] + np.arange(3)]

    def rotations(self, x):
        """(n, 3, 3) each vertex's rotation from rest at positions x (n, 3) m."""
        return _star_rotations(x, self.rest_edges, self.first, self.second)

    def carry(self, precondition, built, x):
        """r -> W precondition(W^T r) on the free DOFs, W the block rotation R_i(x) built_i^T
        from the rotations built (n, 3, 3) where precondition was made to those at positions
        x (n, 3)."""
        turn = _relative(self.rotations(x), built, self.whole)
        slots = self.slots
        return lambda r: _turned(turn, slots, precondition(_turned(turn, slots, r, True)), False)


@njit(cache=True)
def _turned(turn, slots, r, transpose):
    """A copy of the free-DOF vector r whose wholly free vertices' components (slots (w, 3))
    are turned by turn (w, 3, 3), or by its transposes."""
    out = r.copy()
    for i in range(slots.shape[0]):
        a, b, c = slots[i, 0], slots[i, 1], slots[i, 2]
        x, y, z = r[a], r[b], r[c]
        T = turn[i]
        if transpose:
            out[a] = T[0, 0] * x + T[1, 0] * y + T[2, 0] * z
            out[b] = T[0, 1] * x + T[1, 1] * y + T[2, 1] * z
            out[c] = T[0, 2] * x + T[1, 2] * y + T[2, 2] * z
        else:
            out[a] = T[0, 0] * x + T[0, 1] * y + T[0, 2] * z
            out[b] = T[1, 0] * x + T[1, 1] * y + T[1, 2] * z
            out[c] = T[2, 0] * x + T[2, 1] * y + T[2, 2] * z
    return out


@njit(cache=True)
def _relative(now, built, whole):
    """(w, 3, 3) now_i built_i^T for the vertices i of whole (w,); now, built (n, 3, 3)."""
    out = np.empty((whole.shape[0], 3, 3))
    for k in range(whole.shape[0]):
        i = whole[k]
        for p in range(3):
            for q in range(3):
                out[k, p, q] = (now[i, p, 0] * built[i, q, 0] + now[i, p, 1] * built[i, q, 1]
                                + now[i, p, 2] * built[i, q, 2])
    return out


@njit(cache=True)
def _star_rotations(x, rest, first, second):
    """(n, 3, 3) the polar rotations of A_i = sum over the edges at vertex i of current_e
    rest_e^T at positions x (n, 3); an edge list (E,) first/second, rest edge vectors (E, 3).
    A reflection (det A_i < 0, an inverted star) flips the axis of the smallest singular
    value; a vertex whose A_i is singular keeps the identity."""
    n = x.shape[0]
    A = np.zeros((n, 3, 3))
    for e in range(rest.shape[0]):
        i, j = first[e], second[e]
        for a in range(3):
            current = x[j, a] - x[i, a]
            for b in range(3):
                value = current * rest[e, b]
                A[i, a, b] += value
                A[j, a, b] += value
    R = np.zeros((n, 3, 3))
    w, V, S = np.empty(3), np.empty((3, 3)), np.empty((3, 3))
    for i in range(n):
        a = A[i]
        for p in range(3):
            for q in range(3):
                S[p, q] = a[0, p] * a[0, q] + a[1, p] * a[1, q] + a[2, p] * a[2, q]
        eigen(S, w, V)
        smallest = 0
        for k in range(1, 3):
            if w[k] < w[smallest]:
                smallest = k
        if w[smallest] <= 1e-24 * max(w[0], w[1], w[2]):  # also all zero, or rounded below
            for k in range(3):
                R[i, k, k] = 1.0
            continue
        det = (a[0, 0] * (a[1, 1] * a[2, 2] - a[1, 2] * a[2, 1])
               - a[0, 1] * (a[1, 0] * a[2, 2] - a[1, 2] * a[2, 0])
               + a[0, 2] * (a[1, 0] * a[2, 1] - a[1, 1] * a[2, 0]))
        for k in range(3):
            scale = (-1.0 if (det < 0.0 and k == smallest) else 1.0) / math.sqrt(w[k])
            for p in range(3):
                u = (a[p, 0] * V[0, k] + a[p, 1] * V[1, k] + a[p, 2] * V[2, k]) * scale
                for q in range(3):
                    R[i, p, q] += u * V[q, k]
    return R
