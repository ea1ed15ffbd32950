"""The keys of a scene file (anisofem.io.scenefile), each with what it means, and the Markdown
tables of docs/scenes.md made from them."""
from ..physics.material import MODELS

#: The keys of a scene file, by table: key -> what it holds.
SCHEMA = {
    "scene": {
        "mesh": "the mesh file (Gmsh .msh, .vtu, ...), its path relative to the scene file",
        "order": "1 (the file's tets, default) or 2 (linear tets raised to quadratic ones)",
        "gravity": "[gx, gy, gz] m/s^2 (default: none)",
        "body_force": "[bx, by, bz] N/m^3 on every tet (default: none)",
        "material": "a [material] table: every tet's material",
        "regions": "[regions.NAME] tables, NAME a physical volume of the mesh file (its name, or "
                   "its number in quotes): [material] keys that change there",
        "boundary": "[[boundary]] tables, each a place (where) and what is done there",
        "controls": "[controls.NAME] tables: the scene's controls, named inputs a controller "
                    "sets every step",
        "curves": "[curves.NAME] tables: load curves that boundary entries and controls "
                  "follow in time",
        "contact": "a [contact] table: rigid obstacles the body's surface cannot pass "
                   "(default: none)",
    },
    "material": {
        "law": f"the base law: {' or '.join(MODELS)} (default stvk)",
        "young": "Young's modulus, Pa (default 1e5)",
        "poisson": "Poisson's ratio (default 0.48)",
        "density": "kg/m^3 (default 1000)",
        "fiber_stiffness": "kappa, Pa (default 0: no fiber term)",
        "activation": "the fibers' contraction a in [0, 1): their rest stretch is 1 - a "
                      "(default 0: passive fibers); only where fiber_stiffness > 0 (a "
                      "contraction that changes in time: [controls.NAME])",
        "fiber": "the fiber direction: [dx, dy, dz]; {cell_data = NAME}, a 3-vector field per "
                 "tet of the mesh file (normalized, with a warning where not unit length); or "
                 "{helix = {...}}, wound about an axis",
    },
    "helix": {
        "axis": "[ax, ay, az] the helix's axis",
        "origin": "[ox, oy, oz] m, a point on the axis (default 0)",
        "angle": "the winding angle from the axis, degrees (90: hoops around it)",
        "angle_end": "the angle at the region's far end along the axis (default: angle), linear "
                     "in between",
        "segments": "[a1, a2, ...] degrees: the winding angle in equal segments along the axis "
                    "over the region, from its start (instead of angle and angle_end; what "
                    "python -m anisofem design writes)",
        "crossed": "true: a crossed winding, +angle and -angle on alternate tets (the two "
                   "fiber families of a wound actuator; default false)",
    },
    "boundary": {
        "where": "a physical surface of the mesh file (its name, or its number), a side of the "
                 "mesh (x-min, x-max, y-min, y-max, z-min, z-max), or {box = [[x0, y0, z0], "
                 "[x1, y1, z1]]} (m)",
        "held": "true (every component of its vertices) or a list of axes, [\"x\", \"z\"]",
        "displacement": "[ux, uy, uz] m, the held components moved by it",
        "rotation": "{axis = [ax, ay, az], origin = [ox, oy, oz], angle = degrees}: the held "
                    "vertices turned about the axis",
        "traction": "[tx, ty, tz] Pa per rest area (a dead load)",
        "pressure": "Pa, pushing into the material (the walls of a cavity: a closed surface, or "
                    "one that ends on held vertices or on vertices sliding in a plane)",
        "curve": "the name of the load curve its loads and motion follow in time (statics take "
                 "them as written)",
    },
    "controls": {
        "pressure": "a place, as a [[boundary]]'s where: the walls of a cavity, pushed by the "
                    "control's value in Pa",
        "activation": "a region, as [regions.NAME]'s NAME: its fibers contract by the "
                      "control's value, in [0, 1) (the region needs fiber_stiffness > 0)",
        "cable": "[[x, y, z], ...] m: a cable through these rest points of the body, pulled "
                 "with the control's value in N (>= 0), sliding through them",
        "value": "the control's value (default 0), times its curve's factor where it has one",
        "curve": "the name of the load curve its value follows in time (statics take it at 1)",
        "range": "[low, high]: the values a reduced model of the scene is built to follow "
                 "(python -m export reduced fits its snapshots to them)",
    },
    "contact": {
        "obstacles": "[contact.obstacles.NAME] tables, at least one unless self_contact",
        "self_contact": "true: the surface's contact with itself and between the mesh's "
                        "bodies (needs ipctk; default false)",
        "distance": "m, the distance at which the barrier starts (default 1e-3 of the body's "
                    "size)",
        "friction": "Coulomb's coefficient, >= 0 (default 0), in time steps only",
        "stiffness": "the barrier's stiffness, N/m^3 (default E / distance)",
        "smoothing": "m/s, the sliding speed below which friction sticks (default 1e-3 of "
                     "the body's size per second)",
    },
    "obstacle": {
        "plane": "{point = [x, y, z], normal = [nx, ny, nz]}: the half-space on the normal's "
                 "side",
        "sphere": "{center = [x, y, z], radius = r} (m)",
        "box": "{center = [x, y, z], half = [hx, hy, hz]} (m), along the axes",
        "capsule": "{a = [x, y, z], b = [x, y, z], radius = r}: the points within r of the "
                   "segment ab",
        "surface": "{file = \"NAME.stl\"}: the triangles of a surface file (.stl, .obj, "
                   ".ply, .msh, ...; its path relative to the scene file), any shape, its "
                   "edges and corners exact (needs ipctk)",
        "friction": "this obstacle's coefficient, >= 0 (default: [contact]'s)",
        "move": "[dx, dy, dz] m: where it goes, times its curve's factor (with curve)",
        "curve": "the name of the load curve it moves along (with move); a step moves it as "
                 "far as the body lets it, solves, and again, up to 20 times",
    },
    "rotation": {
        "axis": "[ax, ay, az]",
        "origin": "[ox, oy, oz] m (default 0)",
        "angle": "degrees",
    },
    "curves": {
        "times": "[t0, t1, ...] s, increasing",
        "values": "[f0, f1, ...] the factor of the loads at each time (linear in between, "
                  "constant outside)",
    },
}


def schema_markdown():
    """SCHEMA as the Markdown tables of docs/scenes.md."""
    titles = {"scene": "Top level", "material": "[material] and [regions.NAME]",
              "helix": "fiber = {helix = {...}}", "boundary": "[[boundary]]",
              "controls": "[controls.NAME]", "contact": "[contact]",
              "obstacle": "[contact.obstacles.NAME]",
              "rotation": "rotation = {...} of a [[boundary]]", "curves": "[curves.NAME]"}
    lines = []
    for kind, keys in SCHEMA.items():
        lines += [f"### {titles[kind]}", "", "| key | meaning |", "|---|---|"]
        lines += [f"| `{k}` | {v} |" for k, v in keys.items()]
        lines.append("")
    return "\n".join(lines)
