"""Command line: `python -m anisofem {mesh,solve,trade,fit,design,bench}`.

  python -m anisofem mesh box --cells 10 2 2 -o beam.msh
  python -m anisofem solve beam.msh --fixed x-min --gravity 0 0 -9.81 --fiber 1 0 0 \\
      --kappa 1e5 --material neohookean -o beam.vtu
  python -m anisofem trade beam.msh --fiber 0.766 0 0.643 --kappa 1e5 --steps 100 \\
      --json trade.json --png trade.png
  python -m anisofem bench                  # writes results/bench_anisofem.json
  python -m anisofem bench --large --huge
"""
import argparse
import os
import re
import sys

import numpy as np

from . import bench, bench_large, bench_load, convergence, ladder, meshgen, methods, robustness
from . import fit as fitting
from .files import atomic_path, check_folder, write_json
from .io import check_output_path, read_mesh, write_mesh, write_series
from .inversion import inversion
from .material import MODELS, Material
from .metrics import end_vertices, tip_displacement
from .scene import Scene
from .scenefile import SceneFile, dump, load_scene
from .solve import CONTINUATION, simulate, solve

#: Each shape: (its mesh from the shape flags, the flags it takes with their defaults, the end
#: it stands on: the --fixed default)
_SHAPES = {
    "box": (lambda a: meshgen.box_beam(a.size, a.cells, tets_per_cell=a.tets_per_cell),
            {"size": (0.1, 0.02, 0.02), "cells": (10, 2, 2), "tets_per_cell": 5}, "x-min"),
    "cylinder": (lambda a: meshgen.cylinder_beam(a.size[0], a.size[1] / 2, a.cells[0],
                                                 a.cells[1], a.rings),
                 {"size": (0.1, 0.02), "cells": (10, 2), "rings": 1}, "x-min"),
    "t": (lambda a: meshgen.t_shape(), {}, "z-min"),
    "y": (lambda a: meshgen.y_shape(), {}, "z-min")}
#: The shapes' flags
_SHAPE_FLAGS = ("size", "cells", "rings", "tets_per_cell")


#: the finer meshes of the same body the trade can measure against (--bodies): name ->
#: (row label, the finer mesh of a linear mesh)
BODIES = {"quadratic": ("exact, quadratic tets", lambda m: m.raised()),
           "refined": ("exact, refined mesh", lambda m: m.refined()),
           "refined-quadratic": ("exact, refined quadratic", lambda m: m.refined().raised())}


def _order_argument(p):
    p.add_argument("--order", type=int, choices=(1, 2), default=None,
                   help="1: linear tets; 2: quadratic (10-node) tets, a linear mesh raised by "
                        "its edge midpoints (default: a file's own order, linear for a shape)")


def _of_order(mesh, order):
    """mesh at the --order asked (None: as it is); a quadratic file cannot be lowered."""
    if order is None or order == mesh.order:
        return mesh
    if order == 1:
        raise ValueError("--order 1: the mesh has quadratic tets; a quadratic mesh is not "
                         "lowered (read it as it is, or mesh it again)")
    return mesh.raised()


def _fixed(mesh, spec):
    """'x-min', 'y-max', ...: the vertices on that end of the mesh."""
    try:
        axis, side = spec.split("-")
        return end_vertices(mesh, "xyz".index(axis), side)
    except ValueError:
        raise ValueError(f"--fixed: expected AXIS-SIDE like x-min or z-max, got {spec!r}") \
            from None


def _shape_arguments(p):
    p.add_argument("--size", type=float, nargs="+",
                   help="box: length width height (default 0.1 0.02 0.02); cylinder: length "
                        "diameter (default 0.1 0.02), m; t and y have fixed dimensions")
    p.add_argument("--cells", type=int, nargs="+",
                   help="box: nx ny nz (default 10 2 2); cylinder: along section (default 10 "
                        "2)")
    p.add_argument("--rings", type=int, help="cylinder: O-grid rings (default 1)")
    p.add_argument("--tets-per-cell", type=int, choices=(5, 6),
                   help="box: tets per hex cell (default 5; 6: the more accurate split for "
                        "quadratic tets, docs/fem.md)")
    _order_argument(p)


def _shape(args, name):
    """The mesh of the shape called name that the shape flags describe; a flag the shape does
    not take, or with the wrong number of values, is a ValueError."""
    build, takes, _ = _SHAPES[name]
    for flag in _SHAPE_FLAGS:
        given, option = getattr(args, flag), "--" + flag.replace("_", "-")
        if given is None:
            setattr(args, flag, takes.get(flag))
        elif flag not in takes:
            raise ValueError(
                f"{option}: the {name} shape does not take it; it takes "
                + (", ".join("--" + f.replace("_", "-") for f in takes) if takes else
                   f"no shape flag (anisofem.{name}_shape in Python takes its dimensions)"))
        elif isinstance(takes[flag], tuple) and len(given) != len(takes[flag]):
            raise ValueError(f"{option}: expected {len(takes[flag])} values for the {name} "
                             f"shape, got {len(given)}")
    return build(args)


def _no_shape_flags(args):
    """ValueError naming a shape flag given with a mesh file (whose mesh is as it is)."""
    for flag in _SHAPE_FLAGS:
        if getattr(args, flag, None) is not None:
            raise ValueError(f"--{flag.replace('_', '-')}: a shape flag; the mesh of a file is "
                             f"read as it is")


#: The scene flags besides --fixed and their defaults (a scene file sets them all itself)
SCENE_FLAGS = {"gravity": (0.0, 0.0, -9.81), "young": 1e5, "poisson": 0.48, "density": 1000.0,
               "fiber": (1.0, 0.0, 0.0), "kappa": 0.0, "material": "stvk"}


def _scene_arguments(s, fixed="x-min"):
    """The flags that make a Scene of a mesh (solve and trade); fixed: --fixed's default, None
    for the shape's (scene_of)."""
    d = SCENE_FLAGS
    s.add_argument("--fixed", default=fixed,
                   help="end held fixed: AXIS-SIDE" + ("" if fixed else " (default: the end the "
                        "shape stands on: x-min for box and cylinder, z-min for t and y; x-min "
                        "for a mesh file)"))
    s.add_argument("--gravity", type=float, nargs=3, default=d["gravity"],
                   metavar=("GX", "GY", "GZ"), help="m/s^2")
    s.add_argument("--young", type=float, default=d["young"], help="Pa")
    s.add_argument("--poisson", type=float, default=d["poisson"], help="Poisson's ratio")
    s.add_argument("--density", type=float, default=d["density"], help="kg/m^3")
    s.add_argument("--fiber", type=float, nargs=3, default=d["fiber"],
                   help="unit fiber direction")
    s.add_argument("--kappa", type=float, default=d["kappa"], help="fiber stiffness, Pa")
    s.add_argument("--material", default=d["material"], choices=MODELS,
                   help="base material: stvk (the paper's) or neohookean (never turns inside "
                        "out; pick it when the scene compresses hard)")


def is_scene_file(name):
    """Whether a command's positional names a TOML scene file (anisofem.scenefile)."""
    return str(name).lower().endswith(".toml")


def _scene_file(args, name, fixed_default):
    """The Scene of the scene file `name`; ValueError naming a flag given with it that the
    file sets itself (shape, order, --fixed and the scene flags away from their defaults)."""
    _no_shape_flags(args)
    given = [f for f, d in SCENE_FLAGS.items()
             if tuple(np.atleast_1d(getattr(args, f))) != tuple(np.atleast_1d(d))]
    if args.order is not None:
        given.insert(0, "order")
    if args.fixed != fixed_default:
        given.insert(0, "fixed")
    if given:
        raise ValueError(f"--{given[0]}: the scene file {name} sets the scene (its mesh, "
                         f"materials, boundary and loads); change it there")
    return load_scene(name)


def _scene(args, mesh):
    fiber = np.asarray(args.fiber)
    if not np.isfinite(fiber).all():
        raise ValueError(f"--fiber: must be finite, got {args.fiber}")
    if not np.linalg.norm(fiber) > 0:
        raise ValueError(f"--fiber: a direction needs a nonzero vector, got {args.fiber}")
    material = Material(args.young, args.poisson, args.density, fiber / np.linalg.norm(fiber),
                        args.kappa, model=args.material)
    return Scene(mesh, material, fixed=_fixed(mesh, args.fixed), gravity=args.gravity)


def body_of(args, scene, body, flag):
    """The Scene of scene's body on the finer mesh `body` (a key of BODIES), with the same
    flags; ValueError naming `flag` where the scene's tets are quadratic already or it comes
    from a scene file."""
    if is_scene_file(args.scene):
        raise ValueError(f"{flag}: takes a mesh file or a shape; a scene file's regions and "
                         f"surfaces are named on its own mesh")
    if scene.mesh.order != 1:
        raise ValueError(f"{flag}: the scene has quadratic tets already; give its linear mesh")
    return _scene(args, BODIES[body][1](scene.mesh))


def add_scene_arguments(p):
    """The positional scene (a mesh file or a shape) and the flags that make a Scene of it
    (trade here, `python -m export reduced`)."""
    p.add_argument("scene", help="a scene file (.toml, docs/scenes.md), a mesh file meshio "
                                 f"reads, or a shape: {', '.join(sorted(_SHAPES))}")
    _shape_arguments(p)
    _scene_arguments(p, fixed=None)


def scene_of(args):
    """The Scene that the flags of add_scene_arguments describe (args.fixed set to the end
    held where it was not given)."""
    if is_scene_file(args.scene):
        return _scene_file(args, args.scene, None)
    if args.scene in _SHAPES:
        mesh = _shape(args, args.scene)
        args.fixed = args.fixed or _SHAPES[args.scene][2]
    else:
        _no_shape_flags(args)
        mesh = read_mesh(args.scene)
        args.fixed = args.fixed or "x-min"
    return _scene(args, _of_order(mesh, args.order))


class Parser(argparse.ArgumentParser):
    """argparse's parser that reads negative numbers in exponent form (--young -1e5) as values,
    as it reads -100000 and -0.5 (its own pattern misses the exponent)."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = re.compile(r"^-(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?$")


class _ShowDefaults(argparse.ArgumentDefaultsHelpFormatter):
    """Help that names each option's default, where it has one."""

    def _get_help_string(self, action):
        if action.default is None or action.default is False:
            return action.help
        return super()._get_help_string(action)


def _parser():
    p = Parser(prog="python -m anisofem", description=__doc__,
               formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="command", required=True)
    defaults = {"formatter_class": _ShowDefaults}
    m = sub.add_parser("mesh", help="generate a mesh of one of the paper's shapes, or write a "
                                    "scene file's mesh with its fibers and materials",
                       **defaults)
    m.add_argument("shape", help=f"a shape ({', '.join(sorted(_SHAPES))}) or a scene file "
                                 f"(.toml)")
    _shape_arguments(m)
    m.add_argument("-o", "--output", required=True)
    s = sub.add_parser("solve", help="static equilibrium or a backward-Euler rollout", **defaults)
    s.add_argument("mesh", help="a scene file (.toml, docs/scenes.md) or a mesh file meshio "
                                "reads (.msh, .vtu, .xdmf, ...)")
    s.add_argument("-o", "--output", required=True,
                   help="result file (.vtu, .xdmf, .msh), or a ParaView series (.pvd) of every "
                        "step or ramp increment")
    _scene_arguments(s)
    _order_argument(s)
    s.add_argument("--steps", type=int, default=0,
                   help="backward-Euler steps instead of statics (writes the last state)")
    s.add_argument("--dt", type=float, default=0.02, help="s")
    s.add_argument("--method", default="auto", choices=["auto", *methods.METHODS],
                   help="how each solve is done (see anisofem.methods; auto: exact Newton, "
                        "multigrid-preconditioned inexact Newton on large meshes)")
    s.add_argument("--iterations", type=int, default=None,
                   help="a fixed budget of iterations per solve instead of a tolerance")
    s.add_argument("--rtol", type=float, default=1e-8,
                   help="relative tolerance of each solve's gradient norm")
    s.add_argument("--engine", default="serial", choices=["serial", "petsc"],
                   help="petsc: over the MPI ranks of `mpirun -n K python -m anisofem solve "
                        "...` (methods auto, newton and cg; needs `make install-mpi`)")
    s.add_argument("--continuation", default="auto", choices=CONTINUATION,
                   help="static solve: ramp the load in increments where the whole load fails "
                        "(auto), from the start (always) or never")
    s.add_argument("--ramp", type=int, default=0, metavar="K",
                   help="static solves at 1/K, 2/K, ..., 1 of the loads (each from the last), "
                        "every one written when --output is a series (.pvd)")
    t = sub.add_parser("trade", help="the speed/accuracy trade of every solver rung on a scene "
                                     "(table, JSON, Pareto plot; minutes)", **defaults)
    add_scene_arguments(t)
    t.add_argument("--steps", type=int, default=100, help="backward-Euler steps from rest")
    t.add_argument("--dt", type=float, default=0.02, help="s")
    t.add_argument("--tolerance", type=float, default=0.01,
                   help="name the cheapest rung whose tip error stays within this fraction of "
                        "the static deflection")
    t.add_argument("--no-surrogates", action="store_true",
                   help="only the FEM rungs (skip the shipped networks)")
    t.add_argument("--bodies", nargs="+", choices=list(BODIES), default=[],
                   help="the same body on finer meshes (quadratic tets, the mesh refined once, "
                        "both), each rolled out exactly as a row; every rung's error against "
                        "the finest (the body) is added, and the plot shows it (minutes)")
    t.add_argument("--rungs", nargs="+", metavar="NAME",
                   help="run only these rungs besides the exact one (names as in the table, "
                        "quoted: --rungs 'reduced m5' 'cg amg')")
    t.add_argument("--json", help="write the result here")
    t.add_argument("--png", help="write the Pareto plot here")
    f = sub.add_parser("fit", help="identify material parameters from measured marker "
                                   "displacements (one scene file per load case)", **defaults)
    f.add_argument("scenes", nargs="+", help="scene files (.toml), one per load case, of one "
                                             "body")
    f.add_argument("--markers", nargs="+", required=True, metavar="CSV",
                   help="one per scene: rows x, y, z, ux, uy, uz (a marker's rest position and "
                        "measured displacement, m; a header line is skipped)")
    f.add_argument("--params", nargs="+", required=True, metavar="NAME",
                   help=f"what is fitted: {', '.join(fitting.PARAMETERS)}, one value over the "
                        f"whole body, or NAME@REGION over a physical volume (fiber angles in "
                        f"degrees: azimuth about z from x, elevation toward z)")
    f.add_argument("--start", nargs="+", default=[], metavar="NAME=VALUE",
                   help="start values (default: the scene's)")
    f.add_argument("--bounds", nargs="+", default=[], metavar="NAME=LOW:HIGH",
                   help="bounds (default: " + ", ".join(
                       f"{n} {lo:g}:{hi:g}" for n, (_, _, (lo, hi)) in
                       fitting.PARAMETERS.items()) + ")")
    f.add_argument("--max-iter", type=int, default=100, help="L-BFGS-B iterations at most")
    f.add_argument("-o", "--output", help="write the fitted scene file here (.toml)")
    f.add_argument("--json", help="write the fitted values, deviations and residuals here")
    d = sub.add_parser("design", help="design a region's fiber winding angles, one per "
                                      "segment along its helix's axis, so that the body's tip "
                                      "comes to rest at a target", **defaults)
    d.add_argument("scene", help="a scene file (.toml) whose region has helix fibers")
    d.add_argument("--region", required=True, help="the physical volume whose fibers change")
    d.add_argument("--tip", required=True,
                   help="the tip: a physical surface or a side (x-max, ...) whose vertices' "
                        "mean is moved")
    d.add_argument("--target", type=float, nargs=3, required=True, metavar=("X", "Y", "Z"),
                   help="where the tip should come to rest, m")
    d.add_argument("--segments", type=int, default=4, help="winding angles along the axis")
    d.add_argument("--start", type=float, help="start angle of every segment, degrees "
                                               "(default: the scene's helix angle)")
    d.add_argument("--bounds", default="0:90", metavar="LOW:HIGH", help="degrees")
    d.add_argument("--smooth", type=float, default=1e-3,
                   help="weight of the squared angle steps between neighbouring segments, "
                        "per radian^2")
    d.add_argument("--max-iter", type=int, default=100, help="L-BFGS-B iterations at most")
    d.add_argument("-o", "--output", help="write the designed scene file here (.toml)")
    b = sub.add_parser("bench", help="speed of the kernels and solvers (table + JSON)",
                       **defaults)
    b.add_argument("--sizes", nargs="+", default=list(bench.SIZES), choices=list(bench.SIZES))
    b.add_argument("--large", action="store_true",
                   help="static solves and backward-Euler steps at 10^4 and 10^5 tets by "
                        "each large-mesh path, peak memory included (minutes)")
    b.add_argument("--huge", action="store_true",
                   help="with --large or --distributed: 10^6 tets too (minutes)")
    b.add_argument("--distributed", action="store_true",
                   help="the petsc engine on 1 and 2 MPI ranks against one process, 10^5 tets "
                        "(needs `make install-mpi`; minutes)")
    b.add_argument("--convergence", action="store_true",
                   help="the cantilever's static sag and step time with linear and quadratic "
                        "tets, 5 or 6 per cell, on refined meshes, against the extrapolated "
                        "limit, and the cheapest mesh within 2%% of it (about ten minutes)")
    b.add_argument("--refinements", type=int, nargs="+", default=None,
                   help="with --convergence: the refinements of its 10 x 2 x 2 cells (default "
                        f"{' '.join(map(str, convergence.REFINEMENTS))})")
    b.add_argument("--max-unknowns", type=int, default=None,
                   help="with --convergence: leave out meshes with more unknowns (default "
                        f"{convergence.MAX_UNKNOWNS:,})")
    b.add_argument("--crossover", action="store_true",
                   help="exact Newton against multigrid CG from 4,800 to 19,200 tets, where "
                        "method='auto' switches (minutes)")
    b.add_argument("--robustness", action="store_true",
                   help="static solves of 324 soft cantilevers at 1-100 g: does each reach a "
                        "minimum (about 3 minutes)")
    b.add_argument("--dynamics", action="store_true",
                   help="with --robustness: ten backward-Euler steps of 162 of them at dt = "
                        "0.02, 0.2 and 1 s too (longer)")
    b.add_argument("--under-load", action="store_true",
                   help="every rung of the trade on its 200- and 12,800-tet cantilevers, idle "
                        "and beside --busy busy processes that the command starts and stops: "
                        "each one's slowdown (about ten minutes)")
    b.add_argument("--busy", type=int, default=None,
                   help="with --under-load: busy processes (default: the cores this process "
                        "may run on)")
    b.add_argument("--rungs", nargs="+", metavar="NAME",
                   help="with --under-load: only these rungs (names as in the trade's table)")
    b.add_argument("--json", default=None,
                   help="where to write the results (default: results/bench_anisofem.json, "
                        "with --large results/bench_large.json, with --crossover "
                        "results/bench_crossover.json, with --robustness "
                        "results/robustness.json, with --convergence results/convergence.json, "
                        "with --distributed results/bench_distributed.json, with --under-load "
                        "results/bench_under_load.json)")
    return p


#: What a command's bad input raises: each ends it with one line and exit status 2
BAD_INPUT = (ValueError, TypeError, FileNotFoundError, ImportError)


def main(argv=None):
    """Run a command; bad input ends it with a one-line error and exit status 2, before any
    long work starts."""
    parser = _parser()
    args = parser.parse_args(argv)
    try:
        return _COMMANDS[args.command](args)
    except BAD_INPUT as err:
        parser.exit(2, f"{parser.prog} {args.command}: error: {err}\n")


def _mesh(args):
    check_output_path(args.output)
    if is_scene_file(args.shape):
        _no_shape_flags(args)
        if args.order is not None:
            raise ValueError(f"--order: the scene file {args.shape} sets it")
        scene = load_scene(args.shape)
        write_mesh(args.output, scene.mesh, scene=scene)
        print(f"{scene.mesh} with its fiber field -> {args.output}")
        return 0
    if args.shape not in _SHAPES:
        raise ValueError(f"shape: expected one of {', '.join(sorted(_SHAPES))} or a scene file "
                         f"(.toml), got {args.shape!r}")
    mesh = _of_order(_shape(args, args.shape), args.order)
    write_mesh(args.output, mesh)
    print(f"{mesh} -> {args.output}")
    return 0


def _solve(args):
    series = args.output.lower().endswith(".pvd")
    if series:
        check_folder(args.output, "--output")
    else:
        check_output_path(args.output)
    if args.ramp < 0 or (args.ramp and args.steps):
        raise ValueError(f"--ramp: a number of static increments >= 1, without --steps; got "
                         f"{args.ramp}")
    if is_scene_file(args.mesh):
        scene = _scene_file(args, args.mesh, "x-min")
    else:
        scene = _scene(args, _of_order(read_mesh(args.mesh), args.order))
    mesh = scene.mesh
    if args.engine == "petsc":
        from .distributed import command
        return command.run(args, scene, command.check(args, scene))
    how = {"method": args.method, "rtol": args.rtol, "iterations": args.iterations}
    methods.make(n_unknowns=scene.n_free, **how)  # bad options fail here, before the solve
    states, times = None, None
    if args.steps:
        roll = simulate(scene, args.steps, args.dt, **how)
        x, ok = roll.positions[-1], roll.completed
        states, times = roll.positions, args.dt * np.arange(len(roll.positions))
        budget = (f" (a budget of {args.iterations} iterations per step)"
                  if args.iterations else "")
        print(f"{len(roll.positions) - 1} steps, converged: {roll.converged}{budget}")
    elif args.ramp:
        states, times, x, ok = [scene.initial_positions()], [0.0], None, True
        for k in range(1, args.ramp + 1):
            res = solve(scene.loaded(k / args.ramp), x0=x, continuation=args.continuation,
                        **how)
            x, ok = res.x, ok and res.converged
            states.append(x)
            times.append(k / args.ramp)
            print(f"{k}/{args.ramp} of the loads: {res.iterations} Newton iterations, "
                  f"converged: {res.converged}")
    else:
        res = solve(scene, continuation=args.continuation, **how)
        x, ok = res.x, res.converged
        ramped = f" in {res.increments} load increments" if res.increments else ""
        print(f"{res.iterations} Newton iterations{ramped}, converged: {ok}, relative residual "
              f"{res.residuals[-1]:.2e}, {'a minimum' if res.stability.minimum else 'a saddle'}"
              f" (smallest eigenvalue of the Hessian {res.stability.smallest:.3g} N/m)")
    print("tip displacement (m):", np.array2string(tip_displacement(mesh, x), precision=6))
    inv = inversion(mesh, x)
    if not inv.physical:
        print(f"not physical: {inv.inverted} of {mesh.n_tets} elements turned inside out "
              f"(smallest det F {inv.min_volume_ratio:.3g}; the 'inverted' field marks them)")
    if series:
        if states is None:
            states, times = [scene.initial_positions(), x], [0.0, 1.0]
        write_series(args.output, mesh, states, times, scene)
    else:
        write_mesh(args.output, mesh, x, scene)
    print(f"-> {args.output}")
    return 0 if ok else 1


def _trade(args):
    """python -m anisofem trade: print the table, write the JSON and the plot."""
    for path, name in ((args.json, "--json"), (args.png, "--png")):
        if path:
            check_folder(path, name)
    scene = scene_of(args)
    rungs, notes = ladder.fem_rungs(), []
    if not args.no_surrogates:
        rungs += ladder.registered_rungs(scene, args.dt, notes)
    if args.rungs:
        rungs = ladder.select_rungs(rungs, args.rungs)
    bodies = [(BODIES[b][0], body_of(args, scene, b, "--bodies")) for b in args.bodies]
    result = ladder.trade(scene, args.steps, args.dt, tolerance=args.tolerance, rungs=rungs,
                          name=args.scene, bodies=bodies)
    result["notes"][:0] = notes
    print(ladder.trade_table(result))
    if args.json:
        write_json(args.json, result)
        print(f"-> {args.json}")
    if args.png:
        ladder.plot(result, args.png)
        print(f"-> {args.png}")
    return 0


def _bench(args):
    if args.huge and not (args.large or args.distributed):
        raise ValueError("--huge: goes with --large or --distributed")
    if sum((args.large, args.crossover, args.robustness, args.convergence,
            args.distributed, args.under_load)) > 1:
        raise ValueError("--large, --crossover, --robustness, --convergence, --distributed, "
                         "--under-load: one at a time")
    if not args.under_load and (args.busy is not None or args.rungs):
        raise ValueError("--busy, --rungs: go with --under-load")
    if args.dynamics and not args.robustness:
        raise ValueError("--dynamics: goes with --robustness")
    if not args.convergence and (args.refinements or args.max_unknowns is not None):
        raise ValueError("--refinements, --max-unknowns: go with --convergence")
    out = {} if args.json is None else {"out": args.json}
    if args.distributed:
        from .distributed import MISSING, available, bench as distributed_bench
        if not available():
            raise ImportError(MISSING)
        distributed_bench.run(args.huge, **out)
    elif args.under_load:
        bench_load.run(args.busy, rungs=args.rungs, **out)
    elif args.convergence:
        convergence.run(refinements=args.refinements or convergence.REFINEMENTS,
                        max_unknowns=(convergence.MAX_UNKNOWNS if args.max_unknowns is None
                                      else args.max_unknowns), **out)
    elif args.robustness:
        robustness.run(args.dynamics, **out)
    elif args.large:
        bench_large.run(args.huge, **out)
    elif args.crossover:
        bench_large.crossover(**out)
    else:
        bench.run(tuple(args.sizes), **out)
    return 0


def _fit(args):
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
                         args.params, start, bounds, args.max_iter, progress, regions)
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


def _design(args):
    """python -m anisofem design: each iteration's objective and gradient norm, the angles,
    where the tip comes to rest, the designed scene file."""
    from .design import Helix, design
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
              + " ".join(f"{a:.2f}" for a in angles), flush=True)
    result = design(scene_file.scene, helix, scene_file.vertices(args.tip), args.target, start,
                    (low, high), args.smooth, args.max_iter, progress)
    print(f"stopped after {result.iterations} iterations ({result.evaluations} solves, "
          f"{result.seconds:.1f} s): {result.message}")
    print("angles (degrees): " + " ".join(f"{a:.3f}" for a in result.angles))
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


def _marker_table(path):
    """(k, 6) rows of a marker CSV: x, y, z, ux, uy, uz in m (a header line skipped)."""
    if not os.path.isfile(path):
        raise FileNotFoundError(f"--markers: no such file {path!r}")
    try:
        rows = np.loadtxt(path, delimiter=",", ndmin=2)
    except ValueError:
        rows = np.loadtxt(path, delimiter=",", ndmin=2, skiprows=1)
    if rows.shape[1] != 6 or rows.shape[0] == 0:
        raise ValueError(f"--markers: {path} needs rows x, y, z, ux, uy, uz; got shape "
                         f"{rows.shape}")
    return rows


def _interval(text):
    low, sep, high = text.partition(":")
    if not sep:
        raise ValueError(f"expected LOW:HIGH, got {text!r}")
    return float(low), float(high)


def _assignment(text, flag, parse):
    name, sep, value = text.partition("=")
    if not sep or name not in fitting.PARAMETERS:
        raise ValueError(f"{flag}: expected NAME=VALUE with NAME one of "
                         f"{', '.join(fitting.PARAMETERS)}, got {text!r}")
    try:
        return name, parse(value)
    except ValueError as err:
        raise ValueError(f"{flag}: {name}: {err}") from None


_COMMANDS = {"mesh": _mesh, "solve": _solve, "trade": _trade, "bench": _bench, "fit": _fit,
             "design": _design}


if __name__ == "__main__":
    sys.exit(main())
