"""Identify a fiber angle and stiffness from measured marker displacements.

    python examples/identify.py

Makes the measurements, then fits them with the command a user would run:
- the "measured" data: 20 markers on the top of a 0.1 m cantilever, from full solves of a
  fine mesh (20 x 4 x 4 quadratic cells, 6 tets each) with fibers at 10 degrees from the beam
  toward z and kappa = 2E, under three load cases (gravity; a sideways and an axial traction on
  the tip), with 1% noise, written as out/identify/{gravity,side,axial}.csv;
- the model: scene files of a 6x coarser mesh (out/identify/*.toml), started 30 degrees and 3x
  away (-20 degrees, kappa = 2E / 3);
- then `python -m anisofem fit` on them, which prints each iteration, the values with their
  deviations and the markers' misfit, and writes out/identify/fitted.toml.
"""
import os
import sys

import numpy as np

import anisofem as af
from anisofem.cli import main as command
from anisofem.inverse.fit import Markers
from anisofem.inverse.sensitivity import fiber_direction

SIZE = (0.1, 0.02, 0.02)                # m
TRUE_ANGLE, TRUE_KAPPA = 10.0, 2e5      # degrees from x toward z; Pa
#: load case -> the tip's traction (Pa over its 4e-4 m^2 face), or None for gravity
CASES = {"gravity": None, "side": (0.0, 500.0, 0.0), "axial": (5000.0, 0.0, 0.0)}
OUT = os.path.join("out", "identify")


def load_cases(mesh, angle, kappa):
    """The cantilever (held at x = 0) of mesh with fibers at `angle` degrees and `kappa` Pa,
    one Scene per load case of CASES."""
    X = mesh.vertices
    material = af.Material(1e5, 0.45, 1000.0,
                           fiber_direction(np.radians([[0.0, angle]]))[0], kappa)
    held = np.flatnonzero(X[:, 0] < 1e-9)
    tip = mesh.faces_where(lambda c: c[:, 0] > SIZE[0] - 1e-9)
    return [af.Scene(mesh, material, fixed=held, gravity=(0, 0, -9.81)) if t is None else
            af.Scene(mesh, material, fixed=held, traction=t, traction_faces=tip)
            for t in CASES.values()]


def markers():
    """20 markers on the top face, two rows along the beam (m)."""
    xs = np.linspace(0.01, 0.1, 10)
    return np.concatenate([np.stack([xs, np.full(10, y), np.full(10, 0.01)], axis=1)
                           for y in (-0.01, 0.01)])


def measure(seed=0):
    """Marker displacements (per case, (20, 3) m) of the fine mesh at the true parameters, with
    noise of 1% of each case's largest displacement."""
    fine = af.box_beam(SIZE, (20, 4, 4), order=2, tets_per_cell=6)
    probe = Markers(fine, markers())
    rng = np.random.default_rng(seed)
    out = []
    for scene in load_cases(fine, TRUE_ANGLE, TRUE_KAPPA):
        u = probe.at(af.solve(scene).x - fine.vertices)
        out.append(u + 0.01 * np.abs(u).max() * rng.standard_normal(u.shape))
    return out


def write_model(folder, angle, kappa):
    """The coarse mesh (beam.msh, surfaces "base" and "tip") and one scene file per case."""
    coarse = af.box_beam(SIZE, (10, 2, 2), tets_per_cell=6)
    af.io.write_tagged_mesh(os.path.join(folder, "beam.msh"), coarse,
                            surfaces={1: coarse.faces_where(lambda c: c[:, 0] < 1e-9),
                                      2: coarse.faces_where(lambda c: c[:, 0] > SIZE[0] - 1e-9)},
                            names={"base": 1, "tip": 2})
    fiber = fiber_direction(np.radians([[0.0, angle]]))[0]
    for name, traction in CASES.items():
        load = ('gravity = [0, 0, -9.81]\n' if traction is None else
                f'[[boundary]]\nwhere = "tip"\ntraction = {list(traction)}\n')
        with open(os.path.join(folder, f"{name}.toml"), "w") as f:
            f.write(f'mesh = "beam.msh"\norder = 2\n{load if traction is None else ""}'
                    f'[material]\npoisson = 0.45\nfiber_stiffness = {kappa}\n'
                    f'fiber = {fiber.tolist()}\n[[boundary]]\nwhere = "base"\nheld = true\n'
                    f'{load if traction is not None else ""}')


def main():
    os.makedirs(OUT, exist_ok=True)
    for name, u in zip(CASES, measure()):
        np.savetxt(os.path.join(OUT, f"{name}.csv"), np.c_[markers(), u], delimiter=",",
                   header="x,y,z,ux,uy,uz", comments="")
    write_model(OUT, TRUE_ANGLE - 30.0, TRUE_KAPPA / 3)
    print(f"truth: fiber_elevation = {TRUE_ANGLE:g} deg, kappa = {TRUE_KAPPA:g} Pa")
    paths = [os.path.join(OUT, name) for name in CASES]
    return command(["fit", *(p + ".toml" for p in paths), "--markers",
                    *(p + ".csv" for p in paths), "--params", "fiber_elevation", "kappa",
                    "-o", os.path.join(OUT, "fitted.toml")])


if __name__ == "__main__":
    sys.exit(main())
