"""The inverse commands: `fit` (material parameters from measured markers), `design` (a
fiber layout for a target) and `control` (controls in time for a path)."""
import math
import os

import numpy as np

from ..inverse import fit as fitting
from ..io.output import atomic_path, check_folder, write_json
from ..io.scenefile import SceneFile, load_scene
from ..io.toml_writer import dump
from .arguments import is_scene_file


def fit_command(args):
    """python -m anisofem fit: progress per iteration, the values with their deviations, the
    residual per marker, the fitted scene file."""
    if len(args.markers) != len(args.scenes):
        raise ValueError(f"--markers: one CSV per scene ({len(args.scenes)}), got "
                         f"{len(args.markers)}")
    for path, name in ((args.output, "--output"), (args.json, "--json")):
        if path:
            check_folder(path, name)
    if args.output and not is_scene_file(args.output):
        raise ValueError(f"--output: a scene file (.toml), got {args.output!r}")
    unknown = [n for n in args.params if n.partition("@")[0] not in fitting.PARAMETERS]
    if unknown:
        raise ValueError(f"--params: {unknown[0]!r} is not a parameter; fit "
                         f"{', '.join(fitting.PARAMETERS)}, each alone or as NAME@REGION")
    first = SceneFile(args.scenes[0])
    regions = {r: first.region(r) for r in {n.partition("@")[2] for n in args.params} if r}
    scenes = [first.scene] + [load_scene(p) for p in args.scenes[1:]]
    tables = [_marker_table(p) for p in args.markers]
    start = dict(_assignment(a, "--start", float) for a in args.start)
    bounds = dict(_assignment(a, "--bounds", _interval) for a in args.bounds)

    def progress(k, J, values):
        shown = ", ".join(f"{n} = {v:.6g}" for n, v in values.items())
        print(f"iteration {k}: J = {J:.4e}, {shown}", flush=True)
    result = fitting.fit(scenes, [t[:, :3] for t in tables], [t[:, 3:] for t in tables],
                         args.params, start, bounds, args.max_iter, progress, regions,
                         log=_trial_failed)
    print(f"stopped after {result.iterations} iterations ({result.evaluations} solves per "
          f"case, {result.seconds:.1f} s): {result.message}")
    for n, v in result.values.items():
        unit = fitting.PARAMETERS[n.partition("@")[0]][0]
        print(f"  {n} = {v:.6g} +- {result.deviations[n]:.2g} {unit}".rstrip())
    worst = np.argsort(result.marker_residuals)[::-1][:3]
    print(f"misfit: rms {1e3 * result.rms:.4g} mm over {result.marker_residuals.size} markers; "
          "largest: " + ", ".join(f"marker {k} {1e3 * result.marker_residuals[k]:.3g} mm"
                                  for k in worst))
    if args.json:
        write_json(args.json, {"values": result.values, "deviations": result.deviations,
                               "marker_residuals_m": result.marker_residuals.tolist(),
                               "rms_m": result.rms, "iterations": result.iterations,
                               "converged": result.converged, "message": result.message})
        print(f"-> {args.json}")
    if args.output:
        fitted = fitting.fitted_table(first.table, scenes[0], result.values, args.scenes[0],
                                      args.output, regions)
        _write_scene(args.output, f"{args.scenes[0]} with the values fitted by python -m "
                                  f"anisofem fit", fitted)
    return 0 if result.converged else 1


def design_command(args):
    """python -m anisofem design: each iteration's objective and gradient norm, the angles,
    where the tip comes to rest, the designed scene file."""
    from ..inverse.design import Helix, design
    if args.output:
        check_folder(args.output, "--output")
        if not is_scene_file(args.output):
            raise ValueError(f"--output: a scene file (.toml), got {args.output!r}")
    if args.segments < 1:
        raise ValueError(f"--segments: at least 1, got {args.segments}")
    low, high = _interval(args.bounds)
    scene_file = SceneFile(args.scene)
    axis, origin, crossed, angle = scene_file.helix(args.region)
    helix = Helix(scene_file.region(args.region), axis, origin, args.segments, crossed)
    start = args.start if args.start is not None else angle

    def progress(k, J, g, angles):
        print(f"iteration {k}: J = {J:.4e}, |dJ/dangles| = {g:.3e}, angles "
              + _listed(angles, "{:.2f}"), flush=True)
    result = design(scene_file.scene, helix, scene_file.vertices(args.tip), args.target, start,
                    (low, high), args.smooth, args.max_iter, progress, log=_trial_failed)
    print(f"stopped after {result.iterations} iterations ({result.evaluations} solves, "
          f"{result.seconds:.1f} s): {result.message}")
    print("angles (degrees): " + _listed(result.angles, "{:.3f}")
          + ("" if len(result.angles) <= SHOWN else f" (all {len(result.angles)} in the "
             f"scene file{' ' + args.output if args.output else ' --output writes'})"))
    print(f"tip at {np.array2string(result.tip, precision=6)} m, "
          f"{1e3 * result.distance:.4g} mm from the target")
    if args.output:
        table = fitting.moved_mesh_path(scene_file.table, args.scene, args.output)
        region = table.setdefault("regions", {}).setdefault(args.region, {})
        region["fiber"] = {"helix": {"axis": axis.tolist(), "origin": origin.tolist(),
                                     "crossed": crossed,
                                     "segments": [round(float(a), 6) for a in result.angles]}}
        _write_scene(args.output, f"{args.scene} with fiber angles designed by python -m "
                                  f"anisofem design", table)
    return 0 if result.converged else 1


#: Numbers a progress line shows of a list, the first and the last ones where it is longer
SHOWN = 8


def _listed(values, form):
    """values formatted and joined by spaces; past SHOWN, the first SHOWN - 2 and the last two
    around "... (k more) ...", so that a line stays a line."""
    text = [form.format(v) for v in values]
    if len(text) > SHOWN:
        text = text[:SHOWN - 2] + [f"... ({len(text) - SHOWN + 2} more) ..."] + text[-2:]
    return " ".join(text)


def _marker_table(path):
    """(k, 6) rows of a marker CSV: x, y, z, ux, uy, uz in m (_table)."""
    return _table(path, "--markers", ("x", "y", "z", "ux", "uy", "uz"), "marker")


def _table(path, flag, columns, what):
    """(k, len(columns)) rows of numbers of a CSV file, a header line allowed; ValueError
    naming the flag, the file and the line of what is not len(columns) numbers."""
    if not os.path.isfile(path):
        raise FileNotFoundError(f"{flag}: no such file {path!r}")
    rows = []
    with open(path, errors="replace") as f:
        for k, line in enumerate(f, 1):
            fields = [x.strip() for x in line.split(",")]
            if not line.strip() or (k == 1 and not _numbers(fields)):
                continue  # a blank line, or the header
            if len(fields) != len(columns):
                raise ValueError(f"{flag}: {path} line {k}: {len(fields)} fields, expected "
                                 f"{', '.join(columns)}")
            if not _numbers(fields):
                bad = next(x for x in fields if not _numbers([x]))
                raise ValueError(f"{flag}: {path} line {k}: {bad!r} is not a finite number")
            rows.append([float(x) for x in fields])
    if not rows:
        raise ValueError(f"{flag}: {path} holds no {what} rows ({', '.join(columns)} in SI "
                         f"units)")
    return np.array(rows)


def _numbers(fields):
    """Whether every field is a finite number."""
    try:
        return all(math.isfinite(float(x)) for x in fields)
    except ValueError:
        return False


def _interval(text):
    low, sep, high = text.partition(":")
    if not sep:
        raise ValueError(f"expected LOW:HIGH, got {text!r}")
    return float(low), float(high)


def _assignment(text, flag, parse):
    name, sep, value = text.partition("=")
    if not sep or name.partition("@")[0] not in fitting.PARAMETERS:
        raise ValueError(f"{flag}: expected NAME=VALUE with NAME one of "
                         f"{', '.join(fitting.PARAMETERS)} (or NAME@REGION), got {text!r}")
    try:
        return name, parse(value)
    except ValueError as err:
        raise ValueError(f"{flag}: {name}: {err}") from None


def control_command(args):
    """python -m anisofem control: each iteration's objective and the effector's largest
    error; the knots' controls; the full FEM's rollout under them against the path; the scene
    file with the controls on curves (-o)."""
    from ..inverse.control import follow
    from ..reduced import Loads, ReducedModel
    from ..solvers.solve import simulate, solve
    scene_file = SceneFile(args.scene)
    scene = scene_file.scene
    ranges = scene_file.control_ranges
    missing = [n for n in scene.controls if n not in ranges]
    if not scene.controls or missing:
        why = "it has none" if not scene.controls else "missing for " + ", ".join(missing)
        raise ValueError(f"scene: each control needs a range ([controls.NAME] range = [low, "
                         f"high]); {why}")
    path = _table(args.path, "--path", ("t", "x", "y", "z"), "path")
    effector = [int(v) for v in scene_file.vertices(args.effector)]
    print(f"{args.scene}: {scene.mesh.n_tets} tets, controls {', '.join(scene.controls)}; "
          f"building its reduced model ({args.modes} modes + {args.snapshots} directions fitted "
          f"to the controls' ranges)", flush=True)
    model = ReducedModel(scene, modes=args.modes, snapshots=args.snapshots,
                         loads=Loads(controls=ranges), validate=False)
    knots = np.round(np.arange(0.0, path[-1, 0] + 0.5 * args.knot, args.knot), 9)
    if knots[-1] < path[-1, 0]:
        knots = np.append(knots, path[-1, 0])

    def progress(k, J, controls):
        print(f"iteration {k}: J = {J:.4e}", flush=True)
    result = follow(model, effector, path[:, 0], path[:, 1:], args.dt, knots=knots,
                    smooth=args.smooth, max_iter=args.max_iter, progress=progress,
                    log=_trial_failed)
    size = float(np.ptp(scene.mesh.vertices, axis=0).max())
    print(f"stopped after {result.iterations} iterations ({result.evaluations} rollouts, "
          f"{result.seconds:.1f} s): {result.message}")
    print(f"reduced model (r = {model.r}): largest error {1e3 * result.errors[1:].max():.3g} "
          f"mm ({100 * result.largest_error:.3g}% of the body's {1e3 * size:.3g} mm)")
    for j, t in enumerate(result.knot_times):
        print(f"  t = {t:.3f} s: " + ", ".join(f"{n} = {v:.5g}" for n, v in
                                                zip(model.controls, result.controls[j])))
    steps = len(result.errors) - 1
    start = solve(scene.with_controls(result.at(0.0)), warn=False).x
    full = simulate(scene, steps, args.dt, x0=start, controls=result.at, warn=False)
    tip = full.positions[:, effector].mean(axis=1)
    targets = np.array([np.interp(args.dt * np.arange(steps + 1), path[:, 0], path[:, a])
                        for a in (1, 2, 3)]).T
    worst = float(np.linalg.norm(tip - targets[:len(tip)], axis=1)[1:].max())
    print(f"full FEM under these controls: largest error {1e3 * worst:.3g} mm "
          f"({100 * worst / size:.3g}% of the body)")
    if args.output:
        table = controlled_table(scene_file, result, args.output)
        _write_scene(args.output, f"{args.scene} with the controls python -m anisofem control "
                                  f"found, on curves", table)
    return 0 if result.converged else 1


def controlled_table(scene_file, result, output_path):
    """A copy of the scene file's table with each control on a curve of the knots' values:
    [curves.NAME_path] whose values are the control's over its largest magnitude (its value),
    its mesh path made relative to output_path's folder."""
    from ..inverse.fit import moved_mesh_path
    out = moved_mesh_path(scene_file.table, scene_file.path, output_path)
    curves = out.setdefault("curves", {})
    for k, name in enumerate(scene_file.scene.controls):
        values = result.controls[:, k]
        largest = float(np.abs(values).max())
        curves[f"{name}_path"] = {"times": [float(t) for t in result.knot_times],
                                  "values": [float(v / largest) if largest else 0.0
                                             for v in values]}
        control = out["controls"][name]
        control["value"], control["curve"] = largest, f"{name}_path"
    return out


def _write_scene(path, comment, table):
    """Write a scene file's table as TOML at path (atomically), under a comment line."""
    with atomic_path(path, ".toml") as tmp:
        with open(tmp, "w") as fh:
            fh.write(f"# {comment}\n" + dump(table))
    print(f"-> {path}")


def _trial_failed(message):
    """Say that a trial point's solve failed (and the search stepped back from it)."""
    print(f"  trial: {message}", flush=True)
