"""Step an exported anisognn model with numpy and onnxruntime only (copy this one file next to
model.onnx), and the constant mesh tensors the network reads (anisognn builds its training
graphs with these same functions, so the trained and the exported model cannot disagree about
what a graph is).

    sim = OnnxSimulator("model.onnx", vertices, tets, fixed=vertices[:, 0] < 1e-9,
                        fiber_direction=(1, 0, 0), fiber_stiffness=1e5)
    force = sim.masses[:, None] * (0.0, 0.0, -9.81)          # N per vertex
    x, v = sim.rest_positions, np.zeros_like(sim.rest_positions)
    for _ in range(100):
        x, v = sim.step(x, v, force)

Graph of a tet mesh with n vertices (all arrays are numpy; float32 unless said):

- undirected edges: the unique tet edges (k, 2) int64, pairs i < j, sorted.
- directed edges, E = 2 k: edge e goes from senders[e] to receivers[e]; edges 0..k-1 are
  (i -> j), edges k..2k-1 the reverses (j -> i).
- rest features (E, 4): unit rest vector u = (X_s - X_r) / |X_s - X_r| and the rest length
  |X_s - X_r| (m).
- directional weights (E, 3): u itself (paper eq. 4: w_k = u . e_k). Signed: an edge and its
  reverse carry opposite weights.
- fiber features (E, 3): kappa_e d_e where, over the tets sharing the edge, T = mean of
  kappa d d^T (Pa), kappa_e its largest eigenvalue and d_e the unit eigenvector (averaging
  d d^T cannot cancel, and d and -d are one fiber). The sign of d_e is fixed by the fiber alone:
  d_e . r >= 0 with the reference direction r = (1, sqrt 2, sqrt 3) / sqrt 6, so an edge and its
  reverse carry the same feature, a uniform fiber gives every edge the same feature, and
  relabeling the vertices changes nothing (only fibers almost orthogonal to r, which no
  axis-aligned or 45-degree fiber is, sit on the sign flip).
- incoming table (n, K) int64: the edges received by each vertex, padded with the index E
  (a padding edge whose latent features are zero); K is the largest in-degree.
- incoming weights (n, K, 3): the directional weights of those edges, 0 at padding.
- mass (n, 1) kg: lumped, density * volume / 4 of every tet to each of its vertices.
- fixed (n, 3): 1.0 where a component is held (Dirichlet), else 0.0; fixed_positions (n, 3)
  float64 m: where held components are held (here: their rest positions).
- rest_positions (n, 3) float64 m: the rest shape. The model reads the state as displacements
  from it, formed in float64 before the cast to float32: a strain of 1e-3 computed from float32
  positions 10 edge lengths from the origin keeps only 2-3 digits, from float32 displacements
  all of float32's.
- per-tet constants of the elastic force (read only by models with the Galerkin step): tets (m, 4)
  int64; tet_gradients (m, 4, 3) 1/m, the gradients of the four linear shape functions (row a
  is grad N_a, so F = sum_a x_a grad N_a^T); tet_material (m, 4): rest volume (m^3), mu, lam,
  kappa (Pa); tet_fiber (m, 3) unit fiber directions; corners (n, C) int64, the slots 4 t + a
  of the tet corners at each vertex, padded with 4 m.
"""
import json
import os

import numpy as np

#: control_kinds' codes (export.writers.reduced).
PRESSURE, ACTIVATION, TENSION = 0, 1, 2

#: Fiber features of edges whose tets have no fiber are 0; below this kappa (Pa) a fiber is
#: treated as absent when choosing its direction.
FIBER_EPS = 1e-12


def _tet_edges(tets):
    """(m, 6, 2) int64 vertex pairs of the six edges of each tet, each pair sorted."""
    tets = np.asarray(tets, dtype=np.int64)
    return np.sort(tets[:, [[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3]]], axis=2)


def mesh_edges(tets):
    """(k, 2) int64 unique undirected edges (i < j, sorted) of tets (m, 4)."""
    return np.unique(_tet_edges(tets).reshape(-1, 2), axis=0)


def directed_edges(edges):
    """(senders, receivers), each (2k,) int64: the k edges i -> j, then their reverses."""
    return (np.concatenate([edges[:, 0], edges[:, 1]]),
            np.concatenate([edges[:, 1], edges[:, 0]]))


def rest_features(vertices, senders, receivers):
    """(E, 4) float64: unit rest vectors (X_s - X_r)/|.| and rest lengths (m)."""
    vec = vertices[senders] - vertices[receivers]
    length = np.linalg.norm(vec, axis=1, keepdims=True)
    return np.concatenate([vec / length, length], axis=1)


#: the reference direction that fixes the sign of fiber features
FIBER_REFERENCE = np.array([1.0, np.sqrt(2.0), np.sqrt(3.0)]) / np.sqrt(6.0)


def edge_fibers(tets, edges, fiber_direction, fiber_stiffness):
    """(E, 3) float64 fiber features kappa_e d_e of the directed edges (see module docstring).

    tets (m, 4); edges (k, 2) undirected; fiber_direction (m, 3) unit; fiber_stiffness (m,) Pa.
    """
    k = edges.shape[0]
    tensor = np.einsum("m,mi,mj->mij", fiber_stiffness, fiber_direction, fiber_direction)
    ends = _tet_edges(tets)
    # the index of each tet edge among the unique (sorted) edges
    base = int(tets.max()) + 1
    index = np.searchsorted(edges[:, 0] * base + edges[:, 1], ends[..., 0] * base + ends[..., 1])
    total = np.zeros((k, 3, 3))
    np.add.at(total, index.ravel(), np.repeat(tensor, 6, axis=0))
    total /= np.bincount(index.ravel(), minlength=k)[:, None, None]
    values, vectors = np.linalg.eigh(total)
    kappa, d = np.maximum(values[:, 2], 0.0), vectors[:, :, 2]
    d *= np.where(d @ FIBER_REFERENCE < 0, -1.0, 1.0)[:, None]
    feature = np.where((kappa > FIBER_EPS)[:, None], kappa[:, None] * d, 0.0)
    return np.concatenate([feature, feature])


def incoming_table(receivers, n_vertices):
    """(n, K) int64 indices of the edges each vertex receives, padded with E = len(receivers)."""
    n_edges = receivers.shape[0]
    order = np.argsort(receivers, kind="stable")
    counts = np.bincount(receivers, minlength=n_vertices)
    width = max(int(counts.max()) if n_vertices else 0, 1)
    start = np.concatenate([[0], np.cumsum(counts)[:-1]])
    slot = np.arange(n_edges) - np.repeat(start, counts)
    table = np.full((n_vertices, width), n_edges, dtype=np.int64)
    table[receivers[order], slot] = order
    return table


def incoming_weights(table, weights):
    """(n, K, 3) weights of the incoming edges (0 at padding); weights (E, 3)."""
    padded = np.concatenate([weights, np.zeros((1, weights.shape[1]))])
    return padded[table]


#: version of the model's input/output contract (the ONNX file's "format" metadata)
FORMAT = "anisognn-step-2"
#: (name, dtype, shape) of the model's inputs; n vertices, E directed edges, K max in-degree
INPUTS = (
    ("positions", "float64", ("n", 3)),
    ("velocities", "float64", ("n", 3)),
    ("external_force", "float64", ("n", 3)),
    ("senders", "int64", ("E",)),
    ("receivers", "int64", ("E",)),
    ("rest", "float32", ("E", 4)),
    ("fiber", "float32", ("E", 3)),
    ("incoming", "int64", ("n", "K")),
    ("incoming_weights", "float32", ("n", "K", 3)),
    ("mass", "float32", ("n", 1)),
    ("fixed", "float32", ("n", 3)),
    ("fixed_positions", "float64", ("n", 3)),
    ("rest_positions", "float64", ("n", 3)),
    ("tets", "int64", ("m", 4)),
    ("tet_gradients", "float32", ("m", 4, 3)),
    ("tet_material", "float32", ("m", 4)),
    ("tet_fiber", "float32", ("m", 3)),
    ("corners", "int64", ("n", "C")),
)
#: (name, dtype, shape) of the model's outputs
OUTPUTS = (
    ("acceleration", "float32", ("n", 3)),
    ("next_positions", "float64", ("n", 3)),
    ("next_velocities", "float64", ("n", 3)),
)
#: the state inputs, given per step; the other inputs are the constant mesh tensors
STATE = ("positions", "velocities", "external_force")


def tet_volumes(vertices, tets):
    """(m,) float64 unsigned tet volumes in m^3."""
    return np.abs(_signed_volumes(vertices, tets))


def _signed_volumes(vertices, tets):
    """(m,) float64 signed tet volumes in m^3 (negative for a tet ordered the other way)."""
    a, b, c, d = (vertices[tets[:, i]] for i in range(4))
    return np.einsum("ij,ij->i", np.cross(b - a, c - a), d - a) / 6.0


def lumped_masses(vertices, tets, density):
    """(n,) float64 vertex masses in kg: density (kg/m^3, scalar or (m,)) * volume / 4 of every
    tet to each of its vertices."""
    quarter = density * tet_volumes(vertices, tets) / 4.0
    return np.bincount(tets.ravel(), weights=np.repeat(quarter, 4), minlength=vertices.shape[0])


def shape_gradients(vertices, tets):
    """(m, 4, 3) float64 gradients of the linear shape functions of each tet, 1/m (row a is
    grad N_a): rows 1-3 are the rows of Dm^-1, Dm = [X_1 - X_0, X_2 - X_0, X_3 - X_0]; row 0 is
    minus their sum (the rows of an affine partition of unity sum to zero)."""
    corner = vertices[tets]
    inverse = np.linalg.inv(np.transpose(corner[:, 1:] - corner[:, :1], (0, 2, 1)))
    return np.concatenate([-inverse.sum(axis=1, keepdims=True), inverse], axis=1)


def tet_tensors(vertices, tets, mu, lam, fiber_direction, fiber_stiffness):
    """The per-tet constants of the elastic force (module docstring), a dict of float64 and
    int64 arrays. vertices (n, 3) m; tets (m, 4); mu, lam, fiber_stiffness (m,) Pa;
    fiber_direction (m, 3) unit."""
    material = np.stack([tet_volumes(vertices, tets), mu, lam, fiber_stiffness], axis=1)
    return {"tets": tets, "tet_gradients": shape_gradients(vertices, tets),
            "tet_material": material, "tet_fiber": np.asarray(fiber_direction, np.float64),
            "corners": incoming_table(tets.ravel(), vertices.shape[0])}


def mesh_tensors(vertices, tets, masses, fixed, fixed_positions, fiber_direction,
                 fiber_stiffness, mu, lam):
    """The constant inputs of the model, a dict keyed by INPUTS names: index arrays int64, real
    ones float64 (cast them to INPUTS' dtypes to feed the model).

    vertices (n, 3) m; tets (m, 4); masses (n,) kg; fixed (n, 3) bool; fixed_positions (n, 3) m;
    fiber_direction (m, 3) unit; fiber_stiffness, mu, lam (m,) Pa (Lame parameters)."""
    edges = mesh_edges(tets)
    senders, receivers = directed_edges(edges)
    rest = rest_features(vertices, senders, receivers)
    incoming = incoming_table(receivers, vertices.shape[0])
    real = np.float64
    return {"senders": senders, "receivers": receivers, "rest": rest,
            "fiber": edge_fibers(tets, edges, fiber_direction, fiber_stiffness),
            "incoming": incoming, "incoming_weights": incoming_weights(incoming, rest[:, :3]),
            "mass": np.asarray(masses, dtype=real).reshape(-1, 1),
            "fixed": np.asarray(fixed, dtype=real),
            "fixed_positions": np.asarray(fixed_positions, dtype=real),
            "rest_positions": np.asarray(vertices, dtype=real),
            **tet_tensors(vertices, tets, mu, lam, fiber_direction, fiber_stiffness)}


def surface_triangles(vertices, tets):
    """(k, 3) int64 the boundary faces of tets (m, 4) (faces of exactly one tet), each ordered
    so that its normal (x1 - x0) x (x2 - x0) points out of its tet at vertices (n, 3)."""
    tets = np.asarray(tets, dtype=np.int64)
    faces = tets[:, [[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]]].reshape(-1, 3)
    opposite = tets.ravel()
    _, first, counts = np.unique(np.sort(faces, axis=1), axis=0, return_index=True,
                                 return_counts=True)
    keep = first[counts == 1]
    faces, opposite = faces[keep], opposite[keep]
    x0, x1, x2 = (vertices[faces[:, i]] for i in range(3))
    inward = np.einsum("ij,ij->i", np.cross(x1 - x0, x2 - x0), vertices[opposite] - x0) > 0
    faces[inward] = faces[inward][:, [0, 2, 1]]
    return faces


#: the baked-scene file format (export.writers.bake.write_arrays / read_arrays)
ARRAYS_FORMAT = "anisognn-arrays-1"
#: numpy dtypes a baked file may hold, by the names its header uses
ARRAY_DTYPES = {"float64": "<f8", "float32": "<f4", "int64": "<i8", "int32": "<i4",
                "uint8": "u1"}


ARRAY_ALIGNMENT = 8


def read_arrays(path):
    """(header dict, {name: numpy array}) of the files PATH.json and PATH.bin written by
    export.writers.bake.write_arrays(path, ...). ValueError naming the file and what is wrong where
    the header is not complete JSON or not an arrays header, the .bin is missing, or an array's
    dtype, shape or place in the .bin is not one numpy can read."""
    name = f"{path}.json"
    try:
        with open(name) as f:
            header = json.load(f)
    except json.JSONDecodeError as err:
        raise ValueError(f"path: {name} is not complete JSON ({err.msg} at line {err.lineno}, "
                         f"column {err.colno}): a truncated or binary file?") from None
    except UnicodeDecodeError:
        raise ValueError(f"path: {name} is not a text file") from None
    if not isinstance(header, dict) or header.get("format") != ARRAYS_FORMAT:
        found = header.get("format") if isinstance(header, dict) else None
        raise ValueError(f"path: {name} is not an {ARRAYS_FORMAT!r} header (format {found!r})")
    table = header.get("arrays")
    if not isinstance(table, dict) or not isinstance(header.get("bin"), str):
        raise ValueError(f"path: {name} has no \"arrays\" table or no \"bin\" file name")
    bin_path = os.path.join(os.path.dirname(str(path)), header["bin"])
    if not os.path.exists(bin_path):
        raise ValueError(f"path: {name} names its arrays' file {bin_path}, and it is missing")
    data = np.fromfile(bin_path, dtype=np.uint8)
    arrays = {}
    for key, spec in table.items():
        try:
            dtype = np.dtype(ARRAY_DTYPES[spec["dtype"]])
            shape = tuple(spec["shape"])
            offset = spec["offset"]
        except (KeyError, TypeError):
            raise ValueError(f"path: {name}: array {key} has no dtype of "
                             f"{sorted(ARRAY_DTYPES)}, shape or offset") from None
        if not all(isinstance(d, int) and d >= 0 for d in shape) or not isinstance(offset, int):
            raise ValueError(f"path: {name}: array {key} has shape {list(shape)} and offset "
                             f"{offset!r}: whole numbers >= 0 expected")
        size = int(np.prod(shape, dtype=np.int64)) * dtype.itemsize
        if offset % ARRAY_ALIGNMENT or offset < 0:
            raise ValueError(f"path: {name}: array {key} starts at offset {offset}, not a "
                             f"multiple of {ARRAY_ALIGNMENT}")
        if offset + size > data.size:
            raise ValueError(f"path: {name}: array {key} ({size} bytes at offset {offset}) runs "
                             f"past the end of the {data.size}-byte .bin file")
        arrays[key] = np.frombuffer(data, dtype=dtype, count=size // dtype.itemsize,
                                    offset=offset).reshape(shape)
    return header, arrays


def checked(path, header, arrays, spec):
    """arrays checked against spec, {name: (dtype, shape)}, each shape a tuple of numbers and
    names (a name stands for one size wherever it appears; "n" is the header's n where it
    states one; None: any size); float64 arrays must be finite. Returns the sizes the names
    stand for; ValueError naming the file and the array otherwise."""
    name = f"{path}.json"
    sizes = {"n": header["n"]} if isinstance(header.get("n"), int) else {}
    for key, (dtype, shape) in spec.items():
        if key not in arrays:
            raise ValueError(f"path: {name} has no array {key} (a model file needs "
                             f"{', '.join(spec)})")
        a = arrays[key]
        if a.dtype != np.dtype(dtype):
            raise ValueError(f"path: {name}: array {key} is {a.dtype}, expected {dtype}")
        if a.ndim != len(shape):
            raise ValueError(f"path: {name}: array {key} has {a.ndim} dimensions, expected "
                             f"{len(shape)}")
        for size, want in zip(a.shape, shape):
            if isinstance(want, str):
                want = sizes.setdefault(want, size)
            if want is not None and size != want:
                raise ValueError(f"path: {name}: array {key} has shape {a.shape}, expected "
                                 f"{_shape_text(shape, sizes)}")
        if a.dtype == np.float64 and not np.isfinite(a).all():
            raise ValueError(f"path: {name}: array {key} holds a non-finite number at entry "
                             f"{int(np.flatnonzero(~np.isfinite(a.ravel()))[0])}")
    return sizes


def _shape_text(shape, sizes):
    return "(" + ", ".join(str(sizes.get(d, d)) if d is not None else "any" for d in shape) + ")"


class OnnxSimulator:
    """A tet mesh stepped by an exported anisognn model (backward-Euler steps of the model's dt).

    model_path: the .onnx file. vertices (n, 3) m, rest positions; tets (m, 4) vertex indices.
    fixed: held vertices, as None (none), indices (k,), a bool mask (n,) or a per-component bool
    mask (n, 3); held components stay at their rest positions. density: kg/m^3, scalar or (m,).
    fiber_direction: (3,) or (m, 3), normalized here (None: no fiber); fiber_stiffness: Pa,
    scalar or (m,). session_options, providers: passed to onnxruntime.InferenceSession (default:
    onnxruntime's default threading, denormals flushed to zero; the CPU provider).
    """

    def __init__(self, model_path, vertices, tets, fixed=None, density=1000.0,
                 fiber_direction=None, fiber_stiffness=0.0, session_options=None,
                 providers=None):
        import onnxruntime
        vertices = _real(vertices, "vertices", (None, 3))
        n = vertices.shape[0]
        tets = _tets(tets, vertices)
        m = tets.shape[0]
        density = _per_tet(density, "density", m, positive=True)
        direction, stiffness = _fibers(fiber_direction, fiber_stiffness, m)
        self.fixed = _fixed(fixed, n)
        self.rest_positions = vertices
        self.tets = tets
        self._rest_signed = _signed_volumes(vertices, tets)
        self.masses = lumped_masses(vertices, tets, density)
        if session_options is None:
            session_options = onnxruntime.SessionOptions()
            # flush denormals (SiLU of very negative inputs): x86 computes them on a slow path,
            # and values under 1e-38 change nothing here
            session_options.add_session_config_entry("session.set_denormal_as_zero", "1")
        if not os.path.isfile(model_path):
            raise FileNotFoundError(f"model_path: no such file {str(model_path)!r}")
        try:
            self.session = onnxruntime.InferenceSession(
                str(model_path), sess_options=session_options,
                providers=providers or ["CPUExecutionProvider"])
        except Exception as err:  # onnxruntime raises its own Fail / InvalidGraph types
            raise ValueError(f"model_path: onnxruntime cannot load {str(model_path)!r}: "
                             f"{str(err)[:300]}") from None
        self.metadata = dict(self.session.get_modelmeta().custom_metadata_map)
        _check_model(self.session, self.metadata, model_path)
        self.dt = float(self.metadata["dt"])
        mu, lam = _lame(json.loads(self.metadata["trained_material"]))
        tensors = mesh_tensors(vertices, tets, self.masses, self.fixed, vertices, direction,
                               stiffness, np.full(m, mu), np.full(m, lam))
        #: every constant mesh tensor, cast to its INPUTS dtype
        self.constants = {name: tensors[name].astype(dtype) for name, dtype, _ in INPUTS
                          if name in tensors}
        # the ones this model reads (the exporter drops the others)
        wanted = {i.name for i in self.session.get_inputs()}
        self._feed = {name: value for name, value in self.constants.items() if name in wanted}

    @property
    def n_vertices(self):
        return self.rest_positions.shape[0]

    def run(self, x, v, external_force):
        """(acceleration float32, next positions, next velocities), each (n, 3), from positions
        x (n, 3) m, velocities v (n, 3) m/s and external_force (n, 3) N per vertex."""
        n = self.n_vertices
        feed = dict(self._feed)
        for name, value in zip(STATE, (x, v, external_force)):
            feed[name] = _real(value, name, (n, 3))
        return tuple(self.session.run(None, feed))

    def step(self, x, v, external_force):
        """(x, v) one step of dt later: positions (n, 3) m and velocities (n, 3) m/s."""
        _, x_next, v_next = self.run(x, v, external_force)
        if not (np.isfinite(x_next).all() and np.isfinite(v_next).all()):
            raise FloatingPointError("step: the model predicted a non-finite state")
        return x_next, v_next

    def inversion(self, x):
        """(tets turned inside out, smallest volume ratio det F) at positions x (n, 3) m: a state
        with inverted tets is not physical. Costs one pass over the tets (numpy)."""
        ratio = _signed_volumes(_real(x, "x", (self.n_vertices, 3)), self.tets) / self._rest_signed
        return int((ratio <= 0).sum()), float(ratio.min())

    def rollout(self, steps, external_force, x0=None, v0=None):
        """Positions of every step, (steps + 1, n, 3) m, from x0 (default rest) and v0
        (default 0) under a constant external_force (n, 3) N per vertex."""
        steps = int(steps)
        if steps < 0:
            raise ValueError(f"steps: must be >= 0, got {steps}")
        x = self.rest_positions if x0 is None else _real(x0, "x0", (self.n_vertices, 3))
        v = np.zeros_like(x) if v0 is None else _real(v0, "v0", (self.n_vertices, 3))
        out = np.empty((steps + 1,) + x.shape)
        out[0] = x
        for k in range(steps):
            x, v = self.step(x, v, external_force)
            out[k + 1] = x
        return out


#: The header format of a reduced model's arrays files (export.writers.reduced writes them).
REDUCED_FORMAT = "anisofem-reduced-1"
#: A step has converged where its reduced gradient is below FLOOR eps r |(|H| |q| + |f| + |c1|)|,
#: the round-off bound of its sum, whatever rtol asks (float32: 0.43% of the deflection off
#: float64 over 200 steps of the 200-tet cantilever at 1; 2.2% at 16, which stopped at the
#: first iterate; 0.04% at 0.1, which failed at 0.01).
FLOOR = 1.0
#: The contact's round-off floor: CONTACT_FLOOR eps R |H_contact| (R the largest coordinate),
#: and the share of its energy below which two values of it are round-off (anisofem.reduced.
#: contact).
CONTACT_FLOOR, CONTACT_NOISE = 2.0, 1e-12


class ReducedSimulator:
    """A scene's reduced model (anisofem.reduced, written by `python -m export reduced`)
    stepped by backward Euler with numpy alone: positions x = rest_positions + basis q, and the
    exact elastic energy V(q) = c0 + c1 . q + q^T C2 q / 2 + S3[q, q, q] + S4[q, q, q, q], a
    quartic in the r reduced coordinates (W4 holds S4[a, b, c, :] for the sorted triples a <=
    b <= c in lexicographic order).

        sim = ReducedSimulator("cantilever")              # cantilever.json + cantilever.bin
        force = sim.masses[:, None] * (0.0, 0.0, -9.81)   # N per vertex, may change each step
        q, w = sim.rest_state()
        for _ in range(100):
            q, w = sim.step(q, w, force, dt=0.02)
        x = sim.positions(q)                              # (n, 3), m

    path: the arrays files without extension. vertices (n, 3), tets (m, 4): when given, the
    mesh the caller steps, refused unless it is the one the model was built for. dtype:
    float64 (the library's numbers) or float32 (the coefficients and the state rounded to it).
    angle: for a file of models at several fiber angles (`python -m export bake-reduced`),
    the one to step, degrees.
    controls: the names of the model's controls (named pressures, Pa; activations, in [0,
    1)), and control_values their values now (the file's until set_controls, or a step's
    controls, sets them for every later step).
    A step is Newton on the reduced backward-Euler potential with the Hessian's negative
    eigenvalues clamped and an Armijo search on the exact quartic along the step, to a reduced
    gradient of rtol times the step's force size; it raises where it fails.
    """

    def __init__(self, path, vertices=None, tets=None, dtype=np.float64, angle=None):
        header, arrays = read_arrays(path)
        if header.get("model_format") != REDUCED_FORMAT:
            raise ValueError(f"path: {path}.json holds no reduced model (model_format "
                             f"{header.get('model_format')!r}, expected {REDUCED_FORMAT!r})")
        tag = _angle_tag(header, angle)
        r = checked(path, header, arrays, {**MESH_ARRAYS, **{
            "basis" + tag: ("float64", ("n", 3, "r")), "c1" + tag: ("float64", ("r",)),
            "C2" + tag: ("float64", ("r", "r")), "S3" + tag: ("float64", ("r", "r", "r")),
            "W4" + tag: ("float64", ("T", "r"))}})["r"]
        if arrays["W4" + tag].shape[0] != r * (r + 1) * (r + 2) // 6:
            raise ValueError(f"path: {path}.json: array W4{tag} has {arrays['W4' + tag].shape[0]} "
                             f"rows, expected r (r + 1) (r + 2) / 6 = {r * (r + 1) * (r + 2) // 6}")
        if isinstance(header.get("r"), int) and header["r"] != r:
            raise ValueError(f"path: {path}.json: the header says r = {header['r']}, and array "
                             f"basis has {r} columns")
        _check_mesh(path, header, arrays)
        self.header = header
        dtype = np.dtype(dtype)
        if dtype not in (np.float64, np.float32):
            raise ValueError(f"dtype: float64 or float32, got {dtype}")
        self.dtype = dtype
        self.rest_positions = np.array(arrays["rest_positions"], dtype=np.float64)
        self.masses = np.array(arrays["masses"])
        self.held = arrays["held"].astype(bool)
        self.surface = np.array(arrays["surface"])
        _same_mesh(arrays, vertices, tets)
        self.basis = np.array(arrays["basis" + tag], dtype=dtype)    # (n, 3, r)
        self.r = r
        self.c1, self.C2 = (np.array(arrays[k + tag], dtype=dtype) for k in ("c1", "C2"))
        self.S3 = np.array(arrays["S3" + tag], dtype=dtype).reshape(r * r, r)
        self.W4 = np.array(arrays["W4" + tag], dtype=dtype)
        self.triples = _triple_rows(r)
        self._read_controls(path, header, arrays, r)
        self.contact = (Contact(path, header, arrays, r, dtype) if header.get("contact")
                        else None)

    @property
    def obstacles(self):
        """The names of the model's obstacles (none without contact)."""
        return self.contact.names() if self.contact is not None else ()

    def move_obstacle(self, which, position):
        """Move obstacle `which` (a name or an index) to `position` (3,), m (a plane's
        point, a sphere's or box's center, a capsule's end a): reached at the next step as far
        as the body lets it, the rest at later steps."""
        names = self.obstacles
        i = names.index(which) if which in names else which
        if not isinstance(i, (int, np.integer)) or not 0 <= i < len(names):
            raise ValueError(f"obstacle: no obstacle {which!r}; the model has: "
                             f"{', '.join(names) or 'none'}")
        self.contact.move(int(i), position)

    def _read_controls(self, path, header, arrays, r):
        """The control arrays (export.writers.reduced), checked; none where the header lists
        no controls."""
        names = header.get("controls") or []
        if not isinstance(names, list) or not all(isinstance(n, str) for n in names):
            raise ValueError(f"path: {path}.json: controls: expected a list of names")
        self.controls = tuple(names)
        k = len(names)
        self._kinds = np.zeros(0, np.uint8)
        self.control_values = np.zeros(0)
        self._coefficients = self.c1, self.C2, self.S3
        self._cables = []
        if not k:
            return
        checked(path, header, arrays, {"control_kinds": ("uint8", (k,)),
                                       "control_values": ("float64", (k,)),
                                       "control_c1": ("float64", (k, r)),
                                       "control_C2": ("float64", (k, r, r))})
        self._kinds = np.array(arrays["control_kinds"])
        if (self._kinds > TENSION).any() or (np.diff(self._kinds.astype(int)) < 0).any():
            raise ValueError(f"path: {path}.json: array control_kinds: 0 (pressures), 1 "
                             f"(activations) then 2 (cables) expected, got "
                             f"{self._kinds.tolist()}")
        pressures = int((self._kinds == PRESSURE).sum())
        checked(path, header, arrays, {"control_S3": ("float64", (pressures, r, r, r))})
        self._parts = tuple(np.array(arrays[key], dtype=self.dtype) for key in
                            ("control_c1", "control_C2", "control_S3"))
        self._parts = self._parts[:2] + (self._parts[2].reshape(pressures, r * r, r),)
        cables = int((self._kinds == TENSION).sum())
        if cables:
            sizes = checked(path, header, arrays, {"cable_segments": ("int32", (cables,)),
                                                   "cable_a": ("float64", ("S", 3)),
                                                   "cable_D": ("float64", ("S", 3, r))})
            counts = arrays["cable_segments"]
            if (counts < 1).any() or counts.sum() != sizes["S"]:
                raise ValueError(f"path: {path}.json: array cable_segments {counts.tolist()} "
                                 f"does not count the {sizes['S']} rows of cable_a")
            ends = np.cumsum(counts)
            self._cables = [(np.array(arrays["cable_a"][e - c:e]),
                             np.array(arrays["cable_D"][e - c:e], dtype=self.dtype))
                            for c, e in zip(counts, ends)]
        self.control_values = np.zeros(k)
        self.set_controls(np.array(arrays["control_values"]))

    def _check_control(self, i, value):
        """Control i's value as a float; ValueError naming it where it is not finite, an
        activation outside [0, 1) or a negative tension."""
        value = float(value)
        kind = self._kinds[i]
        if kind == ACTIVATION and not 0.0 <= value < 1.0:
            raise ValueError(f"controls: {self.controls[i]!r} is an activation, in [0, 1); "
                             f"got {value!r}")
        if kind == TENSION and not value >= 0.0:
            raise ValueError(f"controls: {self.controls[i]!r} is a cable, a tension >= 0 N; "
                             f"got {value!r}")
        if not np.isfinite(value):
            raise ValueError(f"controls: {self.controls[i]!r} is a pressure, a finite number "
                             f"of Pa; got {value!r}")
        return value

    def _pulled(self):
        """[(a (s, 3), D (s, 3, r), T)] of the cables pulled now."""
        tensions = self.control_values[self._kinds == TENSION]
        return [(a, D, T) for (a, D), T in zip(self._cables, tensions) if T > 0]

    def set_controls(self, values):
        """Set the controls for every later step: a mapping name -> value (the others keep
        theirs) or one value per control, in the order of `controls`. ValueError naming the
        control for an unknown name, a value that is not finite or an activation outside
        [0, 1) (the controls unchanged)."""
        now = control_vector(values, self.controls, self.control_values)
        now = np.array([self._check_control(i, v) for i, v in enumerate(now)])
        if not self.controls:
            return
        beta = np.select([self._kinds == PRESSURE, self._kinds == ACTIVATION],
                         [now, now * (2.0 - now)], 0.0).astype(self.dtype)
        c1p, C2p, S3p = self._parts
        self._coefficients = (self.c1 + beta @ c1p, self.C2 + np.tensordot(beta, C2p, axes=1),
                              self.S3 + np.tensordot(beta[:len(S3p)], S3p, axes=1))
        self.control_values = now

    def rest_state(self):
        """(q, w): the reduced coordinates and velocities of the rest state, zeros (r,)."""
        return np.zeros(self.r, dtype=self.dtype), np.zeros(self.r, dtype=self.dtype)

    def positions(self, q):
        """Full positions (n, 3) float64, m, of reduced coordinates q (r,)."""
        return self.rest_positions + self.basis @ q

    def project(self, force):
        """The reduced force (r,) of nodal forces (n, 3), N (0 on held components)."""
        force = _real(force, "force", self.rest_positions.shape)
        return np.tensordot(force, self.basis, axes=([0, 1], [0, 1])).astype(self.dtype)

    def step(self, q, w, force, dt, rtol=1e-8, max_iter=50, controls=None):
        """One backward-Euler step of dt s from (q, w) under nodal forces `force` (n, 3), N,
        with the controls set to `controls` first (see set_controls; None: as they are):
        returns (q_next, w_next); the last step's Newton iterations are in
        self.iterations."""
        if not dt > 0:
            raise ValueError(f"dt: the time step must be > 0 s, got {dt}")
        if controls is not None:
            self.set_controls(controls)
        c1, C2, S3 = self._coefficients
        q = np.asarray(q, dtype=self.dtype)
        w = np.asarray(w, dtype=self.dtype)
        load = self.project(force)
        q_hat = q + dt * w
        inertia = 1.0 / dt ** 2
        tolerance = rtol * (_norm(load) + _norm(w) / dt)
        eps = np.finfo(self.dtype).eps
        x = q_hat.copy()
        contact = self.contact
        if contact is not None:     # friction lagged at the step's start, clear of the obstacles
            start = contact.positions(q)
            contact.advance(start)
            friction, smooth = contact.lagged(start, dt), contact.smoothing * dt
            x = q + contact.limit(start, contact.U @ (q_hat - q)) * (q_hat - q)
        A = self.W4 @ x
        pulled = self._pulled()
        for it in range(max_iter + 1):
            gathered = A[self.triples].reshape(self.r * self.r, self.r)  # S4[a, b, c, x]
            X = (gathered @ x).reshape(self.r, self.r)
            Y = (S3 @ x).reshape(self.r, self.r)
            g = c1 + (C2 + 3.0 * Y + 4.0 * X) @ x
            extra_g, extra_H = _cable_terms(pulled, x, self.r)
            floor = 0.0
            if contact is not None:
                xs = contact.positions(x)
                touch, gs = contact.energy(xs, friction, smooth)
                contact_g = np.einsum("kir,ki->r", contact.U, gs)
                contact_H = contact.hessian(xs, friction, smooth)
                extra_g, extra_H = extra_g + contact_g, extra_H + contact_H
                floor = CONTACT_FLOOR * eps * float(np.abs(xs).max()) * _norm(contact_H.ravel())
            if pulled or contact is not None:
                g = g + extra_g
            if it == 0:
                tolerance += rtol * _norm(g)
            g += inertia * (x - q_hat) - load
            H = C2 + 6.0 * Y + 12.0 * X + inertia * np.eye(self.r, dtype=self.dtype)
            residual = _norm(g)
            if not np.isfinite(residual):
                raise FloatingPointError("step: the reduced force is not finite")
            terms = np.abs(H + extra_H) @ np.abs(x) + np.abs(load) + np.abs(c1)
            if residual <= max(tolerance, floor, FLOOR * eps * self.r * _norm(terms)):
                self.iterations = it
                return x, (x - q) / dt
            if it == max_iter:
                break
            p = -_positive_solve(H + extra_H, g)
            a1 = float(g @ p)
            if not a1 < 0:
                break
            a2 = 0.5 * float(p @ H @ p)              # the quartic's part (with inertia)
            pull = float(extra_g @ p)
            Ap = self.W4 @ p
            mixed = float(((gathered @ p).reshape(self.r, self.r) @ p) @ p)
            pure = float(((Ap[self.triples].reshape(self.r * self.r, self.r) @ p)
                          .reshape(self.r, self.r) @ p) @ p)
            a3 = float(p @ (S3 @ p).reshape(self.r, self.r) @ p) + 4.0 * mixed
            t = 1.0

            def change(t):       # the terms beside the quartic, from t p
                total = _cable_change(pulled, x, t * p)
                if contact is not None:
                    after = contact.energy(contact.positions(x + t * p), friction, smooth)[0]
                    linear = t * float(contact_g @ p)
                    total += (linear if np.isfinite(after) and abs(after - touch - linear)
                              <= CONTACT_NOISE * max(abs(after), abs(touch)) else after - touch)
                return total
            if contact is not None:
                t = min(1.0, contact.limit(xs, contact.U @ p))
            while (t * (a2 + t * (a3 + t * pure)) + (change(t) / t - pull)
                   > -(1.0 - 1e-4) * a1 and t >= 1e-12):
                t *= 0.5
            if t < 1e-12:
                break
            x = x + t * p
            A = A + t * Ap
        raise FloatingPointError(f"step: Newton stopped at a reduced gradient of {residual:.3g} "
                                 f"after {it} iterations (tolerance {tolerance:.3g})")


class Contact:
    """A reduced model's contact with rigid obstacles (the file's contact entry and arrays;
    anisofem.physics.contact's method, written again with numpy alone): the IPC barrier
    kappa A b(d), b(d) = -(d - dhat)^2 ln(d / dhat), at the surface nodes x_s = rest + U q,
    friction lagged at a step's start (mu lambda f0(|T (x - x_n)|), f0 smoothed below eps =
    smoothing dt), and the largest share of a step that keeps every node at KEEP of its
    distance from every obstacle (Newton on the convex distance along the move).

    obstacles: [{kind, name, friction, and its geometry as numpy arrays}], their positions
    now; move(i, position) sets where obstacle i is to be (a plane's point, a sphere's or a
    box's center, a capsule's end a: translations), reached at the next step as far as the
    body lets it (advance)."""

    KEEP = 0.1

    def __init__(self, path, header, arrays, r, dtype):
        names = header.get("obstacles")
        if not isinstance(names, list) or not all(isinstance(n, str) for n in names):
            raise ValueError(f"path: {path}.json: obstacles: expected a list of names")
        checked(path, header, arrays, {"contact_rest": ("float64", ("k", 3)),
                                       "contact_basis": ("float64", ("k", 3, "r")),
                                       "contact_area": ("float64", ("k",)),
                                       "contact_constants": ("float64", (4,)),
                                       "obstacle_kinds": ("uint8", (len(names),)),
                                       "obstacle_geometry": ("float64", (len(names), 15)),
                                       "obstacle_friction": ("float64", (len(names),))})
        self.x0 = np.array(arrays["contact_rest"])
        self.U = np.array(arrays["contact_basis"], dtype=dtype)
        self.area = np.array(arrays["contact_area"])
        self.dhat, self.kappa, self.mu, self.smoothing = (float(v) for v in
                                                          arrays["contact_constants"])
        kinds = tuple(OBSTACLE_KINDS)
        self.obstacles = []
        for name, code, row, mu in zip(names, arrays["obstacle_kinds"],
                                       arrays["obstacle_geometry"], arrays["obstacle_friction"]):
            if code >= len(kinds):
                raise ValueError(f"path: {path}.json: array obstacle_kinds: obstacle {name!r} "
                                 f"has kind {code}, expected 0 to {len(kinds) - 1}")
            entry = {"kind": kinds[code], "name": name, "friction": None if mu < 0 else mu}
            at = 0
            for key, size in OBSTACLE_KINDS[kinds[code]]:
                entry[key] = np.array(row[at:at + size]) if size > 1 else float(row[at])
                at += size
            if entry["kind"] == "box":
                entry["rotation"] = entry["rotation"].reshape(3, 3)
            self.obstacles.append(entry)
        self.targets = [None] * len(self.obstacles)

    def names(self):
        return tuple(o["name"] for o in self.obstacles)

    def move(self, i, position):
        """Obstacle i to be at `position` (3,), m, from the next step on."""
        self.targets[i] = _real(position, f"obstacle {self.obstacles[i]['name']!r} position",
                                (3,))

    def positions(self, q):
        return self.x0 + self.U @ q

    def advance(self, xs):
        """Move each obstacle toward its target as far as the nodes at xs (k, 3) let it: the
        share of the move that keeps every node at KEEP of its distance (the body held)."""
        for i, (o, target) in enumerate(zip(self.obstacles, self.targets)):
            o["shift"] = np.zeros(3)
            if target is None:
                continue
            key = OBSTACLE_KINDS[o["kind"]][0][0]
            delta = target - o[key]
            d, _, _ = obstacle_geometry(o, xs, False)
            share = float(first_touch(o, xs, np.broadcast_to(-delta, xs.shape),
                                      self.KEEP * d).min(initial=1.0))
            o[key] = o[key] + share * delta
            o["shift"] = share * delta
            if o["kind"] == "capsule":
                o["b"] = o["b"] + share * delta
            self.targets[i] = None if share >= 1.0 else target

    def lagged(self, xs, dt):
        """The friction of a step of dt s lagged at xs (k, 3): [(mu lambda, rows, T, x_lag)],
        x_lag moved with its obstacle's move at the step's start."""
        out = []
        for o in self.obstacles:
            mu = self.mu if o["friction"] is None else float(o["friction"])
            if mu <= 0:
                continue
            d, n, _ = obstacle_geometry(o, xs, False)
            rows = np.flatnonzero((d > 0) & (d < self.dhat))
            if rows.size:
                force = -self.kappa * self.area[rows] * _barrier_slope(d[rows], self.dhat)
                T = np.eye(3) - n[rows, :, None] * n[rows, None, :]
                out.append((mu * force, rows, T, xs[rows] + o.get("shift", 0.0)))
        return out

    def energy(self, xs, friction, eps):
        """(energy J, gradient (k, 3) N) at the nodes xs (k, 3); inf where one reached an
        obstacle."""
        total, g = 0.0, np.zeros_like(xs)
        for o in self.obstacles:
            d, n, _ = obstacle_geometry(o, xs, False)
            if (d <= 0).any():
                return np.inf, g
            near = d < self.dhat
            a, dn = self.area[near], d[near]
            total += self.kappa * float(a @ (-(dn - self.dhat) ** 2 * np.log(dn / self.dhat)))
            g[near] += (self.kappa * a * _barrier_slope(dn, self.dhat))[:, None] * n[near]
        for weight, rows, T, start in friction:
            u = np.einsum("kij,kj->ki", T, xs[rows] - start)
            y = np.sqrt(np.einsum("ij,ij->i", u, u))
            total += float(weight @ np.where(y < eps, -y ** 3 / (3 * eps * eps) + y * y / eps
                                             + eps / 3.0, y))
            g[rows] += (weight * _friction_slope(y, eps))[:, None] * u
        return total, g

    def hessian(self, xs, friction, eps):
        """(r, r) the reduced Hessian of the barrier and friction at xs: each node's exact
        3 x 3 block projected on its basis rows (the step clamps the whole Hessian)."""
        H = np.zeros((len(xs), 3, 3))
        for o in self.obstacles:
            d, n, curvature = obstacle_geometry(o, xs, True)
            near = (d > 0) & (d < self.dhat)
            a, dn, nn = self.area[near], d[near], n[near]
            b1 = _barrier_slope(dn, self.dhat)
            b2 = (-2.0 * np.log(dn / self.dhat) - 4.0 * (dn - self.dhat) / dn
                  + (dn - self.dhat) ** 2 / (dn * dn))
            H[near] += self.kappa * a[:, None, None] * (
                b2[:, None, None] * nn[:, :, None] * nn[:, None, :]
                + b1[:, None, None] * curvature[near])
        for weight, rows, T, start in friction:
            u = np.einsum("kij,kj->ki", T, xs[rows] - start)
            y = np.sqrt(np.einsum("ij,ij->i", u, u))
            unit = u / np.maximum(y, 1e-300)[:, None]
            along = np.where(y < eps, -y / (eps * eps), -1.0 / np.maximum(y, 1e-300))
            H[rows] += weight[:, None, None] * (_friction_slope(y, eps)[:, None, None] * T
                                                + along[:, None, None] * unit[:, :, None]
                                                * unit[:, None, :])
        live = np.flatnonzero(np.abs(H).reshape(len(H), -1).max(axis=1) > 0)
        return np.einsum("kir,kij,kjs->rs", self.U[live], H[live], self.U[live])

    def limit(self, xs, ds):
        """The largest share in (0, 1] of the move ds (k, 3) from xs keeping every node at
        KEEP of its distance from every obstacle."""
        moving = np.einsum("ij,ij->i", ds, ds) > 0
        share = 1.0
        for o in self.obstacles:
            d, _, _ = obstacle_geometry(o, xs[moving], False)
            share = min(share, float(first_touch(o, xs[moving], ds[moving],
                                                 self.KEEP * d).min(initial=1.0)))
        return share


#: Each obstacle kind (in the order of obstacle_kinds' codes) and its geometry's entries in a
#: row of obstacle_geometry, with their sizes; the first is where it is.
OBSTACLE_KINDS = {"plane": (("point", 3), ("normal", 3)),
                  "sphere": (("center", 3), ("radius", 1)),
                  "box": (("center", 3), ("half", 3), ("rotation", 9)),
                  "capsule": (("a", 3), ("b", 3), ("radius", 1))}


def obstacle_geometry(o, x, curvature):
    """(d (k,), normal (k, 3), Hessian of d (k, 3, 3) or None) of points x (k, 3) from the
    obstacle o: a plane's signed distance; a sphere, capsule or box as a convex core (point,
    segment, box) grown by a radius, from the core's closest point."""
    k = len(x)
    if o["kind"] == "plane":
        return ((x - o["point"]) @ o["normal"], np.broadcast_to(o["normal"], x.shape),
                np.zeros((k, 3, 3)) if curvature else None)
    J = np.zeros((k, 3, 3))
    inside = np.zeros(k, bool)
    radius = 0.0
    if o["kind"] == "sphere":
        c, radius = np.broadcast_to(o["center"], x.shape), float(o["radius"])
    elif o["kind"] == "capsule":
        axis = o["b"] - o["a"]
        length = float(np.linalg.norm(axis))
        axis = axis / length
        t = (x - o["a"]) @ axis
        c = o["a"] + np.clip(t, 0.0, length)[:, None] * axis
        J[(t > 0) & (t < length)] = np.outer(axis, axis)
        radius = float(o["radius"])
    else:
        R = o["rotation"]
        local = (x - o["center"]) @ R
        within = np.abs(local) < o["half"]
        c = o["center"] + np.clip(local, -o["half"], o["half"]) @ R.T
        J = np.einsum("ia,ka,ja->kij", R, within.astype(float), R)
        inside = within.all(axis=1)
    r = x - c
    delta = np.sqrt(np.einsum("ij,ij->i", r, r))
    safe = np.where(delta > 0, delta, 1.0)
    n = r / safe[:, None]
    d = delta - radius
    if inside.any():       # within a box: minus the depth to its nearest face
        local = (x[inside] - o["center"]) @ o["rotation"]
        depth = o["half"] - np.abs(local)
        axis = np.argmin(depth, axis=1)
        rows = np.arange(len(axis))
        d[inside] = -depth[rows, axis]
        n[inside] = o["rotation"][:, axis].T * np.sign(local[rows, axis])[:, None]
    if not curvature:
        return d, n, None
    H = (np.eye(3) - J - n[:, :, None] * n[:, None, :]) / safe[:, None, None]
    H[inside | (delta == 0)] = 0.0
    return d, n, H


def first_touch(o, x, dx, floor):
    """(k,) the largest s in [0, 1] for each point x (k, 3) moving by s dx that keeps its
    distance from obstacle o above floor (k,) all the way: Newton on the convex distance from
    s = 0, which never passes its first root."""
    s = np.zeros(len(x))
    live = np.arange(len(x))
    for _ in range(60):
        if not live.size:
            break
        d, n, _ = obstacle_geometry(o, x[live] + s[live, None] * dx[live], False)
        phi = d - floor[live]
        slope = np.einsum("ij,ij->i", n, dx[live])
        clear = slope >= 0.0
        target = np.where(clear, 1.0, s[live] - phi / np.where(clear, -1.0, slope))
        s[live] = np.minimum(target, 1.0)
        live = live[~(clear | (target >= 1.0) | (phi <= 1e-3 * floor[live]))]
    return s


def _barrier_slope(d, dhat):
    return -2.0 * (d - dhat) * np.log(d / dhat) - (d - dhat) ** 2 / d


def _friction_slope(y, eps):
    """f0'(y) / y of the smoothed friction."""
    return np.where(y < eps, -y / (eps * eps) + 2.0 / eps, 1.0 / np.maximum(y, 1e-300))


def control_vector(values, names, now):
    """The controls' values (k,) after setting `values` (a mapping name -> value, the others
    keeping theirs in now (k,), or one value per name); ValueError for an unknown name or a
    wrong count."""
    out = np.array(now, dtype=float)
    if isinstance(values, dict):
        for name, value in values.items():
            if name not in names:
                raise ValueError(f"controls: no control {name!r}; the model has: "
                                 f"{', '.join(names) or 'none'}")
            out[names.index(name)] = value
        return out
    given = np.asarray(values, dtype=float).ravel()
    if given.size != len(names):
        raise ValueError(f"controls: expected {len(names)} values ({', '.join(names)}), got "
                         f"{given.size}")
    return given


def _cable_terms(pulled, q, r):
    """(g (r,), H (r, r)) of the pulled cables' T L(q), L = sum_j |a_j + D_j q|: T sum_j D_j^T
    t_j and T sum_j D_j^T (I - t_j t_j^T) / l_j D_j."""
    g, H = np.zeros(r), np.zeros((r, r))
    for a, D, T in pulled:
        d = a + D @ q
        l = np.linalg.norm(d, axis=1)
        t = d / np.where(l > 0, l, 1.0)[:, None]
        g += T * np.einsum("si,sir->r", t, D)
        P = (np.eye(3) - t[:, :, None] * t[:, None, :]) / np.where(l > 0, l, np.inf)[:, None,
                                                                                        None]
        H += T * np.einsum("sir,sij,sjt->rt", D, P, D)
    return g, H


def _cable_change(pulled, q, step):
    """sum of T (L(q + step) - L(q)) over the pulled cables, each segment's (2 d . e + |e|^2) /
    (|d + e| + |d|) (no cancellation)."""
    total = 0.0
    for a, D, T in pulled:
        d = a + D @ q
        e = D @ step
        size = np.linalg.norm(d + e, axis=1) + np.linalg.norm(d, axis=1)
        total += T * float(np.sum(np.einsum("si,si->s", 2.0 * d + e, e)
                                  / np.where(size > 0, size, 1.0)))
    return total


def _angle_tag(header, angle):
    """The suffix of the model arrays to read: "" for a file of one model, "@A" for the fiber
    angle A of a file of several."""
    angles = header.get("fiber_angles")
    if angles is None:
        if angle is not None:
            raise ValueError(f"angle: this file holds one model, for its own fiber; got {angle}")
        return ""
    if angle is None or float(angle) not in angles:
        raise ValueError(f"angle: this file holds models at fiber angles {angles} (degrees); "
                         f"got {angle}")
    return f"@{float(angle):g}"


def _triple_rows(r):
    """(r, r, r) int64: the row of W4 (sorted triples a <= b <= c in lexicographic order) of
    every ordered triple."""
    a, b, c = np.sort(np.stack(np.meshgrid(*(np.arange(r),) * 3, indexing="ij")), axis=0)
    # rows before a: sum over a' < a of (r - a')(r - a' + 1) / 2, then within a the pairs b <= c
    first = np.concatenate([[0], np.cumsum([(r - k) * (r - k + 1) // 2 for k in range(r)])])
    within = (b - a) * (2 * (r - a) - (b - a) + 1) // 2 + (c - b)
    return first[a] + within


def _norm(v):
    return float(np.sqrt(np.dot(v, v)))


def _positive_solve(H, g):
    """H^-1 g by Cholesky, or with H's eigenvalues clamped to 1e-8 of the largest where H is
    not positive definite."""
    try:
        L = np.linalg.cholesky(H)
    except np.linalg.LinAlgError:
        w, V = np.linalg.eigh(H)
        w = np.maximum(w, 1e-8 * np.abs(w).max())
        return V @ ((V.T @ g) / w)
    return np.linalg.solve(L.T, np.linalg.solve(L, g))


def _same_mesh(arrays, vertices, tets):
    """Raise ValueError unless vertices (n, 3) and tets (m, 4), where given, are the mesh the
    reduced model was built on."""
    if vertices is not None:
        vertices = _real(vertices, "vertices", (None, 3))
        rest = arrays["rest_positions"]
        if vertices.shape != rest.shape:
            raise ValueError(f"vertices: not the mesh this reduced model was built on (it has "
                             f"{rest.shape[0]} vertices; got {vertices.shape[0]})")
        gap = np.linalg.norm(vertices - rest, axis=1)
        moved = gap > 1e-9 * np.abs(rest).max()
        if moved.any():
            k = int(gap.argmax())
            raise ValueError(f"vertices: not the mesh this reduced model was built on (the same "
                             f"{rest.shape[0]} vertices, {int(moved.sum())} of them elsewhere; "
                             f"the farthest, vertex {k}, is at {vertices[k].tolist()}, "
                             f"{gap[k]:.3g} m from its rest position {rest[k].tolist()})")
    if tets is not None:
        tets = np.sort(np.asarray(tets), axis=1)   # a tet's vertex order is its orientation
        built = np.sort(arrays["tets"], axis=1)
        if tets.shape != built.shape or not np.array_equal(tets, built):
            differ = int((tets != built).any(axis=1).sum()) if tets.shape == built.shape \
                else tets.shape[0]
            raise ValueError(f"tets: not the mesh this reduced model was built on "
                             f"({built.shape[0]} tets; got {tets.shape[0]}, {differ} of them "
                             f"different)")


#: the arrays of the mesh every model file moves (export.writers.reduced._mesh_arrays)
MESH_ARRAYS = {"rest_positions": ("float64", ("n", 3)), "masses": ("float64", ("n",)),
               "held": ("uint8", ("n", 3)), "surface": ("int32", (None, 3)),
               "tets": ("int32", ("m", None))}


def _check_mesh(path, header, arrays):
    """ValueError naming the file unless the mesh's tets match the header's m, have 4 or 10
    nodes, and the tets and surface name vertices of the file's n, and the masses are > 0."""
    n, tets = arrays["rest_positions"].shape[0], arrays["tets"]
    if isinstance(header.get("m"), int) and tets.shape[0] != header["m"]:
        raise ValueError(f"path: {path}.json: the header says m = {header['m']} tets, and array "
                         f"tets has {tets.shape[0]}")
    if tets.shape[1] not in (4, 10):
        raise ValueError(f"path: {path}.json: array tets has {tets.shape[1]} nodes a tet, "
                         f"expected 4 or 10")
    _in_range(path, "tets", tets, 0, n)
    _in_range(path, "surface", arrays["surface"], 0, n)
    if not (arrays["masses"] > 0).all():
        raise ValueError(f"path: {path}.json: array masses holds a mass <= 0 kg")


def _in_range(path, key, a, low, high):
    """ValueError naming the file unless every entry of the index array a is in [low, high)."""
    bad = (a < low) | (a >= high)
    if bad.any():
        raise ValueError(f"path: {path}.json: array {key} holds {int(a.ravel()[bad.ravel()][0])}"
                         f", outside [{low}, {high})")


def _real(value, name, shape):
    """value as a finite float64 array of shape (None: any length)."""
    arr = np.asarray(value)
    if arr.dtype == object or not (np.issubdtype(arr.dtype, np.floating)
                                   or np.issubdtype(arr.dtype, np.integer)):
        raise TypeError(f"{name}: expected real numbers, got dtype {arr.dtype}")
    if arr.ndim != len(shape) or any(s is not None and s != a for s, a in zip(shape, arr.shape)):
        want = "(" + ", ".join("any" if s is None else str(s) for s in shape) + ")"
        raise ValueError(f"{name}: expected shape {want}, got {arr.shape}")
    arr = arr.astype(np.float64)
    if not np.isfinite(arr).all():
        raise ValueError(f"{name}: contains NaN or infinite values")
    return arr


def _tets(tets, vertices):
    """tets as an (m, 4) int64 array of in-range vertex indices spanning nonzero volumes."""
    n = vertices.shape[0]
    arr = np.asarray(tets)
    if not np.issubdtype(arr.dtype, np.integer):
        raise TypeError(f"tets: expected integer vertex indices, got dtype {arr.dtype}")
    if arr.ndim == 2 and arr.shape[1] == 10:
        raise ValueError("tets: the network steps linear tets (m, 4); these are quadratic "
                         "(m, 10, order 2)")
    if arr.ndim != 2 or arr.shape[1] != 4 or arr.shape[0] == 0:
        raise ValueError(f"tets: expected shape (m, 4) with m >= 1, got {arr.shape}")
    if arr.min() < 0 or arr.max() >= n:
        raise ValueError(f"tets: vertex index out of range [0, {n})")
    arr = arr.astype(np.int64)
    scale = np.ptp(vertices, axis=0).max()
    flat = np.flatnonzero(tet_volumes(vertices, arr) <= 1e-12 * scale ** 3)
    if flat.size:
        raise ValueError(f"tets: {flat.size} tet(s) have zero volume (flat or repeating a "
                         f"vertex), e.g. tet {flat[0]}")
    return arr


def _per_tet(value, name, m, positive):
    """A scalar or (m,) value as a finite (m,) float64 array (> 0 if positive, else >= 0)."""
    arr = np.asarray(value, dtype=np.float64)
    if arr.ndim == 0:
        arr = np.full(m, float(arr))
    arr = _real(arr, name, (m,))
    if (arr <= 0).any() if positive else (arr < 0).any():
        raise ValueError(f"{name}: must be {'> 0' if positive else '>= 0'}, got min {arr.min()}")
    return arr


def _fibers(direction, stiffness, m):
    """(m, 3) unit fiber directions and (m,) stiffnesses in Pa (0 without a direction)."""
    stiffness = _per_tet(stiffness, "fiber_stiffness", m, positive=False)
    if direction is None:
        if (stiffness > 0).any():
            raise ValueError("fiber_direction: required when fiber_stiffness > 0")
        return np.tile([1.0, 0.0, 0.0], (m, 1)), stiffness
    d = np.asarray(direction, dtype=np.float64)
    d = _real(np.broadcast_to(d, (m, 3)) if d.shape == (3,) else d, "fiber_direction", (m, 3))
    norm = np.linalg.norm(d, axis=1, keepdims=True)
    if (norm == 0).any():
        raise ValueError("fiber_direction: a direction has zero length")
    return d / norm, stiffness


def _lame(material):
    """(mu, lam) in Pa of a dict with "young" (Pa) and "poisson" (the trained material)."""
    young, nu = float(material["young"]), float(material["poisson"])
    return young / (2.0 * (1.0 + nu)), young * nu / ((1.0 + nu) * (1.0 - 2.0 * nu))


def _fixed(fixed, n):
    """(n, 3) bool mask of held components from None, indices (k,), or a bool (n,) / (n, 3)."""
    mask = np.zeros((n, 3), dtype=bool)
    if fixed is None:
        return mask
    arr = np.asarray(fixed)
    if arr.dtype == bool:
        if arr.shape not in ((n,), (n, 3)):
            raise ValueError(f"fixed: a bool mask must have shape ({n},) or ({n}, 3), got "
                             f"{arr.shape}")
        mask[:] = arr.reshape(n, -1)
        return mask
    if not np.issubdtype(arr.dtype, np.integer) or arr.ndim != 1:
        raise ValueError(f"fixed: expected vertex indices (k,) or a bool mask, got dtype "
                         f"{arr.dtype} and shape {arr.shape}")
    if arr.size and (arr.min() < 0 or arr.max() >= n):
        raise ValueError(f"fixed: vertex index out of range [0, {n})")
    mask[arr] = True
    return mask


def _check_model(session, meta, path):
    """Raise ValueError unless the session is an anisognn step model this runtime can feed
    (the exporter drops inputs a model does not read: incoming_weights from "sum" models)."""
    if meta.get("format") != FORMAT:
        raise ValueError(f"model_path: {path} is not an anisognn step model of format "
                         f"{FORMAT!r} (its format metadata: {meta.get('format')!r})")
    names = [i.name for i in session.get_inputs()]
    known = [name for name, _, _ in INPUTS]
    if not set(STATE) <= set(names) <= set(known):
        raise ValueError(f"model_path: {path} has inputs {names}, expected the state inputs "
                         f"{list(STATE)} and some of {known[len(STATE):]}")
