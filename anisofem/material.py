"""Transversely isotropic material: StVK base plus one family of fibers."""
import numpy as np

from ._validate import as_float_array, per_element

#: Tolerance on |d| - 1 for fiber directions of elements with fiber_stiffness > 0.
UNIT_TOLERANCE = 1e-6


class Material:
    """Saint Venant-Kirchhoff base material reinforced by fibers.

    Every parameter is a scalar or a per-element array (one value per tet), so fibers and
    stiffness may vary element by element.

    Parameters
    ----------
    young : Young's modulus E of the base material, Pa (> 0).
    poisson : Poisson's ratio nu, in (-1, 0.5).
    density : mass density, kg/m^3 (> 0).
    fiber_direction : unit fiber direction d in the rest (material) frame, (3,) or (m, 3).
        Required to be unit length wherever fiber_stiffness > 0; ignored elsewhere.
    fiber_stiffness : kappa in psi_fiber = kappa (d^T C d - 1)^2, Pa (>= 0). The paper samples
        kappa in [0, 10 E].
    """

    def __init__(self, young=1e5, poisson=0.48, density=1000.0, fiber_direction=(1.0, 0.0, 0.0),
                 fiber_stiffness=0.0):
        self.young = as_float_array(young, "young")
        self.poisson = as_float_array(poisson, "poisson")
        self.density = as_float_array(density, "density")
        self.fiber_direction = as_float_array(fiber_direction, "fiber_direction")
        self.fiber_stiffness = as_float_array(fiber_stiffness, "fiber_stiffness")
        if (self.young <= 0).any():
            raise ValueError(f"young: Young's modulus must be > 0 Pa, got min {self.young.min()}")
        if (self.poisson >= 0.5).any() or (self.poisson <= -1).any():
            raise ValueError("poisson: Poisson's ratio must lie in (-1, 0.5), got "
                             f"range [{self.poisson.min()}, {self.poisson.max()}]")
        if (self.density <= 0).any():
            raise ValueError(f"density: must be > 0 kg/m^3, got min {self.density.min()}")
        if (self.fiber_stiffness < 0).any():
            raise ValueError("fiber_stiffness: kappa must be >= 0 Pa, got min "
                             f"{self.fiber_stiffness.min()}")
        if self.fiber_direction.shape[-1:] != (3,) or self.fiber_direction.ndim > 2:
            raise ValueError("fiber_direction: expected shape (3,) or (m, 3), got "
                             f"{self.fiber_direction.shape}")
        norms = np.linalg.norm(self.fiber_direction, axis=-1)
        try:
            norms, active = np.broadcast_arrays(norms, self.fiber_stiffness > 0)
        except ValueError:
            raise ValueError("fiber_direction, fiber_stiffness: per-element arrays of "
                             "different lengths") from None
        bad = (np.abs(norms - 1.0) > UNIT_TOLERANCE) & active
        if bad.any():
            worst = float(norms[bad].flat[0])
            kind = "zero" if worst == 0 else "not unit length"
            raise ValueError(f"fiber_direction: {kind} (|d| = {worst:.6g}) where "
                             f"fiber_stiffness > 0; pass d / |d|")

    @classmethod
    def paper(cls, fiber_direction=(1.0, 0.0, 0.0), fiber_stiffness=0.0):
        """The paper's rubber-like base: E = 100 kPa, nu = 0.48; density 1000 kg/m^3 (the paper
        does not state one)."""
        return cls(1e5, 0.48, 1000.0, fiber_direction, fiber_stiffness)

    def __repr__(self):
        def show(a):
            return f"{float(a):g}" if a.ndim == 0 else f"array{a.shape}"
        return (f"Material(young={show(self.young)}, poisson={show(self.poisson)}, "
                f"density={show(self.density)}, fiber_direction="
                f"{self.fiber_direction.tolist() if self.fiber_direction.ndim == 1 else 'array'}"
                f", fiber_stiffness={show(self.fiber_stiffness)})")

    def per_element(self, m):
        """Broadcast to m elements: dict of mu, lam, kappa, density (m,) and fiber (m, 3)."""
        young = per_element(self.young, "young", m)
        nu = per_element(self.poisson, "poisson", m)
        return {
            "mu": young / (2.0 * (1.0 + nu)),
            "lam": young * nu / ((1.0 + nu) * (1.0 - 2.0 * nu)),
            "kappa": per_element(self.fiber_stiffness, "fiber_stiffness", m),
            "fiber": per_element(self.fiber_direction, "fiber_direction", m, width=3),
            "density": per_element(self.density, "density", m),
        }
