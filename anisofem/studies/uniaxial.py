"""A rod in uniaxial tension (paper Fig. 5): the homogeneous closed form of the whole model
(StVK plus the fiber term is StVK with a constant stiffness), the scene that loads a box-shaped
rod so that the FEM should reproduce it, and the FEM's stress-strain curve."""
from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq

from ..physics.material import Material
from ..physics.meshgen import box_beam
from ..physics.metrics import end_vertices
from ..physics.scene import Scene
from ..solvers.solve import solve


@dataclass
class UniaxialState:
    """Homogeneous uniaxial-stress state along x: F (3, 3), total 2nd Piola-Kirchhoff stress
    S (3, 3) in Pa, stretch F_xx, nominal stress P_xx (force per rest area) in Pa."""
    F: np.ndarray
    S: np.ndarray
    stretch: float
    nominal_stress: float


def _stiffness_voigt(young, poisson, d, kappa):
    """6x6 map from Green strain to total 2nd PK stress of psi (constant for this model:
    S = lam tr(E) I + 2 mu E + 8 kappa (d.E d) d d^T). Voigt order 11 22 33 23 13 12, with
    tensor (not engineering) shear strains."""
    mu = young / (2 * (1 + poisson))
    lam = young * poisson / ((1 + poisson) * (1 - 2 * poisson))
    pairs = [(0, 0), (1, 1), (2, 2), (1, 2), (0, 2), (0, 1)]
    D = np.zeros((6, 6))
    for col, (k, l) in enumerate(pairs):
        E = np.zeros((3, 3))
        E[k, l] = E[l, k] = 1.0
        S = lam * np.trace(E) * np.eye(3) + 2 * mu * E + 8 * kappa * (d @ E @ d) * np.outer(d, d)
        D[:, col] = [S[i, j] for i, j in pairs]
    return D, pairs


def uniaxial_analytic(nominal_stress, young=1e5, poisson=0.48, fiber_direction=(1, 0, 0),
                      fiber_stiffness=0.0):
    """Exact homogeneous answer for a rod pulled along x by a dead traction (Pa per rest area)
    with free lateral surfaces: S = diag(s, 0, 0). The model's stress is linear in the Green
    strain, so E = s D^-1 e_x e_x^T; F is the upper-triangular root of C = I + 2E (the frame
    in which x_i = F_ij X_j keeps the x-axis and the x-y plane), and P_xx = s F_xx.
    """
    d = np.asarray(fiber_direction, dtype=float)
    D, pairs = _stiffness_voigt(young, poisson, d, fiber_stiffness)
    c = np.linalg.solve(D, np.eye(6)[0])

    def strain(s):
        E = np.zeros((3, 3))
        for v, (i, j) in zip(c * s, pairs):
            E[i, j] = E[j, i] = v
        return E

    def excess(s):
        return s * np.sqrt(1 + 2 * s * c[0]) - nominal_stress

    if nominal_stress == 0:
        s = 0.0
    elif nominal_stress > 0:
        s = brentq(excess, 0.0, nominal_stress + 1.0, xtol=1e-14, rtol=1e-15)
    else:
        s_min = -1.0 / (3.0 * c[0])  # StVK softens in compression: P_xx is least here
        if excess(s_min) > 0:
            raise ValueError(f"nominal_stress: {nominal_stress} Pa is beyond the material's "
                             f"compressive limit {s_min * np.sqrt(1 / 3):.6g} Pa")
        s = brentq(excess, s_min, 0.0, xtol=1e-14, rtol=1e-15)
    E = strain(s)
    F = np.linalg.cholesky(np.eye(3) + 2 * E).T
    S = np.zeros((3, 3))
    S[0, 0] = s
    return UniaxialState(F, S, float(F[0, 0]), float(s * F[0, 0]))


def uniaxial_bar_scene(mesh, material, nominal_stress):
    """Rod along x loaded by dead tractions +-t e_x on its end faces, held only by six pin
    components that the homogeneous answer leaves unloaded (a corner A fully; the corner at
    the far end along x in y and z; the corner across y from A in z)."""
    X = mesh.vertices
    lo, hi = X.min(0), X.max(0)
    tol = 1e-9 * mesh.size

    def corner(p):
        i = int(np.argmin(np.linalg.norm(X - p, axis=1)))
        if np.linalg.norm(X[i] - p) > tol:
            raise ValueError("mesh: a box-shaped rod with vertices at its corners is needed")
        return i

    a = corner(lo)
    c = corner([hi[0], lo[1], lo[2]])
    b = corner([lo[0], hi[1], lo[2]])
    fixed = np.zeros((mesh.n_vertices, 3), bool)
    fixed[a] = True
    fixed[c, 1:] = True
    fixed[b, 2] = True
    faces_hi = mesh.faces_where(lambda p: p[:, 0] > hi[0] - tol)
    faces_lo = mesh.faces_where(lambda p: p[:, 0] < lo[0] + tol)
    t = np.zeros((len(faces_hi) + len(faces_lo), 3))
    t[: len(faces_hi), 0] = nominal_stress
    t[len(faces_hi):, 0] = -nominal_stress
    return Scene(mesh, material, fixed=fixed, traction=t,
                 traction_faces=np.concatenate([faces_hi, faces_lo]))


def uniaxial_curve(material, nominal_stresses, mesh=None, **newton):
    """FEM stress-strain curve of a rod pulled along x (paper Fig. 5).

    material: a Material with scalar parameters. nominal_stresses: (k,) tractions in Pa.
    mesh: a box-shaped rod along x (default box_beam((0.1, 0.02, 0.02), (10, 2, 2))).
    Returns (stretch (k,), nominal stress (k,)): the stretch is the mean end-face separation
    over the rest length. Each load step starts from the previous answer.
    """
    if not isinstance(material, Material):
        raise TypeError(f"material: expected an anisofem.Material, got "
                        f"{type(material).__name__}")
    mesh = box_beam() if mesh is None else mesh
    stresses = np.asarray(nominal_stresses, dtype=float)
    lo, hi = end_vertices(mesh, 0, "min"), end_vertices(mesh, 0, "max")
    length = mesh.vertices[hi, 0].mean() - mesh.vertices[lo, 0].mean()
    stretch = np.empty(stresses.size)
    x = None
    for k, t in enumerate(stresses):
        result = solve(uniaxial_bar_scene(mesh, material, t), x, **newton)
        if not result.converged:
            raise RuntimeError(f"uniaxial_curve: Newton failed at {t} Pa: {result.message}")
        x = result.x
        stretch[k] = (x[hi, 0].mean() - x[lo, 0].mean()) / length
    return stretch, stresses

