"""Methods that keep a factorization across iterations and steps: "reuse" (FactorReuse) and
"lbfgs" (LBFGS, with the kept factor as its initial inverse Hessian); anisofem.solvers.methods
says what each is for."""
import math

import numpy as np

from .frames import VertexFrames
from .newton_method import Newton

#: Curvature pairs of L-BFGS with s.y below this times |s| |y| are skipped.
CURVATURE_MIN = 1e-10


def _key(potential):
    """What a factor of G's Hessian is valid for: the scene and dt (None: statics)."""
    return potential.scene, getattr(potential, "dt", None)


class KeptFactor(Newton):
    """Newton variants that keep a factorization (`_solve`, None when there is none or it is
    to be renewed) from one solve to the next of the same scene and dt."""

    def __init__(self, **newton):
        super().__init__(**newton)
        self._owner = None

    def start(self, potential):
        super().start(potential)
        scene, dt = _key(potential)
        if self._owner is None or self._owner[0] is not scene or self._owner[1] != dt:
            self._owner, self._solve = (scene, dt), None
            self.first_factor(potential)

    def first_factor(self, potential):
        """Set up the factor the first iteration uses (default none: it factors at once)."""


class FactorReuse(KeptFactor):
    """Newton with the factorization kept across iterations and steps (see the module
    docstring), applied in each vertex's frame rotated since it was made (anisofem.solvers.frames).
    refactor: a step with the kept factor that leaves more than this fraction of the gradient
    norm triggers a fresh factorization at the next iteration."""

    name = "reuse"

    def __init__(self, refactor=0.5, **newton):
        super().__init__(**newton)
        if not 0 < refactor < 1:
            raise ValueError(f"refactor: a fraction in (0, 1), got {refactor}")
        self.refactor = float(refactor)
        self._frames = self._built = None

    def first_factor(self, potential):
        scene = potential.scene
        self._frames = VertexFrames(scene.mesh, scene.free_dofs)

    def refresh(self, x, projected, data=None):
        made = super().refresh(x, projected, data)
        if made and self._frames is not None:  # L-BFGS turns nothing
            self._built = self._frames.rotations(x)
        return made

    def kept(self, x):
        """g -> the kept inverse-Hessian approximation at x applied to g: the kept factor
        turned by the vertex rotations since it was made."""
        return self._frames.carry(self._solve, self._built, x)

    def directions(self, x, g, residual):
        if self._solve is not None:
            self._fresh = False
            yield -self.kept(x)(g)
            self.forget()
        self._fresh = True
        yield from super().directions(x, g, residual)

    def accepted(self, s, y, progress):
        if self._fresh:
            super().accepted(s, y, progress)
        elif progress > self.refactor:
            self._solve = None


class LBFGS(FactorReuse):
    """L-BFGS (see the module docstring): `history` curvature pairs on top of an initial
    inverse Hessian that starts as the factorized rest Hessian and, as in "reuse", is
    refactored at the current state when a step leaves more than `refactor` of the gradient
    norm or fails to make progress."""

    name = "lbfgs"

    def __init__(self, history=5, refactor=0.9, **newton):
        super().__init__(refactor=refactor, **newton)
        if int(history) < 1:
            raise ValueError(f"history: must be >= 1, got {history}")
        self.history = int(history)
        self._pairs = []

    def first_factor(self, potential):
        with self.solver.threads():
            self.refresh(potential.scene.initial_positions(), projected=True)
        self._pairs = []

    def kept(self, x):
        """The L-BFGS inverse Hessian, on the factor as made: turned by the vertex rotations
        it refactored more often and lost accuracy on the 200-tet trade cantilever
        (docs/experiments.md)."""
        return self.apply

    def apply(self, g):
        """H g for the L-BFGS inverse Hessian H (Nocedal and Wright, Algorithm 7.4)."""
        q = g.copy()
        alphas = []
        for s, y, rho in reversed(self._pairs):
            a = rho * float(np.dot(s, q))
            q -= a * y
            alphas.append(a)
        r = self._solve(q)
        for (s, y, rho), a in zip(self._pairs, reversed(alphas)):
            r += (a - rho * float(np.dot(y, r))) * s
        return r

    def forget(self):
        self._pairs = []

    def accepted(self, s, y, progress):
        super().accepted(s, y, progress)
        sy = float(np.dot(s, y))
        if sy > CURVATURE_MIN * math.sqrt(float(np.dot(s, s)) * float(np.dot(y, y))):
            self._pairs.append((s, y, 1.0 / sy))
            del self._pairs[:-self.history]
