"""A swing: the trade's 0.2 m / 1,600-tet cantilever (fibers at 40 degrees in x-z, kappa = E,
nu = 0.48, gravity) pulled sideways at its free end by 0.4 of its weight for 1 s, which moves
the tip more than half the beam's length, then released for 1 s (dt = 0.02 s), by the exact
step and by reduced models, modal, fitted to the scene's default declared loads (a drag of
up to half the weight at the free end in any direction; the swing's drag is within them, and
not one of the static cases the fitted bases were built from), and framed (anisofem.reduced
.framed, fitted to the same declaration).

    python scripts/swing.py [--json results/swing.json]   (by default out/swing.json)

For each rollout: the largest sideways tip displacement (the mean over the free end's
vertices), the largest tip error over the whole rollout and over the release alone (the tip
difference from the exact rollout over the exact rollout's largest tip displacement), and ms
per step (the whole rollout's time over its steps, the full positions included, after one
untimed step). Run alone (about a minute).
"""
import argparse
import time

import numpy as np

import anisofem as af
from anisofem.io.output import publish, scratch_path
from anisofem.reduced import FramedModel, ReducedModel
from anisofem.reduced.model import full_rollout

FIBER = np.array([0.766, 0.0, 0.643]) / np.linalg.norm([0.766, 0.0, 0.643])
HOLD, RELEASE, DT = 50, 50, 0.02
PULL = 0.4
MODELS = ((5, 0), (6, 0), (8, 0), (4, 16), (8, 20))


def scene():
    mesh = af.box_beam(size=(0.2, 0.02, 0.02), cells=(20, 4, 4))
    return af.Scene(mesh, af.Material(1e5, 0.48, 1000.0, FIBER, 1e5),
                    fixed=af.metrics.end_vertices(mesh, 0, "min"), gravity=(0, 0, -9.81))


def pull(s):
    """The sideways drag (n, 3), N: PULL of the weight along +y, spread over the free end's
    vertices by mass."""
    end = af.metrics.end_vertices(s.mesh, 0, "max")
    f = np.zeros((s.mesh.n_vertices, 3))
    f[end, 1] = PULL * s.masses.sum() * 9.81 * s.masses[end] / s.masses[end].sum()
    return f


def timed(rollout, phases):
    """(positions (steps + 1, n, 3), ms per step, whether every step converged) of
    rollout(phases, DT), timed whole (the full positions of every step included) after one
    untimed step (loading compiled kernels, first factorizations)."""
    rollout(((phases[0][0], 1),), DT)
    t0 = time.perf_counter()
    xs, converged = rollout(phases, DT)
    return xs, 1e3 * (time.perf_counter() - t0) / (len(xs) - 1), converged


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--json", default=scratch_path("swing.json"))
    args = p.parse_args(argv)
    s = scene()
    force = pull(s)
    phases = ((force, HOLD), (np.zeros_like(force), RELEASE))
    end = af.metrics.end_vertices(s.mesh, 0, "max")
    full, full_ms, _ = timed(lambda p, dt: full_rollout(s, p, dt), phases)
    tip = (full[:, end] - s.mesh.vertices[end]).mean(axis=1)
    size = np.linalg.norm(tip, axis=1).max()
    rows = [dict(name="exact", r=None, ms=full_ms, sideways=float(np.abs(tip[:, 1]).max()),
                 error=0.0, release_error=0.0, converged=True, build_seconds=0.0)]
    models = [(f"reduced m{m}" + (f" s{k}" if k else ""),
               ReducedModel(s, modes=m, snapshots=k, validate=False)) for m, k in MODELS]
    models.append(("reduced framed b4 c12", FramedModel(s, validate=False)))
    for name, model in models:
        xs, ms, converged = timed(model.rollout, phases)
        d = np.linalg.norm((xs[:, end] - full[:, end]).mean(axis=1), axis=1) / size
        rows.append(dict(name=name, r=model.r, ms=ms, converged=converged,
                         sideways=float(np.abs((xs[:, end] - s.mesh.vertices[end])
                                               .mean(axis=1)[:, 1]).max()),
                         error=float(d.max()), release_error=float(d[HOLD:].max()),
                         build_seconds=model.build_seconds))
    report = dict(scene=dict(tets=s.mesh.n_tets, length=0.2, pull=PULL, hold=HOLD,
                             release=RELEASE, dt=DT, tip_size=float(size)), rows=rows)
    publish(report, show, args.json)


def show(report):
    """Print the swing's table."""
    sc = report["scene"]
    print(f"swing: 0.2 m cantilever, {sc['tets']} tets, drag {sc['pull']} x weight along +y for "
          f"{sc['hold'] * sc['dt']:g} s, released for {sc['release'] * sc['dt']:g} s; largest "
          f"exact tip displacement {1e3 * sc['tip_size']:.1f} mm")
    print(f"{'rollout':21s} {'r':>3s} {'sideways mm':>11s} {'error':>8s} {'release':>8s} "
          f"{'ms/step':>8s} {'build s':>7s}")
    for row in report["rows"]:
        print(f"{row['name']:21s} {row['r'] or '-':>3} {1e3 * row['sideways']:11.1f} "
              f"{row['error']:8.4f} {row['release_error']:8.4f} {row['ms']:8.3g} "
              f"{row['build_seconds']:7.2f}" + ("" if row["converged"]
                                                else "  a step did not converge"))

if __name__ == "__main__":
    main()
