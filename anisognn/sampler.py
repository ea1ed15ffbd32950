"""Training scenes sampled on the fly (paper section 3.3), seeded and reproducible.

Sample i of a Sampler with seed s depends on (s, i) only, so a resumed or data-parallel run
draws exactly the samples an uninterrupted one would.

Each sample: one of 36 beam geometries (box and cylinder, 60-120 tets, about 1 cm elements,
held at the x = 0 end) made of the paper's material (E = 100 kPa, nu = 0.48, 1000 kg/m^3) with
fibers of random direction and stiffness kappa in [0, 10 E] (uniform over the scene, or varying
element by element, or rotating along the beam); a uniform body force of random direction and
magnitude in [0, 10] kN/m^3, an extra force in [0, 15] kN/m^3 on 5% of the elements, and with
probability 0.1 a +z traction on the free end. The paper gives that traction as 0-100 kN/m^3;
here it is that force density times the mean edge length h (N/m^2), which puts it on the scale
of the body forces.
Half of the samples start from a pre-deformed state with kinetic and elastic energy: anisofem's
backward-Euler rollout under another random load for 1-15 steps. With probability
equilibrium_probability (default 0, not in the paper) a sample instead starts at the static
equilibrium of its own scene under its loads scaled by a factor in [1 - s, 1 + s]
(s = equilibrium_spread): the states at which a rollout comes to rest, where the evaluation
measures tip, force and volume errors and a rollout of dynamic states rarely lands. Then
zero-mean Gaussian noise perturbs the free positions and velocities with standard deviations
drawn uniformly from [0, noise_position h] and [0, noise_velocity h / s]: the paper's absolute
1e-3 m and 5e-2 m/s would drown 1 cm elements, so the noise is relative to the element size.
"""
from dataclasses import dataclass

import numpy as np
from anisofem import Material, Scene, box_beam, cylinder_beam, simulate, solve

from .model import check_integer

YOUNG = 1e5
POISSON = 0.48
DENSITY = 1000.0


@dataclass
class SamplerConfig:
    """Ranges of the sampled scenes (see module docstring); units as named."""
    body_force: float = 10e3           # N/m^3, uniform per scene
    extra_force: float = 15e3          # N/m^3, per element
    extra_force_probability: float = 0.05
    traction_density: float = 100e3    # N/m^3, times h gives N/m^2
    traction_probability: float = 0.1
    fiber_stiffness: float = 10.0      # in units of E
    varying_fiber_probability: float = 0.5
    deformed_probability: float = 0.5
    deform_steps: int = 15
    equilibrium_probability: float = 0.0
    equilibrium_spread: float = 0.5    # load factor in [1 - spread, 1 + spread]
    noise_position: float = 1e-3       # in units of h
    noise_velocity: float = 5e-2       # in units of h per second
    dt: float = 0.02

    def __post_init__(self):
        for name in ("extra_force_probability", "traction_probability",
                     "varying_fiber_probability", "deformed_probability",
                     "equilibrium_probability"):
            if not 0 <= getattr(self, name) <= 1:
                raise ValueError(f"[sampler] {name}: must be in [0, 1], got "
                                 f"{getattr(self, name)}")
        for name in ("body_force", "extra_force", "traction_density", "fiber_stiffness",
                     "equilibrium_spread", "noise_position", "noise_velocity"):
            if not getattr(self, name) >= 0:
                raise ValueError(f"[sampler] {name}: must be >= 0, got {getattr(self, name)}")
        check_integer(self, "deform_steps", 1, "[sampler] ")
        if not self.dt > 0:
            raise ValueError(f"[sampler] dt: must be > 0 s, got {self.dt}")


@dataclass
class Sample:
    """A scene and the state (x, v) (n, 3) in m and m/s from which one step is taken."""
    scene: Scene
    x: np.ndarray
    v: np.ndarray


def geometries():
    """The 36 training meshes: 18 box beams and 18 cylinder beams of 60-120 tets."""
    meshes = []
    for length in (0.08, 0.1, 0.12):
        for cells in ((6, 2, 1), (8, 2, 1), (12, 2, 1), (3, 2, 2), (5, 2, 2), (6, 2, 2)):
            nx, ny, nz = cells
            meshes.append(box_beam(size=(length, 0.02, 0.01 * nz), cells=cells))
        for along, section, rings in ((3, 2, 0), (6, 2, 0), (4, 1, 1), (3, 1, 1), (2, 2, 1),
                                      (5, 2, 0)):
            meshes.append(cylinder_beam(length, 0.01, along, section, rings))
    return meshes


class Sampler:
    """Random training samples; sample(i) is a pure function of (seed, i)."""

    def __init__(self, seed=0, config=None):
        self.seed = int(seed)
        self.config = config or SamplerConfig()
        self.use_meshes(geometries())

    def use_meshes(self, meshes):
        """Draw the scenes from meshes (a list of anisofem meshes held at x = 0) instead."""
        self.meshes = list(meshes)
        self._h = [float(np.mean(np.linalg.norm(
            m.vertices[m.edges[:, 0]] - m.vertices[m.edges[:, 1]], axis=1)))
            for m in self.meshes]

    def sample(self, index):
        """Sample number index (an int >= 0)."""
        rng = np.random.default_rng([self.seed, int(index)])
        k = int(rng.integers(len(self.meshes)))
        mesh, h = self.meshes[k], self._h[k]
        material = self._material(rng, mesh)
        fixed = mesh.vertices[:, 0] <= 1e-9
        c = self.config
        x = mesh.vertices.copy()
        v = np.zeros_like(x)
        # no draw when equilibrium_probability is 0: earlier configs keep their samples
        at_rest = c.equilibrium_probability > 0 and rng.random() < c.equilibrium_probability
        if not at_rest and rng.random() < c.deformed_probability:
            before = Scene(mesh, material, fixed=fixed, **self._loads(rng, mesh, h))
            roll = simulate(before, int(rng.integers(1, c.deform_steps + 1)), dt=c.dt,
                            warn=False)
            x, v = roll.positions[-1].copy(), roll.velocities[-1].copy()
        loads = self._loads(rng, mesh, h)
        scene = Scene(mesh, material, fixed=fixed, **loads)
        if at_rest:
            x = self._equilibrium(mesh, material, fixed, loads,
                                  rng.uniform(1 - c.equilibrium_spread, 1 + c.equilibrium_spread))
        free = ~scene.fixed_mask
        x[free] += _noise(rng, free.sum(), c.noise_position * h)
        v[free] += _noise(rng, free.sum(), c.noise_velocity * h)
        return Sample(scene, x, v)

    def _material(self, rng, mesh):
        c = self.config
        m = mesh.n_tets
        kind = rng.random()
        if kind >= c.varying_fiber_probability:  # one fiber for the whole scene
            return Material(YOUNG, POISSON, DENSITY, _unit(rng, 1)[0],
                            rng.uniform(0, c.fiber_stiffness) * YOUNG)
        if kind < c.varying_fiber_probability / 2:  # each element its own fiber
            return Material(YOUNG, POISSON, DENSITY, _unit(rng, m),
                            rng.uniform(0, c.fiber_stiffness, m) * YOUNG)
        # fibers rotating about a random axis along the beam (a helix when the axis is x)
        axis = _unit(rng, 1)[0]
        start = _unit(rng, 1)[0]
        centers = mesh.vertices[mesh.tets].mean(axis=1)
        angle = rng.uniform(-np.pi, np.pi) * centers[:, 0] / centers[:, 0].max()
        d = _rotate(start, axis, angle)
        return Material(YOUNG, POISSON, DENSITY, d, rng.uniform(0, c.fiber_stiffness) * YOUNG)

    @staticmethod
    def _equilibrium(mesh, material, fixed, loads, factor):
        """(n, 3) m: the static equilibrium under loads scaled by factor (Newton's last iterate
        if it does not converge: an energy-decreasing state is still a training state)."""
        scaled = {key: value * factor if key in ("body_force", "traction") else value
                  for key, value in loads.items()}
        return solve(Scene(mesh, material, fixed=fixed, **scaled), max_iter=50).x.copy()

    def _loads(self, rng, mesh, h):
        c = self.config
        m = mesh.n_tets
        body = np.tile(_unit(rng, 1) * rng.uniform(0, c.body_force), (m, 1))
        extra = rng.random(m) < c.extra_force_probability
        body[extra] += _unit(rng, extra.sum()) * rng.uniform(0, c.extra_force, (extra.sum(), 1))
        loads = {"body_force": body}
        if rng.random() < c.traction_probability:
            tip = mesh.vertices[:, 0].max()
            loads["traction"] = np.array([0.0, 0.0, rng.uniform(0, c.traction_density) * h])
            loads["traction_faces"] = mesh.faces_where(lambda p: p[:, 0] >= tip - 1e-9)
        return loads


def _noise(rng, d, largest):
    """(d,) white zero-mean noise over the free DOFs, its standard deviation drawn uniformly
    from [0, largest] (largest's units)."""
    direction = rng.normal(size=d)
    return direction * rng.uniform(0, largest)


def _unit(rng, k):
    """(k, 3) directions uniform on the sphere."""
    d = rng.normal(size=(k, 3))
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def _rotate(d, axis, angle):
    """Rodrigues: d (3,) rotated about the unit axis by angle (m,) radians -> (m, 3)."""
    cos, sin = np.cos(angle)[:, None], np.sin(angle)[:, None]
    return (d * cos + np.cross(axis, d) * sin + axis * np.dot(axis, d) * (1 - cos))
