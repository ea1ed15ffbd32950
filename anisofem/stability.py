"""Whether a state is a minimum of its potential or a saddle: the smallest eigenpair of the
Hessian of G over the free components (the true Hessian, not its PSD projection), by Lanczos
iteration (ARPACK through scipy), warm-started from the previous eigenvector when there is one.

Newton uses it twice (anisofem.methods.Newton): where the true Hessian is indefinite and the
projected iterations stall, the eigenvector is a direction of negative curvature to step along;
and where a solve meets its tolerance at a state whose last true Hessian was indefinite, a
negative eigenvalue means a saddle, which the solve leaves along the eigenvector."""
import math
from dataclasses import dataclass

import numpy as np
import scipy.sparse.linalg as spla

#: an eigenvalue above -ROUNDOFF times the Hessian's largest diagonal entry counts as zero
ROUNDOFF = 1e-9
#: Lanczos restarts before the smallest eigenvalue is called unknown
MAX_LANCZOS = 5000


@dataclass
class Stability:
    """smallest: the smallest eigenvalue of the free Hessian at the state, N/m; scale: the
    Hessian's largest diagonal entry, N/m; vector: the unit eigenvector (unknown order), None
    where Lanczos did not converge."""
    smallest: float
    scale: float
    vector: np.ndarray = None

    @property
    def minimum(self):
        """No direction of negative curvature beyond round-off found: a minimum, not a saddle
        (also where Lanczos did not converge: smallest is then NaN)."""
        return not self.smallest < -ROUNDOFF * self.scale

    def __repr__(self):
        kind = "minimum" if self.minimum else "saddle"
        return f"Stability({kind}, smallest eigenvalue {self.smallest:.4g} N/m)"


def stability(potential, x, start=None):
    """The Stability of positions x (n, 3) for potential (an anisofem.potential.Potential);
    start: a guess of the eigenvector (unknown order), e.g. the last one."""
    layout = potential.scene.layout("csr")
    data = potential.hessian_data(x, layout, want_grad=False)[2]
    H = layout.matrix(data)
    scale = float(H.diagonal().max())
    if H.shape[0] < 16:
        values, vectors = np.linalg.eigh(H.toarray())
        return Stability(float(values[0]), scale, vectors[:, 0])
    try:
        values, vectors = spla.eigsh(H, k=1, which="SA", v0=start, tol=1e-6,
                                     maxiter=MAX_LANCZOS)
    except spla.ArpackNoConvergence:
        return Stability(math.nan, scale)
    return Stability(float(values[0]), scale, vectors[:, 0])
