"""Mesh generators for the paper's shapes: box and cylinder beams, a T and a Y.

Every generator builds hexahedra and splits each into 5 tets around a central tet. The
vertices of a hex mesh whose edge graph is bipartite get a global 2-coloring; each hex's
central tet joins its four color-0 corners, so neighboring hexes split their shared face along
the same diagonal and the split alternates (mirrors) from cell to cell. Unlike the 6-tet split
with all diagonals one way, this keeps the symmetry of the cell grid: a beam with an even
number of cells across a mid-plane is mirror-symmetric about it, so a symmetric load gives a
symmetric answer. The box beam can also split each cell into 6 tets around a body diagonal
(`tets_per_cell=6`), the diagonals mirrored from cell to cell in the same way (each runs from the
cell's corner with even grid indices to the opposite one): for quadratic tets it is the more
accurate split of the two (docs/fem.md). Lengths are in m; beams run along +x from x = 0.
"""
import itertools

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import breadth_first_order

from .mesh import TetMesh

# hex corner numbering: 0-3 bottom face (cyclic), 4-7 top face, 4 above 0
_HEX_EDGES = np.array([[0, 1], [1, 2], [2, 3], [3, 0], [4, 5], [5, 6], [6, 7], [7, 4],
                       [0, 4], [1, 5], [2, 6], [3, 7]])
_NEIGHBORS = np.array([[1, 3, 4], [0, 2, 5], [1, 3, 6], [2, 0, 7],
                       [5, 7, 0], [4, 6, 1], [5, 7, 2], [6, 4, 3]])
_CLASS = (np.array([0, 2, 5, 7]), np.array([1, 3, 4, 6]))


def hexes_to_tets(points, hexes):
    """Split hexahedra (k, 8) into 5 tets each (central tet on color-0 corners); a TetMesh.

    Raises ValueError if the hex edge graph is not bipartite (no conforming 5-tet split).
    """
    points = np.asarray(points, dtype=float)
    hexes = np.asarray(hexes, dtype=np.int64)
    label = _two_color(points.shape[0], hexes[:, _HEX_EDGES].reshape(-1, 2))
    central_first = label[hexes[:, 0]] == 0
    tets = np.empty((hexes.shape[0], 5, 4), np.int64)
    for flag, (central, corners) in ((True, _CLASS), (False, _CLASS[::-1])):
        sel = central_first == flag
        h = hexes[sel]
        tets[sel, 0] = h[:, central]
        for k, c in enumerate(corners):
            tets[sel, k + 1, 0] = h[:, c]
            tets[sel, k + 1, 1:] = h[:, _NEIGHBORS[c]]
    return TetMesh(points, tets.reshape(-1, 4), fix_orientation=True)


def _two_color(n, edges):
    """0/1 label per vertex with every edge joining different labels."""
    graph = coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(n, n))
    graph = (graph + graph.T).tocsr()
    label = -np.ones(n, np.int64)
    for start in range(n):
        if label[start] >= 0:
            continue
        order, pred = breadth_first_order(graph, start, directed=False)
        label[start] = 0
        for v in order[1:]:
            label[v] = 1 - label[pred[v]]
    if (label[edges[:, 0]] == label[edges[:, 1]]).any():
        raise ValueError("hexes: the hex edge graph is not bipartite; no conforming 5-tet split")
    return label


def _extrude(section, quads, heights, axis):
    """Hexes from a quad mesh section (p, 2) swept through the given heights along axis.

    The section's two coordinates fill the other two axes in increasing order.
    """
    p = section.shape[0]
    layers = len(heights)
    other = [a for a in range(3) if a != axis]
    pts = np.empty((layers * p, 3))
    pts[:, axis] = np.repeat(heights, p)
    pts[:, other[0]] = np.tile(section[:, 0], layers)
    pts[:, other[1]] = np.tile(section[:, 1], layers)
    offsets = np.arange(layers - 1)[:, None, None] * p
    hexes = np.concatenate([quads[None] + offsets, quads[None] + offsets + p], axis=2)
    return pts, hexes.reshape(-1, 8)


def _grid_quads(nu, nv, keep=None):
    """Quads of a (nu x nv)-cell grid with vertex (i, j) at index i (nv + 1) + j."""
    i, j = np.meshgrid(np.arange(nu), np.arange(nv), indexing="ij")
    base = (i * (nv + 1) + j).ravel()
    quads = np.stack([base, base + nv + 1, base + nv + 2, base + 1], axis=1)
    return quads if keep is None else quads[keep.ravel()]


def _check_cells(cells, name, count):
    cells = tuple(int(c) for c in np.atleast_1d(cells))
    if len(cells) != count or min(cells) < 1:
        raise ValueError(f"{name}: expected {count} positive cell counts, got {cells}")
    return cells


def of_order(mesh, order):
    """mesh with linear (order 1) or quadratic (order 2: TetMesh.raised) tets."""
    if order not in (1, 2):
        raise ValueError(f"order: 1 (linear tets) or 2 (quadratic tets), got {order!r}")
    return mesh if order == 1 else mesh.raised()


def box_beam(size=(0.1, 0.02, 0.02), cells=(10, 2, 2), order=1, tets_per_cell=5):
    """Box beam [0, L] x [-W/2, W/2] x [-H/2, H/2] with size (L, W, H) in m, split into
    cells (nx, ny, nz) hexes of tets_per_cell (5 or 6) tets each, linear or (order 2)
    quadratic. Even ny and nz keep the mesh mirror-symmetric about the y = 0 and z = 0 planes,
    with either split."""
    nx, ny, nz = _check_cells(cells, "cells", 3)
    L, W, H = (float(s) for s in size)
    if min(L, W, H) <= 0:
        raise ValueError(f"size: all dimensions must be > 0 m, got {size}")
    if tets_per_cell not in (5, 6):
        raise ValueError(f"tets_per_cell: 5 or 6, got {tets_per_cell!r}")
    v, w = np.meshgrid(np.linspace(-W / 2, W / 2, ny + 1), np.linspace(-H / 2, H / 2, nz + 1),
                       indexing="ij")
    section = np.stack([v.ravel(), w.ravel()], axis=1)
    pts, hexes = _extrude(section, _grid_quads(ny, nz), np.linspace(0, L, nx + 1), axis=0)
    if tets_per_cell == 5:
        return of_order(hexes_to_tets(pts, hexes), order)
    return of_order(TetMesh(pts, _six_tets((nx, ny, nz)), fix_orientation=True), order)


def _six_tets(cells):
    """Tets (6 nx ny nz, 4) of a grid of cells (nx, ny, nz) with vertex (i, j, k) at index
    (i (ny + 1) + j) (nz + 1) + k (as _extrude numbers box_beam's): each cell split into the 6
    tets along the monotone paths from its corner with even indices to the opposite corner."""
    idx = np.stack(np.meshgrid(*(np.arange(n) for n in cells), indexing="ij"), -1).reshape(-1, 3)
    start = idx + idx % 2                       # the cell's corner with even indices
    step = 1 - 2 * (idx % 2)                    # towards the opposite corner
    ny, nz = cells[1] + 1, cells[2] + 1
    tets = []
    for axes in itertools.permutations(range(3)):
        path = [start.copy()]
        for a in axes:
            corner = path[-1].copy()
            corner[:, a] += step[:, a]
            path.append(corner)
        tets.append(np.stack([(c[:, 0] * ny + c[:, 1]) * nz + c[:, 2] for c in path], axis=1))
    return np.stack(tets, axis=1).reshape(-1, 4)


def cylinder_beam(length=0.1, radius=0.01, cells_along=10, section_cells=2, rings=1, order=1):
    """Cylinder beam along x from 0 to length, radius in m.

    The cross-section is an O-grid: a square core of section_cells^2 quads (half-width
    radius/2) surrounded by `rings` layers of 4 section_cells quads reaching the circle
    (rings=0: the core itself is mapped onto the disk). Tets: 5 cells_along (section_cells^2
    + 4 section_cells rings). An even section_cells keeps the mesh mirror-symmetric. order 2:
    quadratic tets (straight-sided: their midside nodes on the chords, not on the circle).
    """
    n = _check_cells(section_cells, "section_cells", 1)[0]
    nx = _check_cells(cells_along, "cells_along", 1)[0]
    if int(rings) < 0:
        raise ValueError(f"rings: must be >= 0, got {rings}")
    if length <= 0 or radius <= 0:
        raise ValueError(f"length, radius: must be > 0 m, got {length}, {radius}")
    a = radius / 2 if rings else radius
    u, v = np.meshgrid(np.linspace(-a, a, n + 1), np.linspace(-a, a, n + 1), indexing="ij")
    core = np.stack([u.ravel(), v.ravel()], axis=1)
    quads = [_grid_quads(n, n)]
    i = np.concatenate([np.arange(n), np.full(n, n), np.arange(n, 0, -1), np.zeros(n, int)])
    j = np.concatenate([np.zeros(n, int), np.arange(n), np.full(n, n), np.arange(n, 0, -1)])
    rim = i * (n + 1) + j  # core perimeter, counter-clockwise
    p = core[rim]
    on_circle = p * (radius / np.linalg.norm(p, axis=1))[:, None]
    if rings == 0:
        r_inf = np.abs(core).max(axis=1)
        r_2 = np.linalg.norm(core, axis=1)
        scale = np.divide(r_inf, r_2, out=np.ones_like(r_2), where=r_2 > 0)
        section = core * scale[:, None]
    else:
        layers = [p + (t / rings) * (on_circle - p) for t in range(1, rings + 1)]
        section = np.concatenate([core] + layers)
        index = [rim] + [core.shape[0] + t * 4 * n + np.arange(4 * n) for t in range(rings)]
        for t in range(rings):
            inner, outer = index[t], index[t + 1]
            quads.append(np.stack([inner, np.roll(inner, -1), np.roll(outer, -1), outer], 1))
    pts, hexes = _extrude(section, np.concatenate(quads), np.linspace(0, length, nx + 1), 0)
    return of_order(hexes_to_tets(pts, hexes), order)


def _masked_section(width, height, cell, inside):
    """Structured quads of a (width x height) rectangle centered on x = 0 from z = 0, keeping
    the cells whose center (x, z) satisfies inside(x, z); unused vertices removed."""
    nu, nv = int(round(width / cell)), int(round(height / cell))
    if nu < 1 or nv < 1 or abs(nu * cell - width) > 1e-9 * width or \
            abs(nv * cell - height) > 1e-9 * height:
        raise ValueError(f"cell: {cell} m must divide width {width} m and height {height} m")
    u, v = np.meshgrid(np.linspace(-width / 2, width / 2, nu + 1), np.linspace(0, height, nv + 1),
                       indexing="ij")
    cu, cv = np.meshgrid(-width / 2 + cell * (np.arange(nu) + 0.5), cell * (np.arange(nv) + 0.5),
                         indexing="ij")
    quads = _grid_quads(nu, nv, keep=inside(cu, cv))
    used, quads = np.unique(quads, return_inverse=True)
    section = np.stack([u.ravel(), v.ravel()], axis=1)[used]
    return section, quads.reshape(-1, 4)


def t_shape(width=0.1, height=0.08, flange=0.02, stem=0.02, depth=0.02, cell=0.01, order=1):
    """A T in the x-z plane extruded along y over [-depth/2, depth/2]: a top flange of the given
    width and thickness `flange` on a stem of width `stem`, standing on z = 0. Cubic cells of
    edge `cell` (m); keep width / cell and stem / cell even for x-mirror symmetry. order 2:
    quadratic tets."""
    section, quads = _masked_section(
        width, height, cell, lambda x, z: (z > height - flange) | (np.abs(x) < stem / 2))
    ny = max(1, int(round(depth / cell)))
    pts, hexes = _extrude(section, quads, np.linspace(-depth / 2, depth / 2, ny + 1), axis=1)
    return of_order(hexes_to_tets(pts, hexes), order)


def y_shape(width=0.1, height=0.08, flange=0.02, stem=0.02, depth=0.02, cell=0.01,
            angle=35.0, order=1):
    """A Y: the T of t_shape with both arms bent upward by `angle` degrees from the horizontal
    (vertices with |x| > stem/2 rise by (|x| - stem/2) tan(angle)). order 2: quadratic tets."""
    if not 0 <= angle < 80:
        raise ValueError(f"angle: expected degrees in [0, 80), got {angle}")
    mesh = t_shape(width, height, flange, stem, depth, cell)
    X = mesh.vertices.copy()
    X[:, 2] += np.maximum(np.abs(X[:, 0]) - stem / 2, 0.0) * np.tan(np.radians(angle))
    return of_order(TetMesh(X, mesh.tets), order)


def tube(inner=0.01, outer=0.02, length=0.02, cells=(4, 8, 2), sweep=90.0, order=1):
    """A thick-walled tube along z from 0 to length: radii inner < outer in m, over `sweep`
    degrees of the circle from the +x axis (360: the whole tube, cells around even), cells
    (radial, around, along). Quadratic tets (order 2) are straight-sided: their midside nodes on
    the chords. Its cavity wall: the boundary faces with centroid radius below the wall's
    middle (faces_where)."""
    nr, nt, nz = _check_cells(cells, "cells", 3)
    if not 0 < inner < outer or length <= 0:
        raise ValueError(f"inner, outer, length: need 0 < inner < outer and length > 0 m, got "
                         f"{inner}, {outer}, {length}")
    if not 0 < sweep <= 360:
        raise ValueError(f"sweep: degrees in (0, 360], got {sweep}")
    whole = sweep == 360
    if whole and nt % 2:
        raise ValueError(f"cells: a whole tube needs an even number of cells around, got {nt}")
    theta = np.radians(np.linspace(0.0, sweep, nt + 1))[:nt if whole else nt + 1]
    r = np.linspace(inner, outer, nr + 1)
    R, T = np.meshgrid(r, theta, indexing="ij")
    section = np.stack([(R * np.cos(T)).ravel(), (R * np.sin(T)).ravel()], axis=1)
    quads = _grid_quads(nr, nt)
    if whole:  # the last column of cells closes on the first row of angles
        quads = np.where(quads % (nt + 1) == nt, quads - nt, quads)
        quads = quads - quads // (nt + 1)
    pts, hexes = _extrude(section, quads, np.linspace(0.0, length, nz + 1), axis=2)
    return of_order(hexes_to_tets(pts, hexes), order)


def actuator(radius=0.01, length=0.08, layer=0.002, cavity=0.75, cap=0.01, cells=(8, 4, 16),
             order=1):
    """A fiber-reinforced bending actuator along z from the base z = 0 to z = length (m): a body
    of half-circular section (radius, flat side on y = 0) around a cavity, on a flat
    strain-limiting layer (y from -layer to 0). The cavity fills the section's inner part (its
    corners in the grid's reference square at |u| < cavity, 0 < w < cavity, mapped by the
    elliptical grid map onto the half disc) from the base, where it is open, to `cap` below
    the tip. cells: (across, up, along): across even, the cavity a whole number of cells across
    and up.

    Returns (TetMesh, volumes (m,) its group of each tet, surfaces {group: (k, 3) faces},
    names {name: group}): "body" 1 and "layer" 2, surfaces "cavity" 3 (the cavity's walls),
    "base" 4 (z = 0) and "tip" 5 (z = length); for io.write_tagged_mesh."""
    nu, nw, nz = _check_cells(cells, "cells", 3)
    su, sw = cavity * nu / 2, cavity * nw
    if nu % 2 or abs(su - round(su)) > 1e-9 or abs(sw - round(sw)) > 1e-9 or \
            not 0 < cavity < 1:
        raise ValueError(f"cells, cavity: the cavity (|u| < {cavity}, w < {cavity}) must span "
                         f"whole cells of {cells} (across even)")
    if not 0 < cap < length or min(radius, layer) <= 0:
        raise ValueError(f"radius, length, layer, cap: need positive sizes and cap < length, "
                         f"got {radius}, {length}, {layer}, {cap}")
    u = np.linspace(-1.0, 1.0, nu + 1)
    w = np.concatenate([[-1.0], np.linspace(0.0, 1.0, nw + 1)])  # one row of layer below
    U, W = np.meshgrid(u, w, indexing="ij")
    up = np.clip(W, 0.0, None)
    x = radius * U * np.sqrt(1.0 - up ** 2 / 2.0)
    y = np.where(W < 0, layer * W, radius * up * np.sqrt(1.0 - U ** 2 / 2.0))
    section = np.stack([x.ravel(), y.ravel()], axis=1)
    quads = _grid_quads(nu, nw + 1)
    z = np.linspace(0.0, length, nz + 1)
    pts, hexes = _extrude(section, quads, z, axis=2)
    cu = 0.5 * (u[:-1] + u[1:])
    cw = 0.5 * (w[:-1] + w[1:])
    cz = 0.5 * (z[:-1] + z[1:])
    CU, CW = np.meshgrid(cu, cw, indexing="ij")
    hollow = ((np.abs(CU) < cavity) & (CW > 0) & (CW < cavity)).ravel()
    empty = hollow[None, :] & (cz < length - cap)[:, None]
    keep = ~empty.ravel()
    hexes = hexes[keep]
    used, hexes = np.unique(hexes, return_inverse=True)
    mesh = hexes_to_tets(pts[used], hexes.reshape(-1, 8))
    layer_cells = np.repeat((np.tile(CW.ravel() < 0, nz))[keep], 5)
    volumes = np.where(layer_cells, 2, 1)
    X = mesh.vertices
    faces = mesh.boundary_faces
    corners = X[faces]
    tol = 1e-9 * mesh.size
    on_base = (np.abs(corners[:, :, 2]) < tol).all(axis=1)
    on_tip = (np.abs(corners[:, :, 2] - length) < tol).all(axis=1)
    outer = _on_outer_surface(corners, radius, layer, tol)
    inside = ~(on_base | on_tip | outer)
    surfaces = {3: faces[inside], 4: faces[on_base], 5: faces[on_tip]}
    return (of_order(mesh, order), volumes,
            surfaces, {"body": 1, "layer": 2, "cavity": 3, "base": 4, "tip": 5})


def _on_outer_surface(corners, radius, layer, tol):
    """(k,) whether boundary faces (k, 3, 3) lie on the actuator's outside: the half cylinder
    r = radius above y = 0, the layer's bottom y = -layer and its sides |x| = radius."""
    r = np.hypot(corners[:, :, 0], corners[:, :, 1])
    y = corners[:, :, 1]
    curved = ((np.abs(r - radius) < 1e-6 * radius) & (y >= -tol)).all(axis=1)
    bottom = (np.abs(y + layer) < tol).all(axis=1)
    sides = (np.abs(np.abs(corners[:, :, 0]) - radius) < tol).all(axis=1) & (y <= tol).all(axis=1)
    return curved | bottom | sides
