"""The forward commands: `mesh`, `solve`, `trade` and `bench`."""

import numpy as np

from ..io.meshes import check_output_path, read_mesh, write_mesh, write_series
from ..io.output import check_folder, write_json
from ..io.scenefile import load_scene
from ..physics.inversion import inversion
from ..physics.metrics import tip_displacement
from ..solvers import methods
from ..solvers.solve import simulate, solve
from ..studies import (
    bench,
    bench_large,
    bench_load,
    convergence,
    robustness,
    trade_report,
)
from ..studies import rungs as ladder_rungs
from ..studies.trade import trade
from .arguments import (
    BODIES,
    SHAPES,
    body_of,
    is_scene_file,
    no_shape_flags,
    of_order,
    scene_from_file,
    scene_from_flags,
    scene_of,
    shape_of,
)


def mesh_command(args):
    check_output_path(args.output)
    if is_scene_file(args.shape):
        no_shape_flags(args)
        if args.order is not None:
            raise ValueError(f"--order: the scene file {args.shape} sets it")
        scene = load_scene(args.shape)
        write_mesh(args.output, scene.mesh, scene=scene)
        print(f"{scene.mesh} with its fiber field -> {args.output}")
        return 0
    if args.shape not in SHAPES:
        raise ValueError(f"shape: expected one of {', '.join(sorted(SHAPES))} or a scene file "
                         f"(.toml), got {args.shape!r}")
    mesh = of_order(shape_of(args, args.shape), args.order)
    write_mesh(args.output, mesh)
    print(f"{mesh} -> {args.output}")
    return 0


def solve_command(args):
    series = args.output.lower().endswith(".pvd")
    if series:
        check_folder(args.output, "--output")
    else:
        check_output_path(args.output)
    if args.ramp < 0 or (args.ramp and args.steps):
        raise ValueError(f"--ramp: a number of static increments >= 1, without --steps; got "
                         f"{args.ramp}")
    if is_scene_file(args.mesh):
        scene = scene_from_file(args, args.mesh, "x-min")
    else:
        scene = scene_from_flags(args, of_order(read_mesh(args.mesh), args.order))
    mesh = scene.mesh
    if args.engine == "petsc":
        from ..distributed import command
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
    if not ok and states is None:
        print(f"nothing written to {args.output}: the static solve did not converge, and its "
              f"last iterate is no answer")
        return 1
    if series:
        if states is None:
            states, times = [scene.initial_positions(), x], [0.0, 1.0]
        write_series(args.output, mesh, states, times, scene)
    else:
        write_mesh(args.output, mesh, x, scene)
    print(f"-> {args.output}{'' if ok else ' (the states up to where it failed)'}")
    return 0 if ok else 1


def trade_command(args):
    """python -m anisofem trade: print the table, write the JSON and the plot."""
    for path, name in ((args.json, "--json"), (args.png, "--png")):
        if path:
            check_folder(path, name)
    scene = scene_of(args)
    rungs, notes = ladder_rungs.fem_rungs(), []
    if not args.no_surrogates:
        rungs += ladder_rungs.registered_rungs(scene, args.dt, notes)
    if args.rungs:
        rungs = ladder_rungs.select_rungs(rungs, args.rungs)
    bodies = [(BODIES[b][0], body_of(args, scene, b, "--bodies")) for b in args.bodies]
    result = trade(scene, args.steps, args.dt, tolerance=args.tolerance, rungs=rungs,
                          name=args.scene, bodies=bodies)
    result["notes"][:0] = notes
    print(trade_report.trade_table(result))
    if args.json:
        write_json(args.json, result)
        print(f"-> {args.json}")
    if args.png:
        trade_report.plot(result, args.png)
        print(f"-> {args.png}")
    return 0


def bench_command(args):
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
        from ..distributed import MISSING, available
        from ..studies import bench_distributed as distributed_bench
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
