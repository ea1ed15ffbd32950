"""The framed reduced model against the linear fitted one, on loads neither was built from:
the T and the Y of `trade t` / `trade y` (held at the foot of their stem, no fibers, gravity
along -z, 320 tets) and the 0.2 m / 1,600-tet trade cantilever (fibers at 40 degrees in x-z,
kappa = E), each model fitted to the scene's default declaration (a drag of up to half the
body's weight at each free end, any direction).

    python scripts/framed_validation.py [--cases 8] [--json results/framed_validation.json]

For each scene and model: the validation's largest tip error over `cases` unseen drags (each
held 25 steps of 0.02 s from rest and released 25, against the full FEM), its build time, and
ms per step of a 50-step gravity rollout with the full positions (after one untimed step).
Run alone (a few minutes).
"""
import argparse
import time

import numpy as np

import anisofem as af
from anisofem.io.output import publish, result_path
from anisofem.reduced import FramedModel, ReducedModel

FIBER = np.array([0.766, 0.0, 0.643]) / np.linalg.norm([0.766, 0.0, 0.643])
STEPS, DT = 50, 0.02


def scenes():
    """(name, Scene) of the three bodies."""
    out = []
    for name, mesh in (("T", af.t_shape()), ("Y", af.y_shape())):
        out.append((name, af.Scene(mesh, af.Material(1e5, 0.48, 1000.0),
                                   fixed=af.metrics.end_vertices(mesh, 2, "min"),
                                   gravity=(0, 0, -9.81))))
    mesh = af.box_beam(size=(0.2, 0.02, 0.02), cells=(20, 4, 4))
    out.append(("0.2 m beam", af.Scene(mesh, af.Material(1e5, 0.48, 1000.0, FIBER, 1e5),
                                       fixed=af.metrics.end_vertices(mesh, 0, "min"),
                                       gravity=(0, 0, -9.81))))
    return out


def step_ms(model):
    """ms per step of a gravity rollout from rest, after one untimed step."""
    model.rollout(((None, 1),), DT)
    t0 = time.perf_counter()
    xs, _ = model.rollout(((None, STEPS),), DT)
    return 1e3 * (time.perf_counter() - t0) / STEPS


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--cases", type=int, default=8)
    p.add_argument("--json", default=result_path("framed_validation.json"))
    args = p.parse_args(argv)
    rows = []
    for scene_name, scene in scenes():
        for name, make in (("reduced m4 s16", lambda s: ReducedModel(s, modes=4, snapshots=16,
                                                                      validate=False)),
                           ("reduced framed b4 c12", lambda s: FramedModel(s,
                                                                            validate=False))):
            model = make(scene)
            validation = model.validate(cases=args.cases)
            rows.append(dict(scene=scene_name, model=name, r=int(model.r),
                             tip_error=validation.tip_error,
                             field_error=validation.field_error,
                             converged=validation.converged, inverted=validation.inverted,
                             build_seconds=model.build_seconds, ms=step_ms(model)))
    publish(dict(cases=args.cases, hold_steps=25, dt=DT, rows=rows), show, args.json)


def show(report):
    """Print the table."""
    print(f"validation on {report['cases']} unseen drags (held {report['hold_steps']} steps, "
          f"released as many, dt = {report['dt']} s): largest tip error over the full FEM's")
    print(f"{'scene':11s} {'model':22s} {'r':>3s} {'tip error':>9s} {'ms/step':>8s} "
          f"{'build s':>7s}")
    for row in report["rows"]:
        print(f"{row['scene']:11s} {row['model']:22s} {row['r']:3d} {row['tip_error']:9.4f} "
              f"{row['ms']:8.3g} {row['build_seconds']:7.2f}"
              + ("" if row["converged"] else "  a step did not converge"))


if __name__ == "__main__":
    main()
