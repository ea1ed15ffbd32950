"""A scene: mesh + material + boundary conditions + dead loads, with the per-element data the
kernels need, precomputed once."""
import copy
from dataclasses import dataclass, replace
from functools import cached_property

import numpy as np

from .._validate import as_float_array, as_index_array, check_shape, per_element
from .assembly import BandedLayout, CsrLayout, DenseLayout
from .inversion import volume_change
from .kernels import MAX_NODES
from .densities import STVK
from .material import Material
from .mesh import TetMesh, block_coloring
from .cables import Cable, CableLoad
from .contact import DISTANCE_SHARE, Contact, body_size, surface_nodes
from .obstacles import Plane, Surface
from .self_contact import SelfContact, check_rest, check_surface
from .controls import Activation, control_mapping, control_number
from .curves import Timed
from .pressure import CavityLoad, Pressure


#: Scene.gradient_roundoff's margin over the smallest gradient norm Newton reaches.
ROUNDOFF_FACTOR = 2.0
#: Scene.energy_roundoff's margin over eps mu V per Neo-Hookean element: a sliding block of
#: 40 elements at E = 10 MPa rose 1.5e-15 J (0.05 of eps sum mu V) over a Newton step that cut
#: the gradient 600x.
ENERGY_ROUNDOFF_FACTOR = 4.0


@dataclass(frozen=True)
class ElementData:
    """Arrays the element loop reads (see anisofem.physics.kernels), one row per element."""
    tets: np.ndarray          # (m, k) int64 node indices, k nodes per element
    grads: np.ndarray         # (m, q, k, 3) shape gradients at the quadrature points, 1/m
    weights: np.ndarray       # (m, q) quadrature weights times the rest volume, m^3
    model: np.ndarray         # (m,) int8 base law (anisofem.physics.densities.MODELS)
    mu: np.ndarray            # (m,) Pa
    lam: np.ndarray           # (m,) Pa
    kappa: np.ndarray         # (m,) Pa
    rest2: np.ndarray         # (m,) the fibers' squared rest stretch (1 - activation)^2
    fiber: np.ndarray         # (m, 3) unit fiber directions
    has_fiber: bool           # False: the fiber term is skipped entirely
    block_starts: np.ndarray  # (blocks,) int64 first tet of each assembly block, by color
    color_ptr: np.ndarray     # (colors + 1,) int64 color c: block_starts[ptr[c]:ptr[c+1]]

    def subset(self, rows, tets=None):
        """The ElementData of the elements `rows` (indices), their node numbers replaced by
        `tets` (len(rows), k) where given (a compact numbering), with an assembly coloring of
        their own (the whole mesh's would let two threads scatter into one node)."""
        rows = np.asarray(rows, dtype=np.int64)
        tets = np.ascontiguousarray(self.tets[rows] if tets is None else tets, dtype=np.int64)
        if rows.size:
            starts, ptr = block_coloring(tets[:, :4], int(tets.max()) + 1)
        else:
            starts, ptr = np.zeros(0, np.int64), np.zeros(1, np.int64)
        return replace(self, tets=tets, grads=self.grads[rows], weights=self.weights[rows],
                       model=self.model[rows], mu=self.mu[rows], lam=self.lam[rows],
                       kappa=self.kappa[rows], rest2=self.rest2[rows], fiber=self.fiber[rows],
                       has_fiber=bool((self.kappa[rows] > 0).any()), block_starts=starts,
                       color_ptr=ptr)


class Scene:
    """What is simulated: a mesh, its material, what is held and what loads it.

    Parameters
    ----------
    mesh : TetMesh.
    material : Material (default: Material.paper(), no fibers).
    fixed : Dirichlet vertices: None, vertex indices (k,), a per-vertex bool mask (n,), or a
        per-component bool mask (n, 3) (rollers, symmetry planes).
    fixed_positions : where the fixed components are held, m: (n, 3), or (k, 3) when fixed is
        given as k indices. Default: their rest positions.
    gravity : acceleration (3,) in m/s^2, adds density * gravity to the body force.
    body_force : force density b in N/m^3, (3,) or (m, 3), integrated with the shape functions
        (the consistent load, CONSISTENT: b v / 4 to each vertex of a linear tet).
    nodal_force : (n, 3) forces in N applied to vertices.
    traction : surface load t in N/m^2 on traction_faces, (3,) or (k, 3), per rest area; t
        area / 3 goes to each face vertex of linear tets, to each midside node of quadratic ones
        (dead load: fixed in direction and magnitude).
    traction_faces : (k, 3) vertex triples, which must be boundary faces of the mesh (see
        TetMesh.faces_where).
    pressure : an anisofem.Pressure or a sequence of them: uniform pressures on the walls of
        cavities, follower loads whose potential is -p times the change of the enclosed volume
        (anisofem.physics.pressure); `pressures` holds them bound to the mesh. A named one is a
        control.
    activation : an anisofem.Activation or a sequence of them: the fibers' activation of sets
        of elements, each a control (anisofem.physics.controls); `activations` holds them.
    cable : an anisofem.Cable or a sequence of them: tendons routed through the body, each
        pulled with a tension, a control (anisofem.physics.cables); `cables` holds them bound
        to the mesh.
    contact : an anisofem.Contact: rigid obstacles the body's surface cannot pass, with
        friction (anisofem.physics.contact); ValueError where the body starts inside one.

    Controls (`controls`, their names; `control_values`) are set by with_controls, by load
    curves (following) and by simulate's `controls`.

    Vertices that no tet uses are held in place. The other loads are dead loads: the external
    force vector is constant, f_ext (n, 3), and enters the potential as -f_ext . x.
    """

    def __init__(self, mesh, material=None, *, fixed=None, fixed_positions=None, gravity=None,
                 body_force=None, nodal_force=None, traction=None, traction_faces=None,
                 pressure=None, activation=None, cable=None, contact=None):
        if not isinstance(mesh, TetMesh):
            raise TypeError(f"mesh: expected an anisofem.TetMesh, got {type(mesh).__name__}")
        material = Material.paper() if material is None else material
        if not isinstance(material, Material):
            raise TypeError(f"material: expected an anisofem.Material, got "
                            f"{type(material).__name__}")
        self.mesh = mesh
        self.material = material
        self._layouts = {}
        n, m = mesh.n_vertices, mesh.n_tets
        self._params = material.per_element(m)
        self.fixed_mask = self._fixed_mask(fixed)
        self.fixed_positions = self._fixed_positions(fixed, fixed_positions)
        vol = mesh.rest_volumes
        self.masses = _to_nodes(mesh, self._params["density"] * vol, LUMPED[mesh.order])
        self.gravity = np.zeros(3) if gravity is None else as_float_array(gravity, "gravity",
                                                                           shape=(3,))
        b = self._params["density"][:, None] * self.gravity
        if body_force is not None:
            b += per_element(body_force, "body_force", m, width=3)
        f = np.zeros((n, 3))
        for i in range(3):
            f[:, i] = _to_nodes(mesh, b[:, i] * vol, CONSISTENT[mesh.order])
        if nodal_force is not None:
            f += as_float_array(nodal_force, "nodal_force", shape=(n, 3))
        if traction is not None or traction_faces is not None:
            f += traction_force(mesh, traction, traction_faces)
        self.external_force = f
        self.pressures = _cavity_loads(mesh, pressure, self.fixed_mask)
        self.activations = _activations(activation, self._params)
        self.cables = _cable_loads(mesh, cable)
        _check_names(self.pressures, self.activations, self.cables)
        self.contact = _contact(contact, mesh, self.initial_positions())
        self.timed = ()
        for arr in (self.fixed_mask, self.fixed_positions, self.masses, self.external_force,
                    self.gravity):
            arr.setflags(write=False)

    def gravity_force(self, g):
        """The nodal force (n, 3), N, of gravity g (3,), m/s^2, on this scene's mesh and
        densities (the consistent load, as the scene's own gravity)."""
        g = as_float_array(g, "gravity", shape=(3,))
        per_tet = self._params["density"] * self.mesh.rest_volumes
        share = _to_nodes(self.mesh, per_tet, CONSISTENT[self.mesh.order])
        return share[:, None] * g

    def _fixed_mask(self, fixed):
        n = self.mesh.n_vertices
        mask = np.zeros((n, 3), bool)
        if fixed is not None:
            arr = np.asarray(fixed)
            if arr.size == 0:  # [] or (): no vertex held (numpy reads [] as float64)
                arr = np.zeros(0, np.int64)
            if arr.dtype == bool:
                if arr.shape == (n,):
                    mask[arr] = True
                elif arr.shape == (n, 3):
                    mask |= arr
                else:
                    raise ValueError(f"fixed: a bool mask must have shape ({n},) or ({n}, 3), "
                                     f"got {arr.shape}")
            else:
                idx = as_index_array(arr, "fixed", shape=(None,))
                if idx.size and (idx.min() < 0 or idx.max() >= n):
                    raise ValueError(f"fixed: vertex index out of range [0, {n})")
                if np.unique(idx).size != idx.size:
                    raise ValueError("fixed: repeated vertex indices")
                mask[idx] = True
        mask[self.mesh.unreferenced] = True
        return mask

    def _fixed_positions(self, fixed, positions):
        x = self.mesh.vertices.copy()
        if positions is None:
            return x
        pos = as_float_array(positions, "fixed_positions")
        n = self.mesh.n_vertices
        if pos.shape == (n, 3):
            x[self.fixed_mask] = pos[self.fixed_mask]
            return x
        if fixed is not None and np.asarray(fixed).dtype != bool:
            idx = np.asarray(fixed)
            check_shape(pos, "fixed_positions", (idx.size, 3))
            x[idx] = pos
            return x
        raise ValueError(f"fixed_positions: expected shape ({n}, 3), or (k, 3) with fixed "
                         f"given as k indices; got {pos.shape}")

    @cached_property
    def dof_map(self):
        """(n, 3) int64: index of each free vertex component among the unknowns, -1 if fixed."""
        free = ~self.fixed_mask
        dof = np.full(free.shape, -1, np.int64)
        dof[free] = np.arange(free.sum())
        return dof

    @cached_property
    def free_dofs(self):
        """(k,) int64 flat DOF index (3 i + c) of each unknown, in unknown order."""
        return np.flatnonzero(~self.fixed_mask.ravel())

    @property
    def n_free(self):
        """Number of unknowns (free vertex components)."""
        return int((~self.fixed_mask).sum())

    @cached_property
    def force_unit(self):
        """Largest elastic modulus times the mean squared rest edge length, N: the force that
        strains an element by 100%."""
        p = self._params
        modulus = float(np.max(2 * p["mu"] + np.abs(p["lam"]) + 8 * p["kappa"]))
        return modulus * self._edge_length ** 2

    @cached_property
    def _edge_length(self):
        """Root mean square rest edge length, m."""
        X = self.mesh.vertices[self.mesh.edges]
        return float(np.sqrt(((X[:, 1] - X[:, 0]) ** 2).sum(1).mean()))

    @cached_property
    def gradient_roundoff(self):
        """The free-gradient norm below which float64 cannot resolve G's gradient, N:
        ROUNDOFF_FACTOR eps force_unit (R / l) sqrt(unknowns), with R the largest coordinate
        and l the edge length. F sums absolute positions times shape gradients ~ 1 / l, so
        its round-off is ~ eps R / l and each nodal force's ~ eps E l^2 R / l. Measured, the
        smallest residual Newton reaches is 0.07 to 0.56 of eps force_unit (R / l)
        sqrt(unknowns) (200 to 12,800 tets, nu 0.3 to 0.4999, kappa up to 1000 E, the mesh at
        the origin or 1 m away)."""
        R = float(np.abs(np.concatenate([self.mesh.vertices, self.fixed_positions])).max())
        l = self._edge_length
        return (ROUNDOFF_FACTOR * np.finfo(float).eps * self.force_unit * max(R, l) / l
                * np.sqrt(self.n_free))

    @cached_property
    def elements(self):
        data = element_data(self.mesh, self._params)
        return _activated(data, self.activations) if self.activations else data

    @property
    def controls(self):
        """The names of the scene's controls: its named pressures, its activations, then its
        cables."""
        return (tuple(p.name for p in self.pressures if p.name)
                + tuple(a.name for a in self.activations) + tuple(c.name for c in self.cables))

    @property
    def control_values(self):
        """(k,) the controls' values now, in the order of `controls` (Pa, activation, N)."""
        return np.array([p.magnitude for p in self.pressures if p.name]
                        + [a.value for a in self.activations]
                        + [c.tension for c in self.cables], dtype=float)

    def with_controls(self, values):
        """The same scene with controls set: values, a mapping name -> value (the others
        keep theirs) or one value per control in the order of `controls`. Pressures in Pa,
        activations in [0, 1), tensions >= 0 N. Shares what held_at shares; ValueError naming
        the control for an unknown name, a value that is not a finite number, an activation
        outside [0, 1) or a negative tension."""
        values = control_mapping(values, self.controls)
        moved = self.held_at(self.fixed_positions)
        moved.pressures = tuple(
            p.at(control_number(values[p.name], p.name)) if p.name in values else p
            for p in self.pressures)
        moved.activations = tuple(a.at(values[a.name]) if a.name in values else a
                                  for a in self.activations)
        moved.cables = tuple(c.at(values[c.name]) if c.name in values else c
                             for c in self.cables)
        if any(a.name in values for a in self.activations):
            moved.elements = _activated(self.elements, moved.activations)
        return moved

    def layout(self, kind):
        """The Hessian layout over the free DOFs: kind "csr", "dense" or "banded" (cached);
        it joins the nodes of each cable segment too."""
        if kind not in self._layouts:
            cls = {"csr": CsrLayout, "dense": DenseLayout, "banded": BandedLayout}[kind]
            self._layouts[kind] = cls(self.elements.tets, self.dof_map, self._couplings)
        return self._layouts[kind]

    @cached_property
    def full_layout(self):
        """CSR layout over all 3n DOFs (for the public hessian())."""
        n = self.mesh.n_vertices
        return CsrLayout(self.elements.tets, np.arange(3 * n, dtype=np.int64).reshape(n, 3),
                         self._couplings)

    @property
    def _couplings(self):
        """(g, w) the node groups of the cables' segments (None without cables)."""
        if not self.cables:
            return None
        return np.concatenate([c.groups for c in self.cables])

    def check_static(self):
        """Raise ValueError unless fixed components (or a plane obstacle across the axis) remove
        the rigid translations."""
        held = self.fixed_mask.copy()
        held[self.mesh.unreferenced] = False
        if not held.any():
            raise ValueError("fixed: a static scene needs fixed vertices (with none, the "
                             "equilibrium is not unique: the body can translate and rotate)")
        missing = [c for c in range(3) if not held[:, c].any()]
        if self.contact is not None:   # an obstacle holds the body along its normal
            missing = [c for c in missing if not any(
                isinstance(o, Plane) and abs(o.normal[c]) > 0.5 for o in self.contact.obstacles)]
        if missing:
            raise ValueError(f"fixed: no vertex is held along axis {missing}: the static "
                             f"equilibrium is not unique (free rigid translation)")

    def initial_positions(self):
        """(n, 3) rest positions with fixed components at their prescribed positions."""
        return self.fixed_positions.copy()

    def with_fixed(self, x):
        """A float64 copy of positions x (n, 3) in m with the fixed components moved to their
        prescribed positions."""
        x = np.array(x, dtype=float)
        x[self.fixed_mask] = self.fixed_positions[self.fixed_mask]
        return x

    def held_at(self, fixed_positions):
        """The same scene with its fixed components held at fixed_positions (n, 3), m: for
        prescribed motion, one scene per step. Shares the per-element data, the sparsity
        patterns and the loads, so it costs a copy of the positions."""
        pos = as_float_array(fixed_positions, "fixed_positions",
                             shape=(self.mesh.n_vertices, 3))
        for shared in ("elements", "dof_map", "free_dofs", "neohookean"):
            getattr(self, shared)  # computed once here, so that the copies share them
        moved = copy.copy(self)
        x = self.fixed_positions.copy()
        x[self.fixed_mask] = pos[self.fixed_mask]
        x.setflags(write=False)
        moved.fixed_positions = x
        return moved

    def holding(self, vertices):
        """The same scene with `vertices` (indices) held too, where they are, and no contact:
        what a reduced model's static snapshots of the parts that carry a free body solve."""
        moved = copy.copy(self)
        mask = self.fixed_mask.copy()
        mask[np.asarray(vertices, dtype=int)] = True
        moved.fixed_mask, moved.contact, moved._layouts = mask, None, {}
        for cached in ("dof_map", "free_dofs", "force_unit", "gradient_roundoff",
                       "full_layout"):
            moved.__dict__.pop(cached, None)
        return moved

    def with_contact(self, contact):
        """The same scene with another contact (an anisofem.Contact, or None): for friction or
        stiffness studies. Checked against the body at rest as the constructor's is; shares
        what held_at shares."""
        moved = self.held_at(self.fixed_positions)
        moved.contact = _contact(contact, self.mesh, self.initial_positions())
        return moved

    def loaded(self, share, prescribed=True):
        """The same scene under `share` of its load (0 to 1): the external force times share,
        and with prescribed the fixed components share of the way from rest to their prescribed
        positions (load continuation, anisofem.solvers.continuation; a step keeps them). Shares what
        held_at shares."""
        rest = self.mesh.vertices
        moved = self.held_at(rest + share * (self.fixed_positions - rest) if prescribed
                             else self.fixed_positions)
        force = share * self.external_force
        force.setflags(write=False)
        moved.external_force = force
        moved.pressures = tuple(p.scaled(share) for p in self.pressures)
        moved.cables = tuple(c.at(share * c.tension) for c in self.cables)
        return moved

    def plus_force(self, force):
        """The same scene with nodal forces `force` (n, 3), N, added to its external force.
        Shares what held_at shares."""
        f = as_float_array(force, "force", shape=(self.mesh.n_vertices, 3))
        moved = self.held_at(self.fixed_positions)
        total = self.external_force + f
        total.setflags(write=False)
        moved.external_force = total
        return moved

    def with_material(self, material):
        """The same scene (mesh, held vertices, loads) with another Material of the same
        densities: for parameter studies and fits. Shares the mesh's patterns and the loads."""
        if not isinstance(material, Material):
            raise TypeError(f"material: expected an anisofem.Material, got "
                            f"{type(material).__name__}")
        params = material.per_element(self.mesh.n_tets)
        if not np.array_equal(params["density"], self._params["density"]):
            raise ValueError("material: another density changes the masses and the weight; "
                             "build a new Scene")
        for shared in ("dof_map", "free_dofs"):
            getattr(self, shared)
        moved = copy.copy(self)
        moved.material, moved._params = material, params
        moved.activations = _activations(self.activations, params)
        for cached in ("elements", "full_layout", "force_unit", "gradient_roundoff",
                       "neohookean"):
            moved.__dict__.pop(cached, None)
        return moved

    def following(self, timed):
        """The same scene with loads that follow load curves: timed, a sequence of
        anisofem.physics.curves.Timed, each a part of this scene's loads as written (its force in
        external_force, its pressure in pressures, its motion in fixed_positions, its control's
        value in control_values). Scene.at(t) scales each part by its curve. Shares what
        held_at shares."""
        timed = tuple(timed)
        n = self.mesh.n_vertices
        for k, part in enumerate(timed):
            if not isinstance(part, Timed):
                raise TypeError(f"timed[{k}]: expected anisofem.physics.curves.Timed, got "
                                f"{type(part).__name__}")
            if part.pressure is not None and not 0 <= part.pressure < len(self.pressures):
                raise ValueError(f"timed[{k}]: pressure {part.pressure} is not one of the "
                                 f"scene's {len(self.pressures)}")
            if part.force is not None:
                as_float_array(part.force, f"timed[{k}].force", shape=(n, 3))
            if part.control is not None:
                self._check_timed_control(part, f"timed[{k}].control")
            if part.obstacle is not None:
                names = [o.name for o in self.contact.obstacles] if self.contact else []
                if part.obstacle[0] not in names:
                    raise ValueError(f"timed[{k}].obstacle: no obstacle {part.obstacle[0]!r}; "
                                     f"the scene has: {', '.join(names) or 'none'}")
                as_float_array(part.obstacle[1], f"timed[{k}].obstacle move", shape=(3,))
        moved = self.held_at(self.fixed_positions)
        moved.timed = timed
        return moved

    def _check_timed_control(self, part, where):
        """ValueError unless part.control names a control, and an activation's curve keeps it
        in [0, 1)."""
        if part.control not in self.controls:
            raise ValueError(f"{where}: no control {part.control!r}; the scene has: "
                             f"{', '.join(self.controls) or 'none'}")
        written = dict(zip(self.controls, self.control_values))[part.control]
        if part.control in {a.name for a in self.activations}:
            top = written * max(part.curve.values.max(), 0.0)
            if part.curve.values.min() < 0 or not top < 1.0:
                raise ValueError(f"{where}: the curve {part.curve.name!r} takes activation "
                                 f"{part.control!r} outside [0, 1) (up to {top:g}): the "
                                 f"fibers' rest stretch must stay above 0")

    def at(self, t):
        """The scene at time t, s: each timed part (following) at its curve's value at t;
        the scene itself when none is timed."""
        if not self.timed:
            return self
        force = self.external_force.copy()
        held = self.fixed_positions.copy()
        pressures = list(self.pressures)
        written = dict(zip(self.controls, self.control_values))
        controls, moves = {}, {}
        for part in self.timed:
            c = part.curve(t) - 1.0
            if part.force is not None:
                force += c * part.force
            if part.motion is not None:
                held += (part.motion(c + 1.0) - part.motion(1.0)) * self.fixed_mask
            if part.pressure is not None:
                pressures[part.pressure] = pressures[part.pressure].scaled(c + 1.0)
            if part.control is not None:
                controls[part.control] = (c + 1.0) * written[part.control]
            if part.obstacle is not None:
                name, move = part.obstacle
                moves[name] = moves.get(name, 0.0) + (c + 1.0) * np.asarray(move, dtype=float)
        moved = self.held_at(held)
        if moves:
            moved.contact = replace(self.contact, obstacles=tuple(
                o.moved(moves[o.name]) if o.name in moves else o for o in self.contact.obstacles))
        force.setflags(write=False)
        moved.external_force, moved.pressures, moved.timed = force, tuple(pressures), ()
        return moved.with_controls(controls) if controls else moved

    @cached_property
    def neohookean(self):
        """(m,) bool: the elements with the Neo-Hookean base (the others are StVK)."""
        return self.elements.model != STVK

    @cached_property
    def energy_roundoff(self):
        """The round-off of G's elastic part, J: the Neo-Hookean energy mu/2 (I1 - 3) -
        mu ln J is formed from terms of about 3 mu / 2 per volume, so each element's is about
        eps mu V; ENERGY_ROUNDOFF_FACTOR times their sum (0 for StVK, whose strain is formed
        before it is squared)."""
        nh = self.neohookean
        return float(ENERGY_ROUNDOFF_FACTOR * np.finfo(float).eps
                     * (self._params["mu"][nh] * self.mesh.rest_volumes[nh]).sum())

    def outside_domain(self, x):
        """How many elements have infinite energy at positions x (n, 3): Neo-Hookean ones with
        det F <= 0 (StVK is defined everywhere). A solve cannot start there."""
        if not self.neohookean.any():
            return 0
        return int((volume_change(self.mesh, x)[self.neohookean] <= -1.0).sum())


def element_data(mesh, params):
    """The ElementData of a TetMesh's elements (its element type, cells and quadrature point
    gradients) with material parameters `params` (Material.per_element)."""
    element = mesh.element
    if element.n_nodes > MAX_NODES:
        raise ValueError(f"element: {element.name} has {element.n_nodes} nodes; the element "
                         f"loop holds at most {MAX_NODES}")
    kappa = params["kappa"]
    starts, ptr = mesh.coloring
    return ElementData(
        tets=np.ascontiguousarray(mesh.cells, dtype=np.int64), grads=mesh.point_gradients,
        weights=mesh.point_weights, model=params["model"],
        mu=params["mu"], lam=params["lam"], kappa=kappa, rest2=params["rest2"],
        fiber=params["fiber"],
        has_fiber=bool((kappa > 0).any()), block_starts=starts, color_ptr=ptr)


#: A tet's lumped mass on its nodes, as shares of density times volume, by mesh order: linear
#: tets a quarter each; quadratic tets by HRZ (the consistent mass matrix's diagonal scaled to
#: the element's mass: 1/36 at each corner, 4/27 at each midside node), positive where
#: row-sum lumping gives the corners negative masses.
LUMPED = {1: np.full(4, 0.25), 2: np.array([1 / 36] * 4 + [4 / 27] * 6)}

#: The integrals of a tet's shape functions over its volume, as shares of the volume, by mesh
#: order: a uniform body force b puts b V share on each node (the consistent load; a quadratic
#: tet's corners get -1/20, its midside nodes 1/5).
CONSISTENT = {1: np.full(4, 0.25), 2: np.array([-1 / 20] * 4 + [1 / 5] * 6)}


def _to_nodes(mesh, per_tet, shares):
    """Sum a per-tet quantity (m,) onto each tet's nodes with shares (k,) of it: (n,)."""
    out = np.zeros(mesh.n_vertices)
    np.add.at(out, mesh.cells.ravel(), np.outer(per_tet, shares).ravel())
    return out


def _activations(activation, params):
    """The Activations (a tuple, elements as indices) of `activation`: None, an Activation or a
    sequence of them, on elements with fibers (params: Material.per_element's), none shared."""
    if activation is None:
        return ()
    given = (activation,) if isinstance(activation, Activation) else tuple(activation)
    out, owner = [], np.full(params["kappa"].size, -1)
    for a in given:
        if not isinstance(a, Activation):
            raise TypeError(f"activation: expected anisofem.Activation objects, got "
                            f"{type(a).__name__}")
        a = a.bound(params["kappa"].size, params["kappa"], params["activation"])
        shared = a.elements[owner[a.elements] >= 0]
        if shared.size:
            raise ValueError(f"activation {a.name!r}: {shared.size} of its elements are "
                             f"activation {out[owner[shared[0]]].name!r}'s too (first "
                             f"{int(shared[0])}); an element follows one activation")
        owner[a.elements] = len(out)
        out.append(a)
    return tuple(out)


def _activated(elements, activations):
    """ElementData elements with the fibers' squared rest stretch set by each Activation."""
    rest2 = elements.rest2.copy()
    for a in activations:
        rest2[a.elements] = (1.0 - a.value) ** 2
    return replace(elements, rest2=rest2)


def _cable_loads(mesh, cable):
    """The CableLoads (a tuple) of `cable`: None, a Cable or a sequence of them."""
    if cable is None:
        return ()
    given = (cable,) if isinstance(cable, Cable) else tuple(cable)
    for c in given:
        if not isinstance(c, Cable):
            raise TypeError(f"cable: expected anisofem.Cable objects, got {type(c).__name__}")
    return tuple(CableLoad(mesh, c) for c in given)


def _contact(contact, mesh, x):
    """contact (a Contact, or None) checked against the body at x (n, 3): ValueError naming an
    obstacle the surface starts inside or on."""
    if contact is None:
        return None
    if not isinstance(contact, Contact):
        raise TypeError(f"contact: expected an anisofem.Contact, got {type(contact).__name__}")
    nodes, _ = surface_nodes(mesh)
    if contact.self_contact:
        check_rest(SelfContact(mesh, DISTANCE_SHARE * body_size(mesh), 1.0), x)
    for o in contact.obstacles:
        if isinstance(o, Surface):
            check_surface(mesh, o, x)
            continue
        d, _ = o.distance(x[nodes])
        if (d <= 0).any():
            worst = int(np.argmin(d))
            at = ", ".join(f"{v:.4g}" for v in x[nodes[worst]])
            raise ValueError(f"contact: the body starts inside obstacle {o.name!r} ({o.kind}): "
                             f"{int((d <= 0).sum())} surface nodes, the deepest "
                             f"{-1e3 * d[worst]:.3g} mm in at ({at})")
    return contact


def _check_names(pressures, activations, cables):
    """ValueError where two controls share a name."""
    names = ([p.name for p in pressures if p.name] + [a.name for a in activations]
             + [c.name for c in cables])
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise ValueError(f"controls: the name {twice[0]!r} is given to two controls; each "
                         f"needs its own")


def _cavity_loads(mesh, pressure, fixed_mask):
    """The CavityLoads (a tuple) of `pressure`: None, a Pressure or a sequence of them."""
    if pressure is None:
        return ()
    given = (pressure,) if isinstance(pressure, Pressure) else tuple(pressure)
    for p in given:
        if not isinstance(p, Pressure):
            raise TypeError(f"pressure: expected anisofem.Pressure objects, got "
                            f"{type(p).__name__}")
    return tuple(CavityLoad(mesh, p, fixed_mask) for p in given)


def traction_force(mesh, traction, faces):
    """The nodal force (n, 3), N, of traction (3,) or (k, 3) N/m^2 per rest area on the
    boundary faces (k, 3) (see Scene's traction)."""
    if traction is None or faces is None:
        raise ValueError("traction, traction_faces: give both (N/m^2 and the boundary faces)")
    faces = as_index_array(faces, "traction_faces", shape=(None, 3))
    k = faces.shape[0]
    t = per_element(traction, "traction", k, width=3)
    mesh.find_boundary_faces(faces, "traction_faces")
    X = mesh.vertices[faces]
    area = 0.5 * np.linalg.norm(np.cross(X[:, 1] - X[:, 0], X[:, 2] - X[:, 0]), axis=1)
    f = np.zeros((mesh.n_vertices, 3))
    # a third of each face's load on three nodes: its corners (linear), or its midside nodes
    # (the 6-node triangle's shape functions integrate to 0 at corners, 1/3 at midsides)
    nodes = faces if mesh.order == 1 else mesh.edge_nodes(
        faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)).reshape(-1, 3)
    for c in range(3):
        np.add.at(f[:, c], nodes.ravel(), np.repeat(t[:, c] * area / 3.0, 3))
    return f


#: default_scene's gravity, m/s^2
GRAVITY = (0.0, 0.0, -9.81)


def check_scene(scene):
    """TypeError unless scene is a Scene (solve, step and simulate take nothing else)."""
    if not isinstance(scene, Scene):
        raise TypeError(f"scene: expected an anisofem.Scene, got {type(scene).__name__} (a "
                        f"TetMesh becomes one with anisofem.Scene or default_scene)")


def default_scene(mesh, material=None):
    """A cantilever of mesh: the paper's material (E = 100 kPa, nu = 0.48, 1000 kg/m^3, no
    fibers) unless another Material is given, the vertices at the minimum x held fixed,
    gravity 9.81 m/s^2 along -z."""
    x = mesh.vertices[:, 0]
    fixed = np.flatnonzero(x <= x.min() + 1e-9 * mesh.size)
    return Scene(mesh, Material.paper() if material is None else material, fixed=fixed,
                 gravity=GRAVITY)
