"""Quantities the paper evaluates: tip displacement, imbalanced force and energy split (the
uniaxial rod's closed form and FEM curve are anisofem.studies.uniaxial's, the volume change
anisofem.physics.inversion's)."""
from dataclasses import dataclass

import numpy as np

from .potential import Potential, check_positions, gradient


def end_vertices(mesh, axis=0, side="max"):
    """Indices of the vertices on the min or max end of the mesh along axis (0, 1, 2)."""
    c = mesh.vertices[:, axis]
    tol = 1e-9 * mesh.size
    if side == "max":
        return np.flatnonzero(c >= c.max() - tol)
    if side == "min":
        return np.flatnonzero(c <= c.min() + tol)
    raise ValueError(f"side: expected 'min' or 'max', got {side!r}")


#: Vertices whose displacement is within this fraction of the largest form the tip of a state.
TIP_FRACTION = 0.99


def moving_tip(u):
    """Indices of the vertices whose displacement u (n, 3), m, is within TIP_FRACTION of the
    largest: a loaded cantilever's free end, on any mesh of it."""
    size = np.linalg.norm(u, axis=1)
    return np.flatnonzero(size >= TIP_FRACTION * size.max())


def tip_displacement(mesh, x, axis=0):
    """Mean displacement (3,) in m of the vertices at the free (max) end along axis."""
    x = np.asarray(x, dtype=float)
    tip = end_vertices(mesh, axis, "max")
    return (x[tip] - mesh.vertices[tip]).mean(axis=0)


@dataclass
class ImbalancedForce:
    """Norms of the per-vertex residual force dG/dx at free components, N."""
    max: float
    mean: float
    per_vertex: np.ndarray  # (n,); 0 at fully fixed vertices


def imbalanced_force(scene, x, x_hat=None, dt=None):
    """Per-vertex imbalanced force |dG/dx_i| over free components (paper Table 2); max and mean
    are taken over vertices with at least one free component."""
    g = gradient(scene, x, x_hat, dt)
    g[scene.fixed_mask] = 0.0
    norms = np.linalg.norm(g, axis=1)
    active = ~scene.fixed_mask.all(axis=1)
    return ImbalancedForce(float(norms[active].max()), float(norms[active].mean()), norms)


def energy_split(scene, x, x_hat=None, dt=None):
    """Energy terms in J, a dict: "isotropic", "fiber", "external" (-f_ext . x), "kinetic" (0 in
    statics) and "total"."""
    terms = Potential(scene, x_hat, dt).terms(check_positions(scene, x))
    terms.pop("elements")
    return terms
