"""Material parameters identified from measured marker displacements.

Given markers at rest points X_i of a body and their measured displacements m_ci under one or
more load cases c (each a Scene of the same body), fit minimizes

    J(p) = 1/2 sum_c sum_i |u_c(X_i; p) - m_ci|^2 / s_c^2,

u_c the static FEM displacement interpolated at the marker in its tet, s_c the case's largest
measured displacement (so that each case counts by its relative misfit, as a measurement's
noise grows with its range), over chosen parameters
p (Young's modulus, Poisson's ratio, fiber stiffness, fiber azimuth or elevation, each one
value over the whole body), by L-BFGS-B with bounds (scipy.optimize): each evaluation is one
static solve per case, warm-started from the last, and its gradient one adjoint solve
(anisofem.inverse.sensitivity). At the answer the Gauss-Newton Hessian J_r^T J_r, with J_r the
residuals' Jacobian (one back-substitution per residual on one factorization per case),
gives each parameter's standard deviation: sqrt of the diagonal of s^2 (J_r^T J_r)^-1, s^2
the residuals' variance (their sum of squares over their count less the parameters').
"""
import copy
import math
import os
import time
from dataclasses import dataclass

import numpy as np

from . import lbfgsb
from .._validate import as_float_array
from ..physics.material import Material
from ..physics.points import locate
from ..physics.scene import check_scene
from .sensitivity import fiber_angles, fiber_direction, static_jacobian, static_sensitivity
from ..solvers.solve import solve

#: What can be fitted: name -> (unit, how the optimizer sees it: "log" (positive, by its
#: logarithm) or "plain", default bounds in the parameter's unit). Angles are in degrees.
PARAMETERS = {"young": ("Pa", "log", (1e2, 1e10)),
              "poisson": ("", "plain", (-0.99, 0.499)),
              "kappa": ("Pa", "log", (1e-3, 1e12)),
              "fiber_azimuth": ("deg", "plain", (-180.0, 180.0)),
              "fiber_elevation": ("deg", "plain", (-89.0, 89.0))}

#: The optimizer's variable is ZOOM times the parameter (or its logarithm): L-BFGS-B's first
#: trial step has unit length, which is then a factor e in a stiffness, 0.1 in Poisson's
#: ratio and 5 degrees in an angle.
ZOOM = {"young": 1.0, "poisson": 10.0, "kappa": 1.0, "fiber_azimuth": 0.2,
        "fiber_elevation": 0.2}


@dataclass
class FitResult(lbfgsb.Outcome):
    """An Outcome (its history: (iteration, J, values)) and values {name: fitted value} (Pa,
    or degrees for fiber angles); deviations {name: standard deviation from the Gauss-Newton
    Hessian}; marker_residuals (k,) each marker's misfit, m, the markers of all cases in
    order; rms their root mean square, m."""
    values: dict
    deviations: dict
    marker_residuals: np.ndarray
    rms: float


class Markers:
    """Marker rest points (k, 3), m, on a mesh: u (n, 3) -> their displacements (k, 3), and the
    transpose for a gradient."""

    def __init__(self, mesh, points):
        points = as_float_array(points, "markers", shape=(None, 3))
        if points.shape[0] == 0:
            raise ValueError("markers: no marker given")
        tets, weights = locate(mesh, points)
        self.nodes = mesh.cells[tets]                       # (k, s)
        self.shape = mesh.element.shape(weights[:, 1:])     # (k, s)

    def at(self, u):
        return np.einsum("ka,kai->ki", self.shape, u[self.nodes])

    def spread(self, r, n):
        """W^T r: marker vectors r (k, 3) onto the mesh's n nodes, (n, 3)."""
        out = np.zeros((n, 3))
        np.add.at(out, self.nodes.ravel(), (self.shape[:, :, None] * r[:, None, :]).reshape(-1, 3))
        return out


def fit(scenes, markers, measured, names, start=None, bounds=None, max_iter=100,
        progress=None, regions=None, log=None):
    """Fit `names` so that the scenes' (Scenes of one body, one per load case) static
    displacements at marker rest points match the measured ones, m: markers (k, 3) and
    measured (k, 3) for one case, or a list of each, one per case. A name is a key of
    PARAMETERS (one value over the whole body) or "KEY@REGION" (one value over the tets of
    regions[REGION], an (m,) bool mask). start: {name: value} (default: the first scene's,
    the mean over its tets); bounds: {name: (low, high)} (default PARAMETERS'). progress(
    iteration, J, values) after each iteration; log(message) for each trial point whose solve
    failed or ran past its time limit (lbfgsb.trial_limit; the search steps back from it).
    Returns a FitResult (its marker_residuals: the markers of all cases in order)."""
    t0 = time.perf_counter()
    scenes = [scenes] if not isinstance(scenes, (list, tuple)) else list(scenes)
    for s in scenes:
        check_scene(s)
    base = scenes[0]
    if any(not (np.array_equal(s.mesh.cells, base.mesh.cells)
                and np.array_equal(s.mesh.vertices, base.mesh.vertices)) for s in scenes):
        raise ValueError("scenes: the load cases must share one mesh (the same body)")
    names = list(names)
    bad = [n for n in names if n.partition("@")[0] not in PARAMETERS]
    if bad or not names or len(set(names)) != len(names):
        raise ValueError(f"names: expected distinct parameters among {', '.join(PARAMETERS)} "
                         f"(each alone or as KEY@REGION), got {names}")
    masks = _masks(names, regions or {}, base.mesh.n_tets)
    markers, measured = _per_case(markers, measured, len(scenes))
    probes = [Markers(base.mesh, points) for points in markers]
    layout = _Layout(base, names, masks, start or {}, bounds or {})
    problem = _Problem(scenes, probes, measured, layout)
    history = []

    def report(z, J):
        history.append((len(history) + 1, J, layout.values(z)))
        if progress is not None:
            progress(*history[-1])
    answer = lbfgsb.minimize(problem.objective, layout.to_z(layout.start), layout.z_bounds,
                             max_iter, report, log)
    values = layout.values(answer.x)
    residuals, jacobian = problem.residuals_and_jacobian(answer.x)
    count = residuals.size
    variance = float(residuals @ residuals) / max(count - len(names), 1)
    normal = jacobian.T @ jacobian
    try:
        covariance = variance * np.linalg.inv(normal)
        deviations = {n: float(math.sqrt(max(covariance[k, k], 0.0)))
                      for k, n in enumerate(names)}
    except np.linalg.LinAlgError:
        deviations = {n: math.inf for n in names}
    misfit = np.concatenate([r.reshape(-1, 3) / w for r, w in
                             zip(np.split(residuals, problem.ends[:-1]), problem.weight)])  # m
    per_marker = np.linalg.norm(misfit, axis=1)
    return FitResult(int(answer.nit), problem.evaluations, bool(answer.success),
                     str(answer.message), time.perf_counter() - t0, history, values, deviations,
                     per_marker, float(np.sqrt((per_marker ** 2).mean())))


def _shown(values):
    """Parameter values {name: value} as text."""
    return ", ".join(f"{name} = {value:.4g}" for name, value in values.items())


def _masks(names, regions, m):
    """{name: (m,) bool} the tets each fitted name covers (KEY@REGION: the region's)."""
    out = {}
    for n in names:
        _, _, region = n.partition("@")
        if not region:
            out[n] = np.ones(m, bool)
            continue
        if region not in regions:
            raise ValueError(f"names: {n!r} names the region {region!r}, which regions does not "
                             f"hold (it holds: {', '.join(regions) or 'none'})")
        mask = np.asarray(regions[region], dtype=bool)
        if mask.shape != (m,) or not mask.any():
            raise ValueError(f"regions: {region!r} must be a non-empty ({m},) bool mask of tets")
        out[n] = mask
    return out


def _per_case(markers, measured, cases):
    """(markers, measured): lists of (k_c, 3) arrays, one per case, checked."""
    if cases == 1 and not isinstance(markers, (list, tuple)):
        markers, measured = [markers], [measured]
    if not isinstance(markers, (list, tuple)) or not isinstance(measured, (list, tuple)) or \
            len(markers) != cases or len(measured) != cases:
        raise ValueError(f"markers, measured: give one array of each per load case ({cases})")
    points = [as_float_array(m, f"markers[{c}]", shape=(None, 3)) for c, m in enumerate(markers)]
    moved = [as_float_array(m, f"measured[{c}]", shape=(len(points[c]), 3))
             for c, m in enumerate(measured)]
    return points, moved


#: Where a fitted value goes in a scene file's [material] table
MATERIAL_KEYS = {"young": "young", "poisson": "poisson", "kappa": "fiber_stiffness"}


def moved_mesh_path(table, scene_path, output_path):
    """A deep copy of a scene file's table (of the file at scene_path) whose mesh path is
    relative to output_path's folder, for a scene file written there."""
    out = copy.deepcopy(table)
    mesh = os.path.join(os.path.dirname(os.path.abspath(scene_path)), table["mesh"])
    out["mesh"] = os.path.relpath(mesh, os.path.dirname(os.path.abspath(output_path)))
    return out


def fitted_table(table, scene, values, scene_path, output_path, regions=None):
    """A copy of a scene file's table (tomllib's dict, of the scene at scene_path) with the
    fitted values in it, its mesh path made relative to output_path's folder: the fitted scene
    file's table. A whole-body value goes to [material] and out of every region; a
    KEY@REGION value to [regions.REGION]. regions: {name: (m,) bool} of the REGION names.
    ValueError where a fitted fiber angle joins an unfitted one that varies over its tets."""
    out = moved_mesh_path(table, scene_path, output_path)
    angles = np.degrees(fiber_angles(scene.elements.fiber))
    groups = {}                                 # region (None: the body) -> {kind: value}
    for n, v in values.items():
        kind, _, region = n.partition("@")
        groups.setdefault(region or None, {})[kind] = float(v)
    for region in sorted(groups, key=lambda r: r is not None):   # the body first
        given = groups[region]
        target = (out.setdefault("material", {}) if region is None else
                  out.setdefault("regions", {}).setdefault(region, {}))
        written = []
        for kind, key in MATERIAL_KEYS.items():
            if kind in given:
                target[key] = given[kind]
                written.append(key)
        if any(k.startswith("fiber") for k in given):
            tets = (np.ones(len(angles), bool) if region is None
                    else np.asarray(regions[region], bool))
            pair = []
            for c, kind in enumerate(("fiber_azimuth", "fiber_elevation")):
                if kind in given:
                    pair.append(given[kind])
                elif np.ptp(angles[tets, c]) > 1e-9:
                    raise ValueError(f"--output: the fitted fiber angle joins a {kind} that "
                                     f"varies over its tets; fit both angles to write one "
                                     f"direction")
                else:
                    pair.append(float(angles[tets, c][0]))
            target["fiber"] = [float(c) for c in fiber_direction(np.radians([pair]))[0]]
            written.append("fiber")
        if region is None:
            for other in out.get("regions", {}).values():
                for key in written:
                    other.pop(key, None)
    return out


class _Layout:
    """The fitted parameters as the optimizer's variables z and back, and the per-element
    material they make."""

    def __init__(self, scene, names, masks, start, bounds):
        material, m = scene.material, scene.mesh.n_tets
        params = material.per_element(m)
        self.m, self.names, self.masks = m, names, masks
        self.kinds = {n: n.partition("@")[0] for n in names}
        self.model = [("stvk", "neohookean")[c] for c in params["model"]]
        self.density = params["density"]
        self.base = {"young": params["young"], "poisson": params["poisson"],
                     "kappa": params["kappa"],
                     "fiber_azimuth": np.degrees(fiber_angles(params["fiber"])[:, 0]),
                     "fiber_elevation": np.degrees(fiber_angles(params["fiber"])[:, 1])}
        for given, what in ((start, "start"), (bounds, "bounds")):
            for n in given:
                if n not in names:
                    raise ValueError(f"{what}: {n!r} is not fitted (fitted: "
                                     f"{', '.join(names)})")
        self.start = {n: float(start.get(n, self.base[self.kinds[n]][masks[n]].mean()))
                      for n in names}
        self.bounds = {}
        for n in names:
            low, high = bounds.get(n, PARAMETERS[self.kinds[n]][2])
            if not low < high or not low <= self.start[n] <= high:
                raise ValueError(f"bounds: {n} needs low < high around its start "
                                 f"{self.start[n]:g}, got ({low:g}, {high:g})")
            if PARAMETERS[self.kinds[n]][1] == "log" and low <= 0:
                raise ValueError(f"bounds: {n} is fitted by its logarithm; its lower bound "
                                 f"must be > 0, got {low:g}")
            self.bounds[n] = (low, high)
        self.z_bounds = [tuple(self._z(n, b) for b in self.bounds[n]) for n in names]

    def _z(self, name, value):
        kind = self.kinds[name]
        return ZOOM[kind] * (math.log(value) if PARAMETERS[kind][1] == "log" else value)

    def to_z(self, values):
        return np.array([self._z(n, values[n]) for n in self.names])

    def values(self, z):
        out = {}
        for n, v in zip(self.names, z):
            kind = self.kinds[n]
            v = float(v) / ZOOM[kind]
            out[n] = math.exp(v) if PARAMETERS[kind][1] == "log" else v
        return out

    def material(self, z):
        p = {n: np.array(v, dtype=float) for n, v in self.base.items()}
        for n, v in self.values(z).items():
            p[self.kinds[n]][self.masks[n]] = v
        angles = np.radians(np.stack([p["fiber_azimuth"], p["fiber_elevation"]], axis=1))
        return Material(p["young"], p["poisson"], self.density, fiber_direction(angles),
                        p["kappa"], model=self.model)

    def chain(self, z, s, scaled=True):
        """dJ/dz (len(names),) from a Sensitivity s (per element) at z, or (r, len(names)) from
        one with a leading axis; scaled=False: dJ/dp in the parameters' units."""
        values = self.values(z)
        columns = []
        for n in self.names:
            kind = self.kinds[n]
            per_element = {"young": s.young, "poisson": s.poisson, "kappa": s.kappa,
                           "fiber_azimuth": s.fiber_angles[..., 0],
                           "fiber_elevation": s.fiber_angles[..., 1]}[kind]
            total = per_element[..., self.masks[n]].sum(axis=-1)
            if kind.startswith("fiber"):
                total = total * (math.pi / 180.0)        # per degree
            if scaled:
                total = total * (values[n] if PARAMETERS[kind][1] == "log" else 1.0) / ZOOM[kind]
            columns.append(total)
        return np.stack(columns, axis=-1)


class _Problem:
    """The fit's objective over the optimizer's variables, with warm starts per case."""

    def __init__(self, scenes, markers, measured, layout):
        self.scenes, self.markers, self.measured, self.layout = scenes, markers, measured, layout
        scale = np.array([np.abs(m).max() for m in measured])
        if not (scale > 0).all():
            raise ValueError(f"measured: load case {int(np.argmin(scale))} moves no marker")
        self.weight = 1.0 / scale                                  # 1 / s_c, 1/m
        self.ends = np.cumsum([3 * len(m) for m in measured])
        self.states = [s.initial_positions() for s in scenes]
        self.evaluations = 0
        self.limit = None   # s per solve: none for the start's, lbfgsb.trial_limit after

    def _solve(self, z):
        material = self.layout.material(z)
        out = []
        t0 = time.perf_counter()
        for k, scene in enumerate(self.scenes):
            moved = scene.with_material(material)
            result = solve(moved, x0=self.states[k], warn=False, time_limit=self.limit)
            if not result.converged:
                raise RuntimeError(f"fit: the static solve of load case {k} failed at "
                                   f"{_shown(self.layout.values(z))} ({result.message} after "
                                   f"{result.seconds:.3g} s)")
            self.states[k] = result.x
            out.append((moved, result))
        if self.limit is None:
            self.limit = lbfgsb.trial_limit(time.perf_counter() - t0)
        self.evaluations += 1
        return out

    def _residual(self, k, scene, result):
        """Case k's weighted misfit (k_c, 3) at its solve's answer."""
        return self.weight[k] * (self.markers[k].at(result.x - scene.mesh.vertices)
                                 - self.measured[k])

    def objective(self, z):
        """(J, dJ/dz) at z."""
        J, gradient = 0.0, np.zeros(len(z))
        for k, (scene, result) in enumerate(self._solve(z)):
            r = self._residual(k, scene, result)
            J += 0.5 * float(np.sum(r * r))
            dJ = self.weight[k] * self.markers[k].spread(r, scene.mesh.n_vertices)
            gradient += self.layout.chain(z, static_sensitivity(scene, result, dJ))
        return J, gradient

    def residuals_and_jacobian(self, z):
        """The weighted residuals (c k 3,) at z and their Jacobian (c k 3, len(names)) in the
        parameters."""
        residuals, rows = [], []
        n = self.scenes[0].mesh.n_vertices
        for k, (scene, result) in enumerate(self._solve(z)):
            r = self._residual(k, scene, result)
            residuals.append(r.ravel())
            unit = np.array([self.markers[k].spread(e.reshape(-1, 3), n)
                             for e in self.weight[k] * np.eye(r.size)])
            rows.append(self.layout.chain(z, static_jacobian(scene, result, unit), False))
        return np.concatenate(residuals), np.concatenate(rows)
