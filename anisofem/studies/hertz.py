"""Hertz's contact of a soft ball on a rigid plane, the check of contact's force: a quarter
(x, y >= 0) of the lower half of a ball of radius R about (0, 0, R), on rollers on its cut
planes, its equator held and pushed down by `push` onto a plane half the contact distance
below its pole. The force the plane takes (the barrier's, times 4 for the quarter) against
Hertz's 4/3 E / (1 - nu^2) sqrt(R) d^(3/2), d the indentation: the push less the starting gap
and the gap the barrier leaves at the pole.
"""
import numpy as np

from ..physics.contact import Contact, ContactTerm
from ..physics.material import Material
from ..physics.obstacles import Plane
from ..physics.scene import Scene
from ..solvers.solve import solve

#: The ball's Young's modulus, Pa, and Poisson's ratio.
YOUNG, POISSON = 1e5, 0.3


def pressed(mesh, radius, push, distance):
    """(force N, Hertz's force N, the solve's NewtonResult) of the quarter ball `mesh` (its
    equator at z = radius, its pole at the origin) pushed down by `push` m onto the plane,
    with the contact distance `distance` m."""
    X = mesh.vertices
    held = np.zeros((mesh.n_vertices, 3), bool)
    held[:, 0] = np.abs(X[:, 0]) < 1e-9 * radius
    held[:, 1] = np.abs(X[:, 1]) < 1e-9 * radius
    equator = np.abs(X[:, 2] - radius) < 1e-9 * radius
    held[equator] = True
    moved = X.copy()
    moved[equator, 2] -= push
    start = 0.5 * distance
    scene = Scene(mesh, Material(YOUNG, POISSON, 1000.0), fixed=held, fixed_positions=moved,
                  contact=Contact([Plane((0.0, 0.0, -start), name="plane")],
                                  distance=distance))
    result = solve(scene, warn=False)
    term = ContactTerm(scene)
    grad = np.zeros_like(X)
    term.energy(result.x, grad)
    force = -4.0 * float(grad[:, 2].sum())
    d = push - start - float(term.distances(result.x).min())
    return force, 4.0 / 3.0 * YOUNG / (1 - POISSON ** 2) * np.sqrt(radius) * d ** 1.5, result
