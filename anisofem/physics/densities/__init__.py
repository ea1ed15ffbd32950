"""Energy densities at a point: a base law (one module each) plus the fiber term.

Each base module gives, at one quadrature point,
- ``stress(F, mu, lam, S) -> psi``: the energy density (J/m^3) of the deformation gradient F
  (3, 3) and its 2nd Piola-Kirchhoff stress S (3, 3), Pa;
- ``hessian(G, n, w, mu, lam, F, [S,] project, work, He)``: adds w times its tangent dP/dF,
  contracted with the point's shape gradients G (n, 3), to the element Hessian He (3n, 3n),
  blocks a <= b (exact, or PSD-projected at the point).
The element loop (anisofem.physics.kernels) sums them over an element's quadrature points; it knows
nothing of the law. A new base law is one module here, its name in MODELS and its branch in
point_stress and point_hessian.
"""
from numba import njit

from . import fiber, neohookean, stvk

#: Base laws by code (ElementData.model, anisofem.Material's model names).
MODELS = ("stvk", "neohookean")
STVK, NEOHOOKEAN = 0, 1


@njit(cache=True, inline="always")
def point_stress(model, F, mu, lam, S):
    """The base law `model`'s psi (J/m^3) and stress S (filled) at F."""
    if model == NEOHOOKEAN:
        return neohookean.stress(F, mu, lam, S)
    return stvk.stress(F, mu, lam, S)


@njit(cache=True, inline="always")
def point_hessian(model, G, n, w, mu, lam, kappa, s2, d, F, S, Fd, project, work, He):
    """Add the point's Hessian blocks (base law and fiber term) to He; S is the total stress
    (base and fiber), Fd = F d and s2 the fibers' squared rest stretch (read only where kappa
    != 0). StVK projects the total stress
    in its geometric part, so the fiber adds only its material part there; Neo-Hookean's
    eigenmodes leave the fiber's geometric part to the fiber."""
    if model == NEOHOOKEAN:
        neohookean.hessian(G, n, w, mu, lam, F, project, work, He)
    else:
        stvk.hessian(G, n, w, mu, lam, F, S, project, work, He)
    if kappa != 0.0:
        fiber.hessian(G, n, w, kappa, s2, d, Fd, model == NEOHOOKEAN, project, He)
