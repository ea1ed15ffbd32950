"""The inverse commands: `fit` (material parameters from measured markers) and `design`
(a fiber layout for a target)."""
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
        with atomic_path(args.output, ".toml") as tmp:
            with open(tmp, "w") as fh:
                fh.write(f"# {args.scenes[0]} with the values fitted by python -m anisofem fit\n"
                         + dump(fitted))
        print(f"-> {args.output}")
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
        with atomic_path(args.output, ".toml") as tmp:
            with open(tmp, "w") as fh:
                fh.write(f"# {args.scene} with fiber angles designed by python -m anisofem "
                         f"design\n" + dump(table))
        print(f"-> {args.output}")
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
    """(k, 6) rows of a marker CSV: x, y, z, ux, uy, uz in m, a header line allowed; ValueError
    naming the file and the line of what is not six numbers."""
    if not os.path.isfile(path):
        raise FileNotFoundError(f"--markers: no such file {path!r}")
    rows = []
    with open(path, errors="replace") as f:
        for k, line in enumerate(f, 1):
            fields = [x.strip() for x in line.split(",")]
            if not line.strip() or (k == 1 and not _numbers(fields)):
                continue  # a blank line, or the header
            if len(fields) != 6:
                raise ValueError(f"--markers: {path} line {k}: {len(fields)} fields, expected "
                                 f"x, y, z, ux, uy, uz")
            if not _numbers(fields):
                bad = next(x for x in fields if not _numbers([x]))
                raise ValueError(f"--markers: {path} line {k}: {bad!r} is not a finite number")
            rows.append([float(x) for x in fields])
    if not rows:
        raise ValueError(f"--markers: {path} holds no marker rows (x, y, z, ux, uy, uz in m)")
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


def _trial_failed(message):
    """Say that a trial point's solve failed (and the search stepped back from it)."""
    print(f"  trial: {message}", flush=True)
