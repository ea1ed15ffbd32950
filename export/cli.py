"""`python -m export MODEL -o model.onnx` (MODEL: a model.pt / checkpoint.pt file or a shipped
name), `python -m export bench` (onnxruntime vs torch per step), `python -m export bake
SCENE -o PATH` (a scene's constant tensors for an engine), `python -m export reduced SCENE
-o PATH` (a scene's reduced model for runtime.ReducedSimulator; no torch needed) and
`python -m export bench-reduced` (its build, size and step times) and `python -m export mujoco
FILE` (the MJCF that places a model file on a MuJoCo body, export/mujoco.py)."""
import argparse
import sys
import time

from anisofem.cli import BAD_INPUT, Parser
from anisofem.cli.arguments import ShowDefaults
from anisofem.io.output import check_folder, result_path

from .writers import bake
from . import model_path

#: The subcommands, each with what it does (python -m export --help lists them)
COMMANDS = {"bench": "onnxruntime against torch per step (table + JSON)",
            "bake": "a scene's constant model inputs for an engine (PATH.json + PATH.bin)",
            "reduced": "a scene's reduced model for runtime.ReducedSimulator (no torch needed)",
            "bake-reduced": "the browser page's reduced models of a baked scene",
            "bench-reduced": "the reduced model's build, size and step times",
            "mujoco": "the MJCF that places a model file on a MuJoCo body (the plugin)"}

def fail(parser, err):
    """End the command with one line naming the problem and exit status 2 (as `python -m
    anisofem` does)."""
    parser.exit(2, f"{parser.prog}: error: {err}\n")


def main(argv=None):
    """Run a command; bad input ends it with a one-line error and exit status 2."""
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv[:1] == ["bench"]:
        from .benches import onnx as bench
        parser = Parser(prog="python -m export bench",
                        description="onnxruntime vs torch per step")
        parser.add_argument("--json", default=result_path("bench_export.json"),
                            help="where to write the JSON (default %(default)s)")
        parser.add_argument("--sizes", nargs="+", default=list(bench.MESHES),
                            choices=list(bench.MESHES), help="mesh sizes (default: all)")
        args = parser.parse_args(argv[1:])
        bench.run(sizes=args.sizes, out=args.json)
        return
    if argv[:1] == ["bake"]:
        parser = Parser(
            prog="python -m export bake", description="write a scene's constant model inputs "
            "as PATH.json + PATH.bin (export/README.md, Baked scenes)")
        parser.add_argument("scene", choices=sorted(bake.SCENES))
        parser.add_argument("-o", "--output", required=True, help="PATH (without extension)")
        parser.add_argument("--model", default=model_path("directional"),
                            help="the .onnx file the scene is for (default %(default)s)")
        parser.add_argument("--angles", type=float, nargs="+", default=list(bake.ANGLES),
                            help="fiber angles in degrees from x towards z (default %(default)s)")
        args = parser.parse_args(argv[1:])
        try:
            check_folder(args.output, "--output")
            header = bake.bake(args.scene, args.output, args.model, args.angles)
        except BAD_INPUT as err:
            fail(parser, err)
        print(f"wrote {args.output}.json and .bin: {header['title']}, {header['n']} vertices, "
              f"{header['m']} tets, fiber angles {header['fiber_angles']}")
        return
    if argv[:1] == ["reduced"]:
        return _reduced(argv[1:])
    if argv[:1] == ["bake-reduced"]:
        return _bake_reduced(argv[1:])
    if argv[:1] == ["bench-reduced"]:
        return _bench_reduced(argv[1:])
    if argv[:1] == ["mujoco"]:
        return _mujoco(argv[1:])
    from anisognn import shipped
    from anisognn.cli import add_galerkin_arguments, stepping

    from .writers import to_onnx
    parser = Parser(
        prog="python -m export", usage="python -m export {MODEL,%s} ..." % ",".join(COMMANDS),
        description="export a trained anisognn model to ONNX: python -m export MODEL -o "
        "model.onnx; the other commands (python -m export COMMAND --help for each):\n"
        + "\n".join(f"  {name:<14} {what}" for name, what in COMMANDS.items()),
        formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("model", metavar="MODEL",
                        help=f"a model.pt / checkpoint.pt file or a shipped name {shipped.NAMES}")
    parser.add_argument("-o", "--output", default="model.onnx", help="the .onnx file to write")
    add_galerkin_arguments(parser)
    args = parser.parse_args(argv)
    try:
        check_folder(args.output, "--output")
        net = stepping(shipped.model(args.model), args)
    except BAD_INPUT as err:
        fail(parser, err)
    print(f"exporting {args.model} to {args.output} (tracing and checking take about a "
          f"minute)", file=sys.stderr, flush=True)
    to_onnx.export(net, args.output)
    c = net.config
    print(f"wrote {args.output}: {c.aggregation} aggregation, {c.latent} wide, {c.steps} steps, "
          f"{c.stepping}, dt = {c.dt} s")


def _reduced(argv):
    """python -m export reduced: build a scene's reduced model and write its arrays files."""
    from anisofem import read_mesh
    from anisofem.cli import BODIES, add_scene_arguments, body_of, scene_of
    from anisofem.reduced import MODES, ReducedModel

    from .writers import reduced
    parser = Parser(
        prog="python -m export reduced", description="build a scene's reduced model "
        "(anisofem.reduced) and write it as PATH.json + PATH.bin for runtime.ReducedSimulator",
        formatter_class=ShowDefaults)
    add_scene_arguments(parser)
    parser.add_argument("--modes", type=int, default=MODES,
                        help="vibration modes; without --snapshots the basis adds their modal "
                             "derivatives")
    parser.add_argument("--snapshots", type=int, default=0,
                        help="add this many directions fitted to the full FEM's static "
                             "equilibria under a drag of up to half the body's weight at each "
                             "free end (follows large bending; 0: modes and modal derivatives)")
    parser.add_argument("--body", choices=list(BODIES),
                        help="build the model on this finer mesh of the same body (quadratic "
                             "tets, the mesh refined once, both) and write it for the scene's "
                             "mesh: the body's accuracy at the scene mesh's cost")
    parser.add_argument("--display", metavar="MESH",
                        help="a coarser mesh file of the same body: the file moves its vertices "
                             "(interpolated in the model's elements) instead of the model's")
    parser.add_argument("--framed", action="store_true",
                        help="the framed model instead (anisofem.reduced.FramedModel: domains "
                             "in their own rotating frames, for bodies that bend and swing "
                             "far), for framed_runtime.FramedSimulator")
    parser.add_argument("--drag", nargs="+", action="append", default=[], metavar="WHERE N",
                        help="a drag the model must handle (repeatable): up to N newtons on "
                             "the vertices at WHERE (AXIS-SIDE like x-max, or a surface of a "
                             "scene file), in any direction, or along DX DY DZ given after N; "
                             "declared drags replace the default, half the body's weight at "
                             "each free end")
    parser.add_argument("--cone", type=float, default=0.0,
                        help="degrees by which the scene's gravity may turn (a body carried "
                             "around)")
    parser.add_argument("--carry", nargs=3, type=float, metavar=("TURN", "MOVE", "SECONDS"),
                        help="with --framed: the held vertices carried, turned by up to TURN "
                             "degrees and moved by up to MOVE m, each motion taking at least "
                             "SECONDS s")
    parser.add_argument("-o", "--output", required=True, help="PATH (without extension)")
    args = parser.parse_args(argv)
    try:
        check_folder(args.output, "--output")
        if args.body and args.display:
            raise ValueError("--body, --display: give one (--body draws on the scene's mesh)")
        fixed = args.fixed
        scene = scene_of(args)
        loads = _declared_loads(args, scene)
        shown = None if args.display is None else read_mesh(args.display)
        progress = _progress(_what_is_built(args, scene, fixed, loads))
        if args.framed:
            return _framed(args, scene, shown, loads, progress)
        if args.carry:
            raise ValueError("--carry: the framed model's held vertices move; add --framed")
        display = scene.mesh if args.body else shown
        built = body_of(args, scene, args.body, "--body") if args.body else scene
        if args.body and loads is not None:
            raise ValueError("--body: builds from the default declared loads; --drag and "
                             "--cone name the scene mesh's vertices")
        model = ReducedModel(built, modes=args.modes, snapshots=args.snapshots, loads=loads,
                             progress=progress)
        header = reduced.write(model, args.output, title=args.scene, gravity=scene.gravity,
                               display=display)
    except BAD_INPUT as err:
        fail(parser, err)
    fitted = f" + {model.fitted} fitted" if model.fitted else ""
    print(f"wrote {args.output}.json and .bin: {header['n']} vertices, {header['m']} tets, "
          f"r = {header['r']} ({header['modes']} modes{fitted}), built in "
          f"{model.build_seconds:.2g} s{_checked(model.validation)}")
    if model.validation is not None and model.validation.tip_error > BASIS_WARNING:
        print(f"warning: {100 * model.validation.tip_error:.2g}% off the full FEM: this body "
              f"moves more than its linear basis holds; more --snapshots, or --framed (its "
              f"parts in their own rotating frames) for a body that bends or swings far",
              file=sys.stderr)


def _declared_loads(args, scene):
    """The Loads of --drag, --cone and --carry and of the scene file's control ranges (with
    the default drags where none is given), or None where none is given."""
    from anisofem.cli.arguments import fixed_vertices, is_scene_file
    from anisofem.io.scenefile import SceneFile
    from anisofem.reduced import Carry, Drag, Loads, default_loads
    places = SceneFile(args.scene) if is_scene_file(args.scene) else None
    ranges = places.control_ranges if places else {}
    if not (args.drag or args.cone or args.carry or ranges):
        return None
    drags = []
    for entry in args.drag:
        if len(entry) not in (2, 5):
            raise ValueError(f"--drag: WHERE N or WHERE N DX DY DZ, got {' '.join(entry)!r}")
        where, numbers = entry[0], entry[1:]
        try:
            magnitude, *direction = (float(x) for x in numbers)
        except ValueError:
            raise ValueError(f"--drag {where}: N and DX DY DZ are numbers, got "
                             f"{' '.join(numbers)!r}") from None
        vertices = (places.vertices(where) if places else
                    fixed_vertices(scene.mesh, where, "--drag"))
        drags.append(Drag(vertices, magnitude, (direction,) if direction else None))
    if not args.drag and ranges:
        drags = default_loads(scene).drags
    carry = Carry(*args.carry) if args.carry else None
    loads = Loads(drags=tuple(drags), cone=args.cone, carry=carry, controls=ranges)
    loads.check(scene)
    return loads


def _progress(headline):
    """progress(stage) for a model's build: the headline on stderr at the first stage, then
    each stage with the seconds since (a build of a few thousand tets takes a minute)."""
    start = []

    def progress(stage):
        if not start:
            start.append(time.perf_counter())
            print(headline, file=sys.stderr, flush=True)
        print(f"  [{time.perf_counter() - start[0]:5.1f} s] {stage}", file=sys.stderr,
              flush=True)
    return progress


def _what_is_built(args, scene, fixed, loads):
    """The line said before the build: the mesh, the vertices it holds and why those, what it
    builds and from which loads."""
    from anisofem.cli.arguments import SHAPES, is_scene_file
    held = int(scene.fixed_mask.any(axis=1).sum())
    if is_scene_file(args.scene):
        where = "as the scene file says"
    elif fixed:
        where = f"at {args.fixed} (--fixed)"
    else:
        kind = "the shape's" if args.scene in SHAPES else "a mesh file's"
        where = f"at {args.fixed} ({kind} default; --fixed holds another end)"
    what = ("its framed model" if args.framed else
            f"{args.modes} modes + {args.snapshots} directions fitted to static equilibria"
            if args.snapshots else f"{args.modes} modes and their modal derivatives")
    declared = (f"the declared loads ({len(loads.drags)} drags, a {loads.cone:g} degree "
                f"cone{', a carry' if loads.carry else ''}"
                f"{f', {len(loads.controls)} control ranges' if loads.controls else ''})"
                if loads else
                "the default loads (half the body's weight at each free end)")
    fitted = args.framed or args.snapshots
    return (f"{args.scene}: {scene.mesh.n_tets} tets, holding {held} vertices {where}; "
            f"building {what}{' from ' + declared if fitted else ''}:")


def _framed(args, scene, display, loads, progress):
    """python -m export reduced --framed: the FramedModel of the scene, written (for the
    vertices of the TetMesh display, where given)."""
    from anisofem.reduced import FramedModel

    from .writers import reduced
    if args.body or args.snapshots:
        raise ValueError("--framed: builds on the scene's own mesh from its declared loads; "
                         "--body and --snapshots are the linear model's")
    model = FramedModel(scene, modes=args.modes, loads=loads, progress=progress)
    header = reduced.write_framed(model, args.output, title=args.scene, gravity=scene.gravity,
                                  display=display)
    print(f"wrote {args.output}.json and .bin: {header['n']} vertices, {header['m']} tets, "
          f"{header['domains']} domains, {header['unknowns']} unknowns, "
          f"{header['joint_elements']} joint elements{_cubature(header)}, built in "
          f"{model.build_seconds:.2g} s{_checked(model.validation)}")


def _cubature(header):
    """Where a framed file's joints are a cubature, the clause that says of how many."""
    layer = header["joint_layer"]
    return "" if layer == header["joint_elements"] else f" (a cubature of its {layer})"


#: export reduced warns where the model's validation misses the full FEM's tip by more.
BASIS_WARNING = 0.05


def _checked(v):
    """How far a model's Validation (or None) found it from the full FEM, as a clause."""
    if v is None:
        return ""
    if v.inverted and not v.cases:
        return (f"; not validated: the full FEM turned elements inside out in all {v.inverted} "
                f"drawn cases")
    where = f"on {v.cases} unseen loads" if v.cases else "in the static answer"
    return (f"; tip {100 * v.tip_error:.2g}% and field {100 * v.field_error:.2g}% off the "
            f"full FEM {where}")


def _bench_reduced(argv):
    """python -m export bench-reduced: the reduced model's build, size and step times."""
    from .benches import reduced as bench_reduced
    parser = Parser(
        prog="python -m export bench-reduced", description=bench_reduced.__doc__.split("\n")[0],
        formatter_class=ShowDefaults)
    parser.add_argument("--sizes", nargs="+", default=list(bench_reduced.MESHES),
                        choices=list(bench_reduced.MESHES), help="meshes, by tets")
    parser.add_argument("--modes", type=int, nargs="+", default=list(bench_reduced.MODES),
                        help="vibration modes of each model")
    parser.add_argument("--snapshots", type=int, default=0,
                        help="directions fitted to the default declared loads, added to each "
                             "model's modes (0: modes and modal derivatives)")
    parser.add_argument("--framed", action="store_true",
                        help="also the framed model (anisofem.reduced.FramedModel) of each mesh")
    parser.add_argument("--json", default=result_path("bench_reduced.json"),
                        help="where to write the JSON")
    args = parser.parse_args(argv)
    bench_reduced.run(args.sizes, args.modes, args.json, args.snapshots, args.framed)


def _bake_reduced(argv):
    """python -m export bake-reduced: a baked scene's reduced models, one per fiber angle."""
    from anisofem.reduced import MODES

    from .writers import reduced
    parser = Parser(
        prog="python -m export bake-reduced", description="write the reduced models of a "
        "baked scene at several fiber angles as PATH.json + PATH.bin (the browser page's)",
        formatter_class=ShowDefaults)
    parser.add_argument("scene", choices=sorted(bake.SCENES))
    parser.add_argument("-o", "--output", required=True, help="PATH (without extension)")
    parser.add_argument("--modes", type=int, default=MODES, help="vibration modes")
    parser.add_argument("--snapshots", type=int, default=0,
                        help="directions fitted to the scene's default declared loads (0: "
                             "modes and modal derivatives)")
    parser.add_argument("--angles", type=float, nargs="+", default=list(bake.ANGLES),
                        help="fiber angles in degrees from x towards z")
    parser.add_argument("--framed", action="store_true",
                        help="the framed models instead (anisofem.reduced.FramedModel), for "
                             "bodies that bend and swing far")
    args = parser.parse_args(argv)
    try:
        check_folder(args.output, "--output")
        if args.framed:
            if args.snapshots:
                raise ValueError("--framed: builds from the scene's default declared loads; "
                                 "--snapshots is the linear model's")
            header = reduced.bake_framed(args.scene, args.output, args.angles)
        else:
            header = reduced.bake(args.scene, args.output, args.modes, args.angles,
                                  args.snapshots)
    except BAD_INPUT as err:
        fail(parser, err)
    worst = max(v["tip_error"] for v in header["validation"])
    where = (f"on {header['validation'][0]['cases']} unseen loads"
             if args.snapshots or args.framed else "in the static answer")
    kind = f"{header['domains']} framed domains, " if args.framed else ""
    print(f"wrote {args.output}.json and .bin: {header['title']}, {kind}r = {header['r'][0]}, "
          f"fiber "
          f"angles {header['fiber_angles']}; tip within {100 * worst:.2g}% of the full FEM "
          f"{where} at every angle")


def _mujoco(argv):
    """Print the MJCF of a model file on a MuJoCo body, checked by compiling it with the
    plugin (built on first use)."""
    from . import mujoco as plugin
    parser = Parser(prog="python -m export mujoco", description="print the MJCF that places "
                    "a model file (python -m export reduced) on a MuJoCo body, checked by "
                    "MuJoCo's compiler with the anisofem.soft plugin")
    parser.add_argument("file", help="the model file's path, without extension")
    parser.add_argument("--body", default="soft", help="the carrying body's name "
                        "(default %(default)s)")
    parser.add_argument("--substeps", type=int, default=1,
                        help="each soft step divided in this many (default %(default)s)")
    parser.add_argument("--timestep", type=float, default=None,
                        help="the soft time step, s (default: MuJoCo's)")
    args = parser.parse_args(argv)
    try:
        text = plugin.mjcf(args.file, body=args.body, substeps=args.substeps,
                           timestep=args.timestep)
        plugin.load_plugin()
        plugin.mujoco_module().MjModel.from_xml_string(text)
    except (RuntimeError,) + BAD_INPUT as err:
        fail(parser, err)
    print(text, end="")
