"""The command line's shared arguments: the shapes `mesh` makes, the scene flags (material,
fibers, loads, held end) and how a scene file or a mesh with them becomes a Scene, the body
(a finer mesh of the scene's body) of `--bodies`, and the parser classes."""
import argparse
import re

import numpy as np

from ..io.meshes import read_mesh
from ..io.scenefile import load_scene
from ..physics import meshgen
from ..physics.material import MODELS, Material
from ..physics.metrics import end_vertices
from ..physics.scene import Scene

#: Each shape: (its mesh from the shape flags, the flags it takes with their defaults, the end
#: it stands on: the --fixed default)
SHAPES = {
    "box": (lambda a: meshgen.box_beam(a.size, a.cells, tets_per_cell=a.tets_per_cell),
            {"size": (0.1, 0.02, 0.02), "cells": (10, 2, 2), "tets_per_cell": 5}, "x-min"),
    "cylinder": (lambda a: meshgen.cylinder_beam(a.size[0], a.size[1] / 2, a.cells[0],
                                                 a.cells[1], a.rings),
                 {"size": (0.1, 0.02), "cells": (10, 2), "rings": 1}, "x-min"),
    "t": (lambda a: meshgen.t_shape(), {}, "z-min"),
    "y": (lambda a: meshgen.y_shape(), {}, "z-min")}
#: The shapes' flags
SHAPE_FLAGS = ("size", "cells", "rings", "tets_per_cell")


#: the finer meshes of the same body the trade can measure against (--bodies): name ->
#: (row label, the finer mesh of a linear mesh)
BODIES = {"quadratic": ("exact, quadratic tets", lambda m: m.raised()),
           "refined": ("exact, refined mesh", lambda m: m.refined()),
           "refined-quadratic": ("exact, refined quadratic", lambda m: m.refined().raised())}


def order_argument(p):
    p.add_argument("--order", type=int, choices=(1, 2), default=None,
                   help="1: linear tets; 2: quadratic (10-node) tets, a linear mesh raised by "
                        "its edge midpoints (default: a file's own order, linear for a shape)")


def of_order(mesh, order):
    """mesh at the --order asked (None: as it is); a quadratic file cannot be lowered."""
    if order is None or order == mesh.order:
        return mesh
    if order == 1:
        raise ValueError("--order 1: the mesh has quadratic tets; a quadratic mesh is not "
                         "lowered (read it as it is, or mesh it again)")
    return mesh.raised()


def fixed_vertices(mesh, spec, flag="--fixed"):
    """'x-min', 'y-max', ...: the vertices on that end of the mesh (ValueError naming `flag`
    where spec is not one)."""
    try:
        axis, side = spec.split("-")
        return end_vertices(mesh, "xyz".index(axis), side)
    except ValueError:
        raise ValueError(f"{flag}: expected AXIS-SIDE like x-min or z-max, got {spec!r}") \
            from None


def shape_arguments(p):
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
    order_argument(p)


def shape_of(args, name):
    """The mesh of the shape called name that the shape flags describe; a flag the shape does
    not take, or with the wrong number of values, is a ValueError."""
    build, takes, _ = SHAPES[name]
    for flag in SHAPE_FLAGS:
        given, option = getattr(args, flag), "--" + flag.replace("_", "-")
        if given is None:
            setattr(args, flag, takes.get(flag))
        elif flag not in takes:
            raise ValueError(
                f"{option}: the {name} shape does not take it; it takes "
                + (", ".join("--" + f.replace("_", "-") for f in takes) if takes else
                   f"no shape flag (anisofem.{name}shape_of in Python takes its dimensions)"))
        elif isinstance(takes[flag], tuple) and len(given) != len(takes[flag]):
            raise ValueError(f"{option}: expected {len(takes[flag])} values for the {name} "
                             f"shape, got {len(given)}")
    return build(args)


def no_shape_flags(args):
    """ValueError naming a shape flag given with a mesh file (whose mesh is as it is)."""
    for flag in SHAPE_FLAGS:
        if getattr(args, flag, None) is not None:
            raise ValueError(f"--{flag.replace('_', '-')}: a shape flag; the mesh of a file is "
                             f"read as it is")


#: The scene flags besides --fixed and their defaults (a scene file sets them all itself)
SCENE_FLAGS = {"gravity": (0.0, 0.0, -9.81), "young": 1e5, "poisson": 0.48, "density": 1000.0,
               "fiber": (1.0, 0.0, 0.0), "kappa": 0.0, "material": "stvk"}


def scene_arguments(s, fixed="x-min"):
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
    """Whether a command's positional names a TOML scene file (anisofem.io.scenefile)."""
    return str(name).lower().endswith(".toml")


def scene_from_file(args, name, fixed_default):
    """The Scene of the scene file `name`; ValueError naming a flag given with it that the
    file sets itself (shape, order, --fixed and the scene flags away from their defaults)."""
    no_shape_flags(args)
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


def scene_from_flags(args, mesh):
    fiber = np.asarray(args.fiber)
    if not np.isfinite(fiber).all():
        raise ValueError(f"--fiber: must be finite, got {args.fiber}")
    if not np.linalg.norm(fiber) > 0:
        raise ValueError(f"--fiber: a direction needs a nonzero vector, got {args.fiber}")
    material = Material(args.young, args.poisson, args.density, fiber / np.linalg.norm(fiber),
                        args.kappa, model=args.material)
    return Scene(mesh, material, fixed=fixed_vertices(mesh, args.fixed), gravity=args.gravity)


def body_of(args, scene, body, flag):
    """The Scene of scene's body on the finer mesh `body` (a key of BODIES), with the same
    flags; ValueError naming `flag` where the scene's tets are quadratic already or it comes
    from a scene file."""
    if is_scene_file(args.scene):
        raise ValueError(f"{flag}: takes a mesh file or a shape; a scene file's regions and "
                         f"surfaces are named on its own mesh")
    if scene.mesh.order != 1:
        raise ValueError(f"{flag}: the scene has quadratic tets already; give its linear mesh")
    return scene_from_flags(args, BODIES[body][1](scene.mesh))


def add_scene_arguments(p):
    """The positional scene (a mesh file or a shape) and the flags that make a Scene of it
    (trade here, `python -m export reduced`)."""
    p.add_argument("scene", help="a scene file (.toml, docs/scenes.md), a mesh file meshio "
                                 f"reads, or a shape: {', '.join(sorted(SHAPES))}")
    shape_arguments(p)
    scene_arguments(p, fixed=None)


def scene_of(args):
    """The Scene that the flags of add_scene_arguments describe (args.fixed set to the end
    held where it was not given)."""
    if is_scene_file(args.scene):
        return scene_from_file(args, args.scene, None)
    if args.scene in SHAPES:
        mesh = shape_of(args, args.scene)
        args.fixed = args.fixed or SHAPES[args.scene][2]
    else:
        no_shape_flags(args)
        mesh = read_mesh(args.scene)
        args.fixed = args.fixed or "x-min"
    return scene_from_flags(args, of_order(mesh, args.order))


class Parser(argparse.ArgumentParser):
    """argparse's parser that reads negative numbers in exponent form (--young -1e5) as values,
    as it reads -100000 and -0.5 (its own pattern misses the exponent)."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = re.compile(r"^-(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?$")


class ShowDefaults(argparse.ArgumentDefaultsHelpFormatter):
    """Help that names each option's default, where it has one."""

    def _get_help_string(self, action):
        if action.default is None or action.default is False:
            return action.help
        return super()._get_help_string(action)
