"""Transversely isotropic material: a StVK or Neo-Hookean base plus one family of fibers."""
import numpy as np

from .._validate import as_float_array, per_element
from .densities import MODELS

#: Tolerance on |d| - 1 for fiber directions of elements with fiber_stiffness > 0.
UNIT_TOLERANCE = 1e-6


class Material:
    """A base material reinforced by fibers.

    Every parameter is a scalar or a per-element array (one value per tet), so fibers, stiffness
    and even the base model may vary element by element.

    The base model (same Lame parameters, same fiber term kappa (I4 - s^2)^2):

    - "stvk", Saint Venant-Kirchhoff, psi = lam/2 tr(E)^2 + mu tr(E^2): the paper's material
      and the one the network is trained on. It depends on F only through C = F^T F, so an
      element and its mirror image have the same energy, and it softens under compression:
      squeezed hard (a cantilever under 10 g, a block pressed to half its height) Newton can
      converge to states with elements turned inside out (det F <= 0), which results report
      (NewtonResult.inversion, InversionWarning). Fine for moderate strains.
    - "neohookean", compressible Neo-Hookean,
      psi = mu/2 (tr C - 3) - mu ln J + lam/2 (ln J)^2 (J = det F), +inf for J <= 0. The
      energy grows without bound as an element flattens, and the line search rejects any
      trial state with J <= 0 (its energy is infinite), so no solve or step ever produces an
      inverted element, whatever the load. Chosen over the Stable Neo-Hookean energy of Smith,
      de Goes and Kim (2018), which stays finite through J <= 0 and so resists inversion
      without excluding it. Its cost: a solve must start from a state with det F > 0
      everywhere (rest is; prescribed positions that jump too far in one step are refused
      with an error), and its Hessian needs one small eigen-decomposition more per element.
      Pick it whenever a scene compresses hard. Both agree to first order in the strain.

    Parameters
    ----------
    young : Young's modulus E of the base material, Pa (> 0).
    poisson : Poisson's ratio nu, in (-1, 0.5).
    density : mass density, kg/m^3 (> 0).
    fiber_direction : unit fiber direction d in the rest (material) frame, (3,) or (m, 3).
        Required to be unit length wherever fiber_stiffness > 0; ignored elsewhere.
    fiber_stiffness : kappa in psi_fiber = kappa (d^T C d - s^2)^2, Pa (>= 0). The paper samples
        kappa in [0, 10 E].
    model : "stvk" (default) or "neohookean", or a per-element sequence of them (m,).
    activation : the fibers' contraction a, in [0, 1): their rest stretch is s = 1 - a, so an
        activated fiber pulls its element shorter along d (an artificial muscle, a contractile
        fiber; Min et al. 2019). 0 (default): passive fibers, s = 1. Only where fibers are
        (fiber_stiffness > 0).
    """

    def __init__(self, young=1e5, poisson=0.48, density=1000.0, fiber_direction=(1.0, 0.0, 0.0),
                 fiber_stiffness=0.0, model="stvk", activation=0.0):
        self.model = _model_codes(model)
        self.activation = as_float_array(activation, "activation")
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
        if not ((self.activation >= 0) & (self.activation < 1)).all():
            bad = self.activation[~((self.activation >= 0) & (self.activation < 1))].flat[0]
            raise ValueError(f"activation: a share in [0, 1) (the fibers' rest stretch is 1 - "
                             f"activation), got {bad}")
        try:
            unfibered = np.broadcast_arrays(self.activation > 0, self.fiber_stiffness == 0)
        except ValueError:
            raise ValueError("activation, fiber_stiffness: per-element arrays of different "
                             "lengths") from None
        if (unfibered[0] & unfibered[1]).any():
            count = int((unfibered[0] & unfibered[1]).sum())
            raise ValueError(f"activation: {count} element{'s are' if count > 1 else ' is'} "
                             f"activated with no fibers (fiber_stiffness 0): only fibers "
                             f"contract")
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
        model = MODELS[int(self.model)] if self.model.ndim == 0 else f"array{self.model.shape}"
        return (f"Material(young={show(self.young)}, poisson={show(self.poisson)}, "
                f"density={show(self.density)}, fiber_direction="
                f"{self.fiber_direction.tolist() if self.fiber_direction.ndim == 1 else 'array'}"
                f", fiber_stiffness={show(self.fiber_stiffness)}, model={model!r}"
                + (f", activation={show(self.activation)}" if self.activation.any() else "")
                + ")")

    def replaced(self, **changes):
        """The same material with some parameters changed (the constructor's names)."""
        model = ([MODELS[int(c)] for c in self.model] if self.model.ndim
                 else MODELS[int(self.model)])
        given = {"young": self.young, "poisson": self.poisson, "density": self.density,
                 "fiber_direction": self.fiber_direction,
                 "fiber_stiffness": self.fiber_stiffness, "model": model,
                 "activation": self.activation}
        unknown = set(changes) - set(given)
        if unknown:
            raise TypeError(f"changes: unknown material parameter {sorted(unknown)[0]!r}")
        return Material(**(given | changes))

    def per_element(self, m):
        """Broadcast to m elements: dict of young, poisson, mu, lam, kappa, density, activation,
        rest2 (the fibers' squared rest stretch) (m,), fiber (m, 3) and model (m,) int8 (index
        into MODELS)."""
        young = per_element(self.young, "young", m)
        nu = per_element(self.poisson, "poisson", m)
        activation = per_element(self.activation, "activation", m)
        return {
            "young": young, "poisson": nu,
            "mu": young / (2.0 * (1.0 + nu)),
            "lam": young * nu / ((1.0 + nu) * (1.0 - 2.0 * nu)),
            "kappa": per_element(self.fiber_stiffness, "fiber_stiffness", m),
            "fiber": per_element(self.fiber_direction, "fiber_direction", m, width=3),
            "density": per_element(self.density, "density", m),
            "model": _per_element_model(self.model, m),
            "activation": activation,
            "rest2": (1.0 - activation) ** 2,
        }


def lame_slopes(mu, lam, d_mu, d_lam):
    """(dX/dyoung, dX/dpoisson) of any X from its slopes d_mu = dX/dmu and d_lam = dX/dlam (per
    Pa) at the Lame parameters mu, lam (Pa; arrays broadcast): mu = E / (2 (1 + nu)) and
    lam = E nu / ((1 + nu) (1 - 2 nu))."""
    young = mu * (3 * lam + 2 * mu) / (lam + mu)
    nu = lam / (2 * (lam + mu))
    return ((mu * d_mu + lam * d_lam) / young,
            -mu / (1 + nu) * d_mu + young * (1 + 2 * nu ** 2) / ((1 + nu) ** 2 * (1 - 2 * nu) ** 2)
            * d_lam)


def _model_codes(model):
    """A model name or a sequence of them as int8 codes (index into MODELS): () or (m,)."""
    names = np.asarray(model, dtype=object)
    if names.ndim > 1 or names.size == 0:
        raise ValueError(f"model: expected one of {MODELS} or a per-element sequence of them, "
                         f"got shape {names.shape}")
    bad = [n for n in names.ravel() if n not in MODELS]
    if bad:
        raise ValueError(f"model: expected one of {MODELS}, got {bad[0]!r}")
    if names.ndim == 0:
        return np.array(MODELS.index(model), dtype=np.int8)
    return np.array([MODELS.index(n) for n in names], dtype=np.int8)


def _per_element_model(codes, m):
    codes = np.asarray(codes)
    if codes.ndim and codes.shape != (m,):
        raise ValueError(f"model: expected one name or {m} per-element names, got "
                         f"{codes.shape[0]}")
    return np.broadcast_to(codes, (m,)).astype(np.int8)
