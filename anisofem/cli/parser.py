"""Command line: `python -m anisofem {mesh,solve,trade,fit,design,control,bench}`.

  python -m anisofem mesh box --cells 10 2 2 -o beam.msh
  python -m anisofem solve beam.msh --fixed x-min --gravity 0 0 -9.81 --fiber 1 0 0 \\
      --kappa 1e5 --material neohookean -o beam.vtu
  python -m anisofem trade beam.msh --fiber 0.766 0 0.643 --kappa 1e5 --steps 100 \\
      --json trade.json --png trade.png
  python -m anisofem bench                  # writes results/bench_anisofem.json
  python -m anisofem bench --large --huge
"""
import argparse

from ..inverse import fit as fitting
from ..solvers import methods
from ..solvers.solve import CONTINUATION
from ..studies import (
    bench,
    convergence,
)
from .arguments import (
    BODIES,
    SHAPES,
    Parser,
    ShowDefaults,
    add_scene_arguments,
    order_argument,
    scene_arguments,
    shape_arguments,
)


def build_parser():
    p = Parser(prog="python -m anisofem", description=__doc__,
               formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="command", required=True)
    defaults = {"formatter_class": ShowDefaults}
    m = sub.add_parser("mesh", help="generate a mesh of one of the paper's shapes, or write a "
                                    "scene file's mesh with its fibers and materials",
                       **defaults)
    m.add_argument("shape", help=f"a shape ({', '.join(sorted(SHAPES))}) or a scene file "
                                 f"(.toml)")
    shape_arguments(m)
    m.add_argument("-o", "--output", required=True)
    s = sub.add_parser("solve", help="static equilibrium or a backward-Euler rollout", **defaults)
    s.add_argument("mesh", help="a scene file (.toml, docs/scenes.md) or a mesh file meshio "
                                "reads (.msh, .vtu, .xdmf, ...)")
    s.add_argument("-o", "--output", required=True,
                   help="result file (.vtu, .xdmf, .msh), or a ParaView series (.pvd) of every "
                        "step or ramp increment")
    scene_arguments(s)
    order_argument(s)
    s.add_argument("--steps", type=int, default=0,
                   help="backward-Euler steps instead of statics (writes the last state)")
    s.add_argument("--dt", type=float, default=0.02, help="s")
    s.add_argument("--method", default="auto", choices=["auto", *methods.METHODS],
                   help="how each solve is done (see anisofem.solvers.methods; auto: exact Newton, "
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
    c = sub.add_parser("control", help="controls in time (a scene file's [controls], within "
                                       "their ranges) that make a point of the body follow a "
                                       "path, found in its reduced model", **defaults)
    c.add_argument("scene", help="a scene file (.toml) whose controls give their range")
    c.add_argument("--effector", required=True,
                   help="what follows the path: a physical surface, a side (x-max, ...) or a "
                        "box whose vertices' mean moves")
    c.add_argument("--path", required=True, metavar="CSV",
                   help="rows t, x, y, z: where the effector should be at each time (s, m; "
                        "linear in between; a header line is skipped)")
    c.add_argument("--dt", type=float, default=0.02, help="time step, s")
    c.add_argument("--knot", type=float, default=0.1,
                   help="time between the control curves' points, s")
    c.add_argument("--modes", type=int, default=6, help="the reduced model's vibration modes")
    c.add_argument("--snapshots", type=int, default=24,
                   help="its directions fitted to static equilibria over the controls' ranges")
    c.add_argument("--smooth", type=float, default=1e-4,
                   help="weight of the squared jumps between a control's points, over its "
                        "range")
    c.add_argument("--max-iter", type=int, default=200, help="L-BFGS-B iterations at most")
    c.add_argument("-o", "--output", help="write the scene file with the controls on curves "
                                          "here (.toml)")
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
                        "out/robustness.json, with --convergence results/convergence.json, "
                        "with --distributed results/bench_distributed.json, with --under-load "
                        "results/bench_under_load.json)")
    return p
