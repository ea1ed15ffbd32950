"""`python -m anisognn evaluate MODEL...`: the fixed evaluation suite, every model against
anisofem on the same scenes, side by side (paper Table 1, Table 2, Fig. 6, plus the energy gap).

Scenes (the paper's material, E = 100 kPa, nu = 0.48, 1000 kg/m^3; fibers with kappa = E; the
end x = 0 held; meshes of the training family, about 1 cm elements):
- cantilever: a 0.1 x 0.02 x 0.02 m box beam and a 0.1 m long, 1 cm radius cylinder under
  gravity, fibers parallel to gravity (z) or orthogonal to it (along the beam, x): Table 1;
- imbalance: the box beam under a downward body force of 1000 or 5000 N/m^3 with fibers at 45,
  60 or 90 degrees from the beam axis towards gravity, d = (cos a, 0, sin a): Table 2;
- tension: the box beam under a body force of 10 kN/m^3 along +x (it hangs from its held end),
  fibers at 45 degrees in the x-y plane: Fig. 6.

Each simulator rolls every scene forward from rest for `steps` steps of dt (default 1000 steps
of 0.02 s: 20 s, long past the settling time); the final state is compared with anisofem's
static equilibrium. Metrics per scene (units as named):
- tip_error (m): |mean tip displacement - the FEM's|; tip_ratio: that over |FEM tip deflection|;
- force_max, force_mean (N): imbalanced force |dG/dx| per free vertex at the final state;
- volume_change_max: max over tets of |det F - 1|; volume_change_error: its relative
  difference to the FEM's;
- energy_gap (J): G(final) - G(FEM), and energy_gap_ratio: that over G(rest) - G(FEM);
- max_displacement (m) over the whole rollout and finite: the stability check (bounded means
  below the beam's length);
- rest_acceleration_mean, _max (m/s^2): |x_1 - x_fem| / dt^2 over the vertices not fully held,
  for one step from the FEM equilibrium at rest (0 for an exact simulator). The resting state
  is sensitive to it: bending is soft, so a small force error at rest moves the resting tip
  far (a simulator's rollout rests where its acceleration at rest vanishes).
- rest_stiffness: how the simulator's acceleration at rest changes with the deflection, as a
  share of the FEM's: with u = x_fem - X and p(s) the mass-weighted projection on u of one
  step from X + s u at rest, (p(0.5) - p(1.5)) over the FEM's (1 for an exact simulator, 0 for
  one that holds every still, deformed state in place, whatever its load).
"""
import math
import os
import sys
from dataclasses import dataclass

import numpy as np

import anisofem
from anisofem import Material, Scene, box_beam, cylinder_beam
from anisofem.physics import metrics
from anisofem.io.output import result_path, write_json
from anisofem.physics.inversion import volume_change

from .sampler import DENSITY, POISSON, YOUNG

GRAVITY = 9.81         # m/s^2
STEPS = 1000
DT = 0.02              # s


@dataclass
class Case:
    """One evaluation scene: group ("cantilever", "imbalance", "tension"), a label, the scene."""
    group: str
    label: str
    scene: Scene


def _beam(kind):
    if kind == "box":
        return box_beam(size=(0.1, 0.02, 0.02), cells=(5, 2, 2))
    return cylinder_beam(0.1, 0.01, 5, 2, 0)


def _scene(mesh, fiber, body_force):
    """The beam held at x = 0 with fibers d (3,) (kappa = E) under a uniform body force
    (3,) N/m^3."""
    material = Material(YOUNG, POISSON, DENSITY, np.asarray(fiber, float) / np.linalg.norm(fiber),
                        YOUNG)
    return Scene(mesh, material, fixed=metrics.end_vertices(mesh, 0, "min"),
                 body_force=np.tile(body_force, (mesh.n_tets, 1)).astype(float))


def cases():
    """The suite's scenes, in table order."""
    out = []
    weight = [0.0, 0.0, -DENSITY * GRAVITY]
    for kind in ("box", "cylinder"):
        for name, fiber in (("parallel", (0, 0, 1)), ("orthogonal", (1, 0, 0))):
            out.append(Case("cantilever", f"{kind}, fibers {name} to gravity",
                            _scene(_beam(kind), fiber, weight)))
    for density in (1000.0, 5000.0):
        for angle in (45, 60, 90):
            a = math.radians(angle)
            out.append(Case("imbalance", f"{density:g} N/m^3, fibers at {angle} deg",
                            _scene(_beam("box"), (math.cos(a), 0, math.sin(a)),
                                   [0, 0, -density])))
    out.append(Case("tension", "box beam, 10 kN/m^3 along x, fibers at 45 deg in x-y",
                    _scene(_beam("box"), (1, 1, 0), [10e3, 0, 0])))
    return out


def fem_rollout(scene, steps, x0=None, dt=DT):
    """anisofem's own backward-Euler rollout from x0 (n, 3) at rest (default: the rest shape),
    (steps + 1, n, 3): the reference simulator."""
    return anisofem.simulate(scene, steps, dt=dt, x0=x0, warn=False).positions


def model_rollout(model):
    """A simulator (scene, steps, x0=None) -> (steps + 1, n, 3) positions for an anisognn model,
    from x0 (n, 3) at rest (default: the rest shape)."""
    from .rollout import rollout

    def run(scene, steps, x0=None):
        return rollout(model, scene, steps, x0=x0)
    return run


def _rollout(run, scene, steps, x0=None):
    """run(scene, steps, x0), or None if the simulator gave up on a non-finite state."""
    try:
        return run(scene, steps, x0)
    except FloatingPointError:
        return None


def _step_at_rest(run, scene, x):
    """(n, 3) m: the simulator run's displacement over one step from x (n, 3) at rest, or None
    if it is not finite."""
    positions = _rollout(run, scene, 1, x)
    if positions is None or not np.isfinite(positions).all():
        return None
    return positions[1] - x


def rest_acceleration(run, scene, x_fem):
    """{"rest_acceleration_mean", "rest_acceleration_max"} in m/s^2: the simulator run's
    acceleration over the vertices not fully held for one step from x_fem (n, 3) at rest (inf if
    the step is not finite)."""
    step = _step_at_rest(run, scene, x_fem)
    if step is None:
        return {"rest_acceleration_mean": math.inf, "rest_acceleration_max": math.inf}
    moving = ~scene.fixed_mask.all(axis=1)
    a = np.linalg.norm(step, axis=1)[moving] / DT ** 2
    return {"rest_acceleration_mean": float(a.mean()), "rest_acceleration_max": float(a.max())}


#: the deflections, as shares of the FEM's, between which rest_stiffness compares
STIFFNESS_SHARES = (0.5, 1.5)


def rest_stiffness(run, scene, x_fem):
    """{"rest_stiffness"}: the change of the simulator run's one-step displacement at rest
    between STIFFNESS_SHARES of the FEM deflection u = x_fem - X (n, 3), projected on u in the
    mass norm, over anisofem's (module docstring; nan if a step is not finite)."""
    u = x_fem - scene.mesh.vertices
    weighted = scene.masses[:, None] * u

    def change(simulator):
        steps = [_step_at_rest(simulator, scene, scene.mesh.vertices + s * u)
                 for s in STIFFNESS_SHARES]
        if any(step is None for step in steps):
            return math.nan
        return float(((steps[0] - steps[1]) * weighted).sum() / (u * weighted).sum())
    return {"rest_stiffness": change(run) / change(fem_rollout)}


def score(scene, positions, x_fem):
    """The metrics (see module docstring) of a rollout's positions (k + 1, n, 3), or None for
    one that blew up, against the static equilibrium x_fem (n, 3)."""
    mesh = scene.mesh
    finite = positions is not None and bool(np.isfinite(positions).all())
    max_disp = float(np.linalg.norm(positions - mesh.vertices, axis=2).max()) if finite else math.inf
    out = {"finite": finite, "max_displacement": max_disp,
           "bounded": finite and max_disp < mesh.size}
    if not finite:
        return out
    x = positions[-1]
    tip_fem = metrics.tip_displacement(mesh, x_fem)
    tip_error = float(np.linalg.norm(metrics.tip_displacement(mesh, x) - tip_fem))
    deflection = float(np.linalg.norm(tip_fem))
    force = metrics.imbalanced_force(scene, x)
    vol = float(np.abs(volume_change(mesh, x)).max())
    vol_fem = float(np.abs(volume_change(mesh, x_fem)).max())
    g_fem = anisofem.energy(scene, x_fem)
    gap = anisofem.energy(scene, x) - g_fem
    return {**out, "tip_error": tip_error, "tip_fem": deflection,
            "tip_ratio": tip_error / deflection,
            "force_max": force.max, "force_mean": force.mean,
            "volume_change_max": vol, "volume_change_fem": vol_fem,
            "volume_change_error": abs(vol - vol_fem) / vol_fem,
            "energy_gap": gap,
            "energy_gap_ratio": gap / (anisofem.energy(scene, scene.initial_positions()) - g_fem)}


def evaluate(simulators, steps=STEPS, suite=None, progress=False):
    """Score simulators {name: (scene, steps, x0) -> positions} on suite (default cases()).

    Returns (results {simulator name: [metrics dict per scored case]}, the scored cases,
    not_scored [{"case", "reason"}]). A case whose FEM equilibrium is not physical (StVK turned
    inside out: no real material gets there) is not scored: there is no answer to compare with.
    progress: a line on stderr per simulator and case."""
    suite = cases() if suite is None else suite
    scored, fem, not_scored = [], [], []
    for c in suite:
        ref = anisofem.solve(c.scene, warn=False)
        if ref.physical:
            scored.append(c)
            fem.append(ref.x)
        else:
            not_scored.append({"case": c.label, "reason": (
                f"the FEM equilibrium turns {ref.inversion.inverted} of {c.scene.mesh.n_tets} "
                f"elements inside out (StVK): not a physical reference")})
    results = {name: [] for name in simulators}
    total, done = len(simulators) * len(scored), 0
    for name, run in simulators.items():
        for c, x in zip(scored, fem):
            if progress:
                done += 1
                print(f"[{done}/{total}] {name}: {c.label}", file=sys.stderr, flush=True)
            results[name].append({"group": c.group, "case": c.label,
                                  **score(c.scene, _rollout(run, c.scene, steps), x),
                                  **rest_acceleration(run, c.scene, x),
                                  **rest_stiffness(run, c.scene, x)})
    return results, scored, not_scored


COLUMNS = {"cantilever": (("tip_error", "tip error m", "{:.2e}"), ("tip_ratio", "/FEM", "{:.3f}")),
           "imbalance": (("force_mean", "mean force N", "{:.2e}"),
                         ("force_max", "max force N", "{:.2e}")),
           "tension": (("volume_change_max", "max |dV/V|", "{:.2e}"),
                       ("volume_change_error", "vs FEM", "{:.3f}")),
           "every case": (("energy_gap", "gap J", "{:.2e}"), ("energy_gap_ratio", "share", "{:.3f}"),
                          ("rest_acceleration_mean", "rest a", "{:.2e}"),
                          ("rest_stiffness", "rest k", "{:.2f}"), ("bounded", "bounded", "{}"))}
TITLES = {"cantilever": "Table 1: cantilever tip displacement error at rest (FEM tip deflection "
                        "in brackets)",
          "imbalance": "Table 2: imbalanced force at the final state",
          "tension": "Fig. 6: max per-element volume change, beam in tension",
          "every case": "Energy gap to the FEM equilibrium (J; share of the rest-to-equilibrium "
                        "drop),\nmean acceleration of one step from it (m/s^2), stiffness at rest"
                        " (share of the\nFEM's) and stability over the whole rollout"}


def format_tables(results, suite, ratio=None):
    """The results as text tables that fit a terminal: one per group, each case's line followed
    by a line per simulator; with ratio = (name a, name b), a line "a/b" with a's over b's for
    the group's first metric (not in the last table, of every case)."""
    names = list(results)
    lines = []
    for group, columns in COLUMNS.items():
        blocks = []
        for i, case in enumerate(suite):
            if group not in (case.group, "every case"):
                continue
            label = case.label
            if group == "cantilever":
                label += f" [{results[names[0]][i].get('tip_fem', math.nan) * 1e3:.1f} mm]"
            elif group == "tension":
                label += f" [FEM {results[names[0]][i].get('volume_change_fem', math.nan):.2e}]"
            rows = [[n] + [_cell(results[n][i].get(key, math.nan), fmt)
                           for key, _, fmt in columns] for n in names]
            if ratio and group != "every case":
                a, b = (results[n][i].get(columns[0][0], math.nan) for n in ratio)
                rows.append([f"{ratio[0]}/{ratio[1]}", f"{a / b:.2f}" if b else "-"]
                            + [""] * (len(columns) - 1))
            blocks.append((label, rows))
        lines += ["", TITLES[group]] + _table(["model"] + [c[1] for c in columns], blocks)
    return "\n".join(lines)


def _cell(value, fmt):
    """value as table text: fmt.format(value), a bool as yes or NO."""
    return ("yes" if value else "NO") if isinstance(value, bool) else fmt.format(value)


def _table(header, blocks):
    """Text lines of a table of blocks [(title, rows)]: each title (unless None) on a line of
    its own, its rows indented below; first column left-aligned, the others right-aligned."""
    rows = [r for _, block in blocks for r in block]
    widths = [max(len(r[k]) for r in [header] + rows) for k in range(len(header))]

    def line(row):
        return ("  " + "  ".join(c.ljust(w) if k == 0 else c.rjust(w)
                                 for k, (c, w) in enumerate(zip(row, widths)))).rstrip()
    out = [line(header), line(["-" * w for w in widths])]
    for title, block in blocks:
        out += [title] * (title is not None) + [line(r) for r in block]
    return out


def summary(results, suite, ratio=None):
    """Per simulator: mean tip ratio, mean imbalanced force, worst volume change error, mean
    acceleration at the FEM's rest, mean stiffness at rest, all finite and bounded; with
    ratio = (name a, name b) also a's over b's."""
    out = {}
    for name, rows in results.items():
        tips = _pick(rows, suite, "cantilever", "tip_ratio")
        out[name] = {"tip_ratio_mean": _reduce(np.mean, tips),
                     "tip_ratio_max": _reduce(np.max, tips),
                     "force_mean": _reduce(np.mean, _pick(rows, suite, "imbalance",
                                                          "force_mean")),
                     "volume_change_error_max": _reduce(np.max, _pick(
                         rows, suite, "tension", "volume_change_error")),
                     "rest_acceleration_mean": _reduce(np.mean, [r["rest_acceleration_mean"]
                                                                 for r in rows]),
                     "rest_stiffness_mean": _reduce(np.mean, [r["rest_stiffness"]
                                                              for r in rows]),
                     "all_bounded": all(r["bounded"] for r in rows)}
    if ratio:
        first, second = (results[n] for n in ratio)
        tips = [a["tip_error"] / b["tip_error"] for a, b, c in zip(first, second, suite)
                if c.group == "cantilever" and "tip_error" in a and "tip_error" in b]
        out["ratios"] = {"tip_error_mean": _reduce(np.mean, tips),
                         "tip_error_max": _reduce(np.max, tips),
                         "force_mean": out[ratio[0]]["force_mean"] / out[ratio[1]]["force_mean"]}
    return out


def _reduce(fn, values):
    """fn(values) as a float; NaN for no values (every case of a group not scored)."""
    return float(fn(values)) if len(values) else math.nan


def _pick(rows, suite, group, key):
    """The values of key over a group's cases (inf where a rollout blew up)."""
    return [r.get(key, math.inf) for r, c in zip(rows, suite) if c.group == group]


def run(models, steps=STEPS, out=result_path("evaluation.json"), echo=print, progress=True):
    """Evaluate models {name: GraphNet} beside anisofem's own rollout ("fem"), print the
    tables (the first model over the second in the ratio columns) and write the JSON
    atomically; progress: a line on stderr per simulator and case. Returns the JSON dict."""
    simulators = {name: model_rollout(m) for name, m in models.items()}
    simulators["fem"] = fem_rollout
    results, suite, not_scored = evaluate(simulators, steps, progress=progress)
    ratio = tuple(models)[:2] if len(models) >= 2 else None
    echo(format_tables(results, suite, ratio))
    for skipped in not_scored:
        echo(f"not scored: {skipped['case']}: {skipped['reason']}")
    report = {"steps": steps, "dt": DT, "results": results, "not_scored": not_scored,
              "summary": summary(results, suite, ratio)}
    if out:
        write_json(os.fspath(out), report)
        echo(f"wrote {out}")
    return report
