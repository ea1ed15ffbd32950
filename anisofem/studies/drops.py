"""Drop tests of contact: the 0.2 m beam, the T and a tentacle-like rod (Neo-Hookean, fibers
along x), dropped onto the ground and obstacles or onto each other, and what each rollout
shows (every step converged, the nearest gaps, no intersection, nothing inverted).
"""
import numpy as np

from ..physics.material import Material
from ..physics.mesh import TetMesh
from ..physics.meshgen import box_beam, cylinder_beam, t_shape

#: The bodies a drop test takes.
KINDS = ("beam", "tee", "rod")
#: The bodies' material: Neo-Hookean (never inverted), 100 kPa, fibers along x.
MATERIAL = Material(1e5, 0.45, 1000.0, np.array([1.0, 0, 0]), 1e5, model="neohookean")
#: A quarter turn about z, m/m: the upper body of a stack lies across the lower one.
ACROSS = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])


def body(kind):
    """The TetMesh of a body (KINDS): the 0.2 m beam (20 x 2 x 2 cells) along x, the T
    (meshgen.t_shape, standing in the x-z plane), a 0.2 m rod of radius 15 mm along x."""
    if kind == "beam":
        return box_beam(size=(0.2, 0.02, 0.02), cells=(20, 2, 2))
    if kind == "tee":
        return t_shape()
    if kind == "rod":
        return cylinder_beam(length=0.2, radius=0.015)
    raise ValueError(f"kind: expected one of {KINDS}, got {kind!r}")


def lying(kind):
    """The body's rest positions (n, 3), m, lying still on the ground z = 0 (the T on its side,
    its plane horizontal), centred on the z axis."""
    mesh = body(kind)
    X = mesh.vertices
    if kind == "tee":
        X = X @ np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]]).T
    X = X - [0.0, 0.0, X[:, 2].min()]
    X[:, :2] -= X[:, :2].mean(axis=0)
    return X, mesh.tets


def stacked(lower, upper, gap=0.02, above=1e-4):
    """(TetMesh of two bodies, how many vertices the lower has): `lower` lying on the ground,
    `above` m over it, and `upper` across it (turned a quarter about z), `gap` m higher."""
    A, a_tets = lying(lower)
    B, b_tets = lying(upper)
    A = A + [0.0, 0.0, above]
    B = B @ ACROSS.T + [0.0, 0.0, A[:, 2].max() + gap]
    return TetMesh(np.vstack([A, B]), np.vstack([a_tets, b_tets + len(A)])), len(A)


def fall_steps(g, dt, height=0.03):
    """Steps of dt s that a drop from `height` m at g m/s^2 takes three times over, and five
    more: the fall, the impact and the rest after it."""
    return int(round(np.sqrt(2 * height / g) * 3 / dt)) + 5
