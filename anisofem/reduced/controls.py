"""A reduced model's controls: each one's part of the energy kept apart from the polynomial and
scaled at run time, so that a controller changes it every step and the energy stays exact.

A pressure p on a cavity adds p times the cubic of its volume change (polynomial.
pressure_terms); an activation a of a set of elements adds b times a quadratic of q plus b^2
times a constant, b = 1 - (1 - a)^2 = a (2 - a) (polynomial.activation_terms). With controls
u, the model's energy is the polynomial with c1 + sum_k beta_k c1_k, C2 + sum_k beta_k C2_k
and S3 + sum_k beta_k S3_k (beta_k: p for a pressure, b for an activation): forming them costs
r^2 per control, and r^3 per pressure.

A cable's T L(q) is not a polynomial: L = sum_j |a_j + D_j q| over its s segments, the
routing points' positions linear in q (CablePart). Its energy, gradient and Hessian cost
O(s r^2) per evaluation, and a step with a pulled cable is Newton with a backtracking search
on the energy itself (ReducedModel), not on the exact quartic along the step.
"""
from dataclasses import dataclass

import numpy as np

from ..physics.cables import tension_value
from ..physics.controls import activation_value, control_mapping, control_number
from ..physics.potential import Potential
from .polynomial import Polynomial, activation_terms, pressure_terms

#: The kinds of control a reduced model takes.
KINDS = ("pressure", "activation", "tension")


@dataclass
class ControlPart:
    """One control's part of a reduced model's energy: name, kind (KINDS), value (as the
    scene wrote it), c0 J, c1 (r,) N, C2 (r, r) N/m, S3 (r, r, r) N/m^2 or None (an
    activation's part is quadratic), per unit of its coefficient (coefficient(value)), and
    constant J, an activation's energy per unit of the coefficient squared."""
    name: str
    kind: str
    value: float
    c0: float
    c1: np.ndarray
    C2: np.ndarray
    S3: np.ndarray = None
    constant: float = 0.0

    def coefficient(self, value):
        """What the part is scaled by at the control's value: a pressure's value, Pa; an
        activation a's b = a (2 - a)."""
        return value if self.kind == "pressure" else value * (2.0 - value)

    def checked(self, value):
        """value as this control's number; ValueError naming it otherwise."""
        return (control_number(value, self.name) if self.kind == "pressure"
                else activation_value(value, self.name))


@dataclass
class CablePart:
    """A cable's part of a reduced model's energy, T L(q) with L(q) = sum_j |a_j + D_j q|:
    name, value (the tension the scene wrote, N), a (s, 3) its segments at x0, m, D (s, 3, r)
    their rate in q."""
    name: str
    value: float
    a: np.ndarray
    D: np.ndarray
    kind = "tension"
    S3 = None

    def coefficient(self, value):
        return value

    def checked(self, value):
        """value as a tension; ValueError naming the cable otherwise."""
        return tension_value(value, self.name)

    def _segments(self, q):
        d = self.a + self.D @ q                                   # (s, 3)
        l = np.linalg.norm(d, axis=1)
        return d / np.where(l > 0, l, 1.0)[:, None], l

    def length(self, q):
        """L(q), m."""
        return float(self._segments(q)[1].sum())

    def change(self, q, step):
        """L(q + step) - L(q), m, without the cancellation of the difference: each segment's
        (|d + e|^2 - |d|^2) / (|d + e| + |d|) = (2 d . e + |e|^2) / (|d + e| + |d|)."""
        d = self.a + self.D @ q
        e = self.D @ step
        moved = d + e
        size = np.linalg.norm(moved, axis=1) + np.linalg.norm(d, axis=1)
        return float(np.sum(np.einsum("si,si->s", 2.0 * d + e, e)
                            / np.where(size > 0, size, 1.0)))

    def slope(self, q):
        """dL/dq (r,): the reduced force of a unit tension, N per N."""
        t, _ = self._segments(q)
        return np.einsum("si,sir->r", t, self.D)

    def hessian(self, q):
        """d2L/dq2 (r, r), 1/m: sum_j D_j^T (I - t_j t_j^T) / l_j D_j."""
        t, l = self._segments(q)
        P = (np.eye(3) - t[:, :, None] * t[:, None, :]) / np.where(l > 0, l, np.inf)[:, None,
                                                                                        None]
        return np.einsum("sir,sij,sjt->rt", self.D, P, self.D)


def control_parts(scene, x0, basis):
    """The control parts (a tuple, in the order of scene.controls) of a scene's named
    pressures, activations (ControlPart) and cables (CablePart) at positions x0 + basis q, x0
    (n, 3) m, basis (3n, r)."""
    parts = []
    for cavity in scene.pressures:
        if cavity.name:
            c0, c1, C2, S3 = pressure_terms(cavity, x0, basis)
            parts.append(ControlPart(cavity.name, "pressure", cavity.magnitude, c0, c1, C2, S3))
    for activation in scene.activations:
        share = np.zeros(scene.mesh.n_tets)
        share[activation.elements] = 1.0
        (c0, c1, C2), constant = activation_terms(scene.elements, share, x0, basis)
        parts.append(ControlPart(activation.name, "activation", activation.value, c0, c1, C2,
                                 constant=constant))
    U = basis.reshape(-1, 3, basis.shape[1])
    for cable in scene.cables:
        rest = np.einsum("pk,pki->pi", cable.weights, x0[cable.nodes])
        rows = np.einsum("pk,pkir->pir", cable.weights, U[cable.nodes])
        parts.append(CablePart(cable.name, cable.tension, np.diff(rest, axis=0),
                               np.diff(rows, axis=0)))
    return tuple(parts)


def control_responses(scene, x0, factor, free):
    """(N, k) the static response -K^-1 f_k of the free unknowns to each control, f_k the
    force of a unit of its coefficient at x0 (n, 3) (a pressure of 1 Pa; an activation's b =
    1), K^-1 by factor (splu of the free Hessian): the directions a basis needs to follow
    its controls to first order. The force is the difference of two FEM gradients: exact,
    since the gradient is affine in each coefficient."""
    unset = passive(scene)
    rest = Potential(unset).energy_gradient(x0)[1]
    activations = {a.name for a in scene.activations}
    columns = []
    for name in scene.controls:
        value = ACTIVATION_PROBE if name in activations else 1.0
        beta = value * (2.0 - value) if name in activations else value
        pushed = Potential(unset.with_controls({name: value})).energy_gradient(x0)[1]
        columns.append(-factor.solve((pushed - rest).ravel()[free] / beta))
    return np.column_stack(columns) if columns else np.zeros((free.size, 0))


#: The activation control_responses evaluates the gradient at (any in (0, 1) gives the same).
ACTIVATION_PROBE = 0.5


def passive(scene):
    """The scene with its controls at 0 (named pressures, activations, cables): what a
    model's polynomial is built from, its controls' parts kept apart."""
    zero = {name: 0.0 for name in scene.controls}
    return scene.with_controls(zero) if zero else scene


def control_values(parts, values):
    """(k,) the controls' values: each part's written value, replaced by values (a mapping
    name -> value, or one value per part in order; None: as written); ValueError naming the
    control for an unknown name or a bad value."""
    out = np.array([p.value for p in parts], dtype=float)
    if values is None:
        return out
    names = tuple(p.name for p in parts)
    for name, value in control_mapping(values, names).items():
        k = names.index(name)
        out[k] = parts[k].checked(value)
    return out


def controlled(poly, parts, values):
    """The Polynomial of poly plus each part at values (k,) (control_values)."""
    c0, c1, C2, S3 = poly.c0, poly.c1.copy(), poly.C2.copy(), poly.S3
    copied = False
    for part, value in zip(parts, values):
        beta = part.coefficient(value)
        if beta == 0.0 or part.kind == "tension":
            continue
        c0 += beta * part.c0 + beta * beta * part.constant
        c1 += beta * part.c1
        C2 += beta * part.C2
        if part.S3 is not None:
            if not copied:
                S3, copied = S3.copy(), True
            S3 += beta * part.S3
    return Polynomial(c0, c1, C2, S3, poly.W4)
