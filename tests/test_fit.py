"""Identification (anisofem.fit) on data its own mesh did not make: markers from full solves of
a finer quadratic mesh at a true fiber angle and stiffness, 1% noise, a start 30 degrees and 3x
away; and the refusals."""
import time

import numpy as np
import pytest

import anisofem as af
from anisofem.fit import Markers, fit
from anisofem.sensitivity import fiber_direction

SIZE = (0.1, 0.02, 0.02)
TRUE_ANGLE, TRUE_KAPPA = 10.0, 2e5     # degrees from x toward z; Pa


def load_cases(mesh, angle, kappa):
    """The cantilever (held at x = 0) under gravity, a sideways (y) and an axial (x) traction on
    its tip face: three load cases of one body."""
    X = mesh.vertices
    held = np.flatnonzero(X[:, 0] < 1e-9)
    material = af.Material(1e5, 0.45, 1000.0,
                           fiber_direction(np.radians([[0.0, angle]]))[0], kappa)
    tip = mesh.faces_where(lambda c: c[:, 0] > SIZE[0] - 1e-9)
    cases = [af.Scene(mesh, material, fixed=held, gravity=(0, 0, -9.81))]
    for axis, force in ((1, 0.2), (0, 2.0)):   # N over the 4e-4 m^2 tip face
        t = np.zeros(3)
        t[axis] = force / 4e-4
        cases.append(af.Scene(mesh, material, fixed=held, traction=t, traction_faces=tip))
    return cases


def markers():
    """20 markers on the top face, two rows along the beam."""
    xs = np.linspace(0.01, 0.1, 10)
    return np.concatenate([np.stack([xs, np.full(10, y), np.full(10, 0.01)], axis=1)
                           for y in (-0.01, 0.01)])


def test_fit_recovers_the_fiber_angle_and_stiffness():
    """The truth: 20 x 4 x 4 quadratic cells (6 tets each); the fit: 10 x 2 x 2 (6x fewer
    unknowns). Measured: angle within 0.03 degrees, kappa 4.8% low (the coarse mesh's
    stiffness), 7 s on 2 cores; asserted within 2 degrees, 10% and a minute."""
    fine = af.box_beam(SIZE, (20, 4, 4), order=2, tets_per_cell=6)
    coarse = af.box_beam(SIZE, (10, 2, 2), order=2, tets_per_cell=6)
    points = markers()
    probe = Markers(fine, points)
    truth = [probe.at(af.solve(s).x - fine.vertices)
             for s in load_cases(fine, TRUE_ANGLE, TRUE_KAPPA)]
    rng = np.random.default_rng(0)
    measured = [u + 0.01 * np.abs(u).max() * rng.standard_normal(u.shape) for u in truth]
    seen = []
    t0 = time.perf_counter()
    result = fit(load_cases(coarse, TRUE_ANGLE - 30.0, TRUE_KAPPA / 3), [points] * 3, measured,
                 ["fiber_elevation", "kappa"], progress=lambda *row: seen.append(row))
    seconds = time.perf_counter() - t0
    assert result.converged, result.message
    assert abs(result.values["fiber_elevation"] - TRUE_ANGLE) < 2.0
    assert abs(result.values["kappa"] / TRUE_KAPPA - 1.0) < 0.10
    assert seconds < 60.0
    assert len(seen) == result.iterations and seen[-1][2] == result.values
    assert result.marker_residuals.shape == (60,)
    noise = 0.01 * max(np.abs(u).max() for u in truth)
    assert result.rms < 3 * noise                     # the fit explains the data to its noise
    assert 0 < result.deviations["kappa"] < 0.1 * TRUE_KAPPA


def test_fit_refusals():
    mesh = af.box_beam(SIZE, (4, 2, 2))
    cases = load_cases(mesh, 0.0, 1e5)
    points = markers()[:4]
    with pytest.raises(ValueError, match="names: expected distinct parameters"):
        fit(cases[0], points, np.ones((4, 3)), ["kapa"])
    with pytest.raises(ValueError, match="one array of each per load case"):
        fit(cases, points, np.ones((4, 3)), ["kappa"])
    with pytest.raises(ValueError, match=r"measured\[0\]: expected shape \(4, 3\)"):
        fit(cases[0], points, np.ones((5, 3)), ["kappa"])
    with pytest.raises(ValueError, match="lies in no tet"):
        fit(cases[0], points + 1.0, np.ones((4, 3)), ["kappa"])
    with pytest.raises(ValueError, match="bounds: kappa needs low < high around its start"):
        fit(cases[0], points, np.ones((4, 3)), ["kappa"], bounds={"kappa": (1e6, 1e7)})
    with pytest.raises(ValueError, match="moves no marker"):
        fit(cases[0], points, np.zeros((4, 3)), ["kappa"])
