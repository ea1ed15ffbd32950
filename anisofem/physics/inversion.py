"""Whether a state is physical: each tet's volume ratio det F, and how many are turned inside
out. Saint Venant-Kirchhoff energy depends on F only through F^T F, so an element and its
mirror image have the same energy, and under hard compression Newton can converge to an
equilibrium with inverted elements that no real material reaches."""
from dataclasses import dataclass

import numpy as np


def volume_change(mesh, x):
    """(m,) relative volume change det(F) - 1 of each tet (0: volume kept); for quadratic tets,
    where F varies, the smallest over the element's quadrature points."""
    x = np.asarray(x, dtype=float)
    if mesh.order == 2:
        F = np.einsum("eai,epaj->epij", x[mesh.cells], mesh.point_gradients)
        return np.linalg.det(F).min(axis=1) - 1.0
    t = mesh.tets
    a, b, c = (x[t[:, k]] - x[t[:, 0]] for k in (1, 2, 3))  # (m, 3) edge vectors
    # the triple product a . (b x c) by components (np.cross costs 4x more on small meshes)
    det = (a[:, 0] * (b[:, 1] * c[:, 2] - b[:, 2] * c[:, 1])
           + a[:, 1] * (b[:, 2] * c[:, 0] - b[:, 0] * c[:, 2])
           + a[:, 2] * (b[:, 0] * c[:, 1] - b[:, 1] * c[:, 0]))
    return det / (6.0 * mesh.rest_volumes) - 1.0


#: An element whose volume ratio det F is below this is degenerate (nearly flat).
DEGENERATE_J = 0.01


@dataclass
class Inversion:
    """How far a state is from physical: inverted, the tets with det F <= 0 (turned inside out:
    no real material gets there); degenerate, those with det F < DEGENERATE_J (inverted ones
    included); min_volume_ratio, the smallest det F."""
    inverted: int
    degenerate: int
    min_volume_ratio: float

    @property
    def physical(self):
        return self.inverted == 0


def inversion(mesh, x):
    """The Inversion of positions x (n, 3) m on mesh."""
    ratio = volume_change(mesh, x) + 1.0
    return Inversion(int((ratio <= 0).sum()), int((ratio < DEGENERATE_J).sum()),
                     float(ratio.min()))
