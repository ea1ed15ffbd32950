"""Python through the C runtime (export/c: anisofem.h, the deployed implementation of both
kinds of model), built with the system C compiler and called through ctypes. It steps a file
like runtime.ReducedSimulator and framed_runtime.FramedSimulator (the numpy references the
tests hold it against) at C's speed (`python -m export bench-reduced`).

    sim = CReducedSimulator("cantilever")   # compiles the library on first use (build())
    q, w = sim.rest_state()
    sim.step(q, w, force, 0.02)             # in place; force (n, 3) N
    x = sim.positions(q)

    sim = CFramedSimulator("t")             # the same interface as FramedSimulator
    now = before = sim.rest_state()
    now, before = sim.step(now, before, force, 0.02), now
"""
import ctypes
import hashlib
import os
import shutil
import subprocess

import numpy as np

from .runtime import control_vector

FOLDER = os.path.join(os.path.dirname(os.path.abspath(__file__)), "c")
#: The runtime's sources, in build order, and its headers.
SOURCES = tuple(os.path.join(FOLDER, f"{name}.c") for name in
                ("arrays", "linalg", "reduced", "reach", "contact", "framed", "model",
                 "files"))
HEADERS = (os.path.join(FOLDER, "anisofem.h"), os.path.join(FOLDER, "af_internal.h"))
#: The kinds af_kind returns (anisofem.h).
REDUCED, FRAMED = 1, 2

#: Compiler flags, best first: for this machine's processor (vector units, fused multiply-add:
#: the framed step 1.7-1.9x faster than at -O2), and what any C99 compiler takes.
FLAGS = (["-O3", "-march=native"], ["-O2"])


def compiler():
    """The system C compiler's command (cc, gcc or clang), or None."""
    for name in ("cc", "gcc", "clang"):
        path = shutil.which(name)
        if path:
            return path
    return None


def build(folder=None):
    """Compile the C runtime into folder/libanisofem.so (C99, the first of FLAGS the compiler
    takes) unless it is there for these sources; returns its path. folder: by default a cache
    folder named by the sources' hash ($ANISOFEM_CACHE, else ~/.cache/anisofem). RuntimeError
    without a C compiler or where it fails."""
    return compile_library("libanisofem.so", SOURCES, HEADERS, [], folder, "c")


def compile_library(name, sources, headers, extra, folder=None, prefix="c"):
    """Compile sources (C99, the first of FLAGS the compiler takes, then the arguments extra:
    include folders, libraries) into folder/name unless it is there for these sources, headers
    and extra; returns its path. folder: by default the cache folder prefix-HASH
    ($ANISOFEM_CACHE, else ~/.cache/anisofem). RuntimeError without a C compiler or where it
    fails, with the compiler's message."""
    digest = hashlib.sha256(" ".join(extra).encode())
    for path in tuple(sources) + tuple(headers):
        with open(path, "rb") as f:
            digest.update(f.read())
    tag = digest.hexdigest()[:16]
    if folder is None:
        cache = os.environ.get("ANISOFEM_CACHE") or os.path.join(
            os.path.expanduser("~"), ".cache", "anisofem")
        folder = os.path.join(cache, f"{prefix}-{tag}")
    lib = os.path.join(folder, name)
    stamp = lib + ".sources"
    if os.path.exists(lib) and os.path.exists(stamp):
        with open(stamp) as f:
            if f.read() == tag:
                return lib
    cc = compiler()
    if cc is None:
        raise RuntimeError("the C runtime needs a C compiler (cc, gcc or clang) on the PATH, "
                           "and none is there; the numpy runtimes (export/runtime.py, "
                           "export/framed_runtime.py) step the same files without one")
    os.makedirs(folder, exist_ok=True)
    tmp = lib + f".{os.getpid()}.tmp"
    for flags in FLAGS:
        done = subprocess.run([cc, "-std=c99", *flags, "-shared", "-fPIC", "-o", tmp,
                               *sources, *extra, "-lm"], capture_output=True, text=True)
        if done.returncode == 0:
            break
    if done.returncode != 0:
        raise RuntimeError(f"compiling {name} from {os.path.dirname(sources[0])} failed:\n"
                           f"{done.stderr}")
    os.replace(tmp, lib)
    with open(stamp + f".{os.getpid()}.tmp", "w") as f:
        f.write(tag)
    os.replace(stamp + f".{os.getpid()}.tmp", stamp)
    return lib


_DOUBLE_P = ctypes.POINTER(ctypes.c_double)
_LIBRARIES = {}


def library(lib=None):
    """The ctypes library at lib (build()'s path; None: build() it), its functions typed."""
    lib = lib or build()
    if lib not in _LIBRARIES:
        c = ctypes.CDLL(lib)
        handle, char_p = ctypes.c_void_p, ctypes.c_char_p
        types = {
            "af_load": (handle, [char_p, char_p, char_p, ctypes.c_size_t]),
            "af_free": (None, [handle]),
            "af_kind": (ctypes.c_int, [handle]),
            "af_vertices": (ctypes.c_int, [handle]),
            "af_state_size": (ctypes.c_int, [handle]),
            "af_rest_state": (None, [handle, _DOUBLE_P]),
            "af_carry_state": (ctypes.c_int, [handle, _DOUBLE_P, _DOUBLE_P]),
            "af_set_constant_force": (ctypes.c_int, [handle, _DOUBLE_P]),
            "af_set_solver": (ctypes.c_int, [handle, ctypes.c_double, ctypes.c_int]),
            "af_step": (ctypes.c_int, [handle, _DOUBLE_P, _DOUBLE_P, _DOUBLE_P,
                                       ctypes.c_double]),
            "af_iterations": (ctypes.c_int, [handle]),
            "af_error": (char_p, [handle]),
            "af_positions": (None, [handle, _DOUBLE_P, _DOUBLE_P]),
            "af_masses": (_DOUBLE_P, [handle]),
            "af_rest_positions": (_DOUBLE_P, [handle]),
            "af_held": (ctypes.POINTER(ctypes.c_ubyte), [handle]),
            "af_surface": (ctypes.POINTER(ctypes.c_int), [handle, ctypes.POINTER(ctypes.c_int)]),
            "af_tets": (ctypes.POINTER(ctypes.c_int), [handle, ctypes.POINTER(ctypes.c_int),
                                                       ctypes.POINTER(ctypes.c_int)]),
            "af_gravity": (ctypes.c_int, [handle, _DOUBLE_P]),
            "af_time_step": (ctypes.c_double, [handle]),
            "af_controls": (ctypes.c_int, [handle]),
            "af_control_name": (char_p, [handle, ctypes.c_int]),
            "af_control_value": (ctypes.c_double, [handle, ctypes.c_int]),
            "af_set_controls": (ctypes.c_int, [handle, _DOUBLE_P]),
            "af_obstacles": (ctypes.c_int, [handle]),
            "af_obstacle_name": (char_p, [handle, ctypes.c_int]),
            "af_obstacle_position": (ctypes.c_int, [handle, ctypes.c_int, _DOUBLE_P]),
            "af_move_obstacle": (ctypes.c_int, [handle, ctypes.c_int, _DOUBLE_P]),
            "af_obstacle_motion": (ctypes.c_int, [handle, ctypes.c_int, ctypes.c_double,
                                                  _DOUBLE_P, _DOUBLE_P, _DOUBLE_P, _DOUBLE_P]),
            "af_turn_obstacle": (ctypes.c_int, [handle, ctypes.c_int, _DOUBLE_P]),
            "af_obstacle_wrench": (ctypes.c_int, [handle, ctypes.c_int, _DOUBLE_P]),
            "af_obstacle_center": (ctypes.c_int, [handle, ctypes.c_int, _DOUBLE_P]),
            "af_obstacle_shape": (ctypes.c_int, [handle, ctypes.c_int, _DOUBLE_P]),
            "af_reach": (ctypes.c_int, [handle, ctypes.POINTER(ctypes.c_int), _DOUBLE_P,
                                        ctypes.c_int, _DOUBLE_P, _DOUBLE_P, _DOUBLE_P,
                                        ctypes.c_double, _DOUBLE_P, _DOUBLE_P]),
        }
        for name, (restype, argtypes) in types.items():
            function = getattr(c, name)
            function.restype, function.argtypes = restype, argtypes
        _LIBRARIES[lib] = c
    return _LIBRARIES[lib]


class CModel:
    """A model file (path without extension: path.json + path.bin) loaded by the C runtime:
    its body's arrays, and one step of a flat state (af_state_size doubles) in place. lib: the
    library's path (None: build() it); angle: the fiber angle of a file of several, as its
    header writes it. ValueError with the runtime's message where the file cannot be stepped."""

    def __init__(self, path, lib=None, angle=None):
        self._c = library(lib)
        error = ctypes.create_string_buffer(512)
        self._handle = self._c.af_load(str(path).encode(),
                                       None if angle is None else str(angle).encode(),
                                       error, len(error))
        if not self._handle:
            raise ValueError(error.value.decode())
        c, h = self._c, self._handle
        self.kind = c.af_kind(h)
        self.n = c.af_vertices(h)
        self.state_size = c.af_state_size(h)
        self.masses = np.ctypeslib.as_array(c.af_masses(h), (self.n,)).copy()
        self.rest_positions = np.ctypeslib.as_array(c.af_rest_positions(h), (self.n, 3)).copy()
        self.held = np.ctypeslib.as_array(c.af_held(h), (self.n, 3)).astype(bool)
        count, nodes = ctypes.c_int(), ctypes.c_int()
        surface = c.af_surface(h, ctypes.byref(count))
        self.surface = np.ctypeslib.as_array(surface, (count.value, 3)).copy()
        tets = c.af_tets(h, ctypes.byref(count), ctypes.byref(nodes))
        self.tets = np.ctypeslib.as_array(tets, (count.value, nodes.value)).copy()
        g = np.zeros(3)
        self.gravity = g if c.af_gravity(h, _pointer(g)) else None
        self.time_step = c.af_time_step(h) or None
        self._solver = None      # the model's own until set
        self._force_buffer = None
        self.controls = tuple(c.af_control_name(h, i).decode() for i in range(c.af_controls(h)))

    @property
    def control_values(self):
        """(k,) the controls' values now."""
        return np.array([self._c.af_control_value(self._handle, i)
                         for i in range(len(self.controls))])

    def set_controls(self, values):
        """Set the controls for every later step: a mapping name -> value (the others keep
        theirs) or one value per control. ValueError for an unknown name or a wrong count;
        RuntimeError with the runtime's message for a bad value."""
        now = np.ascontiguousarray(control_vector(values, self.controls, self.control_values))
        if not self.controls:
            return
        self._check(self._c.af_set_controls(self._handle, _pointer(now)), "af_set_controls")

    def __del__(self):
        if getattr(self, "_handle", None):
            self._c.af_free(self._handle)
            self._handle = None

    def _check(self, code, name):
        if code != 0:
            raise RuntimeError(f"{name}: {self._c.af_error(self._handle).decode()}")

    def _forces(self, force):
        """A pointer to force as a contiguous float64 (n, 3) array (kept alive on self), or
        None."""
        if force is None:
            return None
        force = np.ascontiguousarray(force, dtype=np.float64)
        if force.shape != (self.n, 3):
            raise ValueError(f"force: expected shape ({self.n}, 3), got {force.shape}")
        self._force_buffer = force
        return _pointer(force)

    def set_constant_force(self, force):
        """A force (n, 3), N, added to every later step, projected once (None clears it)."""
        self._check(self._c.af_set_constant_force(self._handle, self._forces(force)),
                    "af_set_constant_force")

    def set_solver(self, tolerance, max_iter):
        """Newton's relative tolerance and iteration budget (af_set_solver)."""
        if (tolerance, max_iter) != self._solver:
            self._check(self._c.af_set_solver(self._handle, tolerance, max_iter),
                        "af_set_solver")
            self._solver = (tolerance, max_iter)

    def advance(self, state, force, dt, base=None):
        """One step of the flat state (float64 (state_size,), contiguous) in place; base (3, 4)
        [R_g | c_g] or None. RuntimeError with the runtime's message where it fails."""
        if base is not None:
            base = np.asarray(base, float)
            base = np.ascontiguousarray(np.concatenate([base[:, :3].ravel(), base[:, 3]]))
        self._check(self._c.af_step(self._handle, _pointer(state), self._forces(force),
                                    None if base is None else _pointer(base), dt), "af_step")

    @property
    def iterations(self):
        """Newton iterations of the last step."""
        return self._c.af_iterations(self._handle)

    def _positions(self, state):
        x = np.empty((self.n, 3))
        self._c.af_positions(self._handle, _pointer(np.ascontiguousarray(state, float)),
                             _pointer(x))
        return x


class CReducedSimulator(CModel):
    """A reduced model's file stepped by the C runtime with runtime.ReducedSimulator's
    interface: a state (q, w), r numbers each."""

    def __init__(self, path, lib=None, angle=None):
        super().__init__(path, lib, angle)
        if self.kind != REDUCED:
            raise ValueError(f"{path}: a framed model: step it with CFramedSimulator")
        self.r = self.state_size // 2
        self._state = np.empty(self.state_size)

    def rest_state(self):
        """(q, w): zeros (r,), float64."""
        return np.zeros(self.r), np.zeros(self.r)

    def step(self, q, w, force, dt, rtol=1e-8, max_iter=50, controls=None):
        """One backward-Euler step of q, w (float64 (r,)) in place under the constant force plus
        nodal forces (n, 3), N (None: none), with the controls set to `controls` first (see
        set_controls; None: as they are); RuntimeError with the runtime's message where it
        fails (q and w unchanged)."""
        self.set_solver(rtol, max_iter)
        if controls is not None:
            self.set_controls(controls)
        state = self._state
        state[:self.r], state[self.r:] = q, w
        self.advance(state, force, dt)
        q[:], w[:] = state[:self.r], state[self.r:]

    def positions(self, q):
        """Positions (n, 3), m, of coordinates q (r,)."""
        return self._positions(q)  # af_positions reads a state's first half: q

    @property
    def obstacles(self):
        """The names of the model's obstacles (none without contact)."""
        c, h = self._c, self._handle
        return tuple(c.af_obstacle_name(h, i).decode() for i in range(c.af_obstacles(h)))

    def obstacle_position(self, which):
        """(3,) where obstacle `which` (a name or an index) is now, m."""
        out = np.zeros(3)
        self._check(self._c.af_obstacle_position(self._handle, self._obstacle(which),
                                                 _pointer(out)), "af_obstacle_position")
        return out

    def move_obstacle(self, which, position):
        """af_move_obstacle: obstacle `which` (a name or an index) to be at position (3,),
        m, as runtime.ReducedSimulator.move_obstacle."""
        at = np.ascontiguousarray(position, dtype=np.float64)
        self._check(self._c.af_move_obstacle(self._handle, self._obstacle(which), _pointer(at)),
                    "af_move_obstacle")

    def set_obstacle_motion(self, which, mass, velocity, acceleration, inertia=None,
                            offset=None):
        """af_obstacle_motion: obstacle `which` free, of `mass` kg (0: moved only by
        move_obstacle), from velocity (3 or 6,: its center's, m/s, then its spin, rad/s) under
        acceleration (3 or 6,), turning where inertia (3, 3), kg m^2 about its center, is
        given; its center offset (3,), m, from its position (None: none)."""
        v, a = (np.zeros(6) for _ in range(2))
        v[:len(velocity)], a[:len(acceleration)] = velocity, acceleration
        inertia, offset = (None if u is None else np.ascontiguousarray(u, dtype=np.float64)
                           for u in (inertia, offset))
        self._check(self._c.af_obstacle_motion(
            self._handle, self._obstacle(which), float(mass),
            None if inertia is None else _pointer(inertia),
            None if offset is None else _pointer(offset), _pointer(v), _pointer(a)),
            "af_obstacle_motion")

    def turn_obstacle(self, which, rotation):
        """af_turn_obstacle: obstacle `which` turned by rotation (3, 3) from how the file has
        it, at the next step's start where the body lets it."""
        R = np.ascontiguousarray(rotation, dtype=np.float64)
        self._check(self._c.af_turn_obstacle(self._handle, self._obstacle(which), _pointer(R)),
                    "af_turn_obstacle")

    def obstacle_shape(self, which):
        """(kind, its 15 numbers) of obstacle `which` now (af_obstacle_shape)."""
        out = np.zeros(15)
        kind = self._c.af_obstacle_shape(self._handle, self._obstacle(which), _pointer(out))
        self._check(min(kind, 0), "af_obstacle_shape")
        return kind, out

    def obstacle_center(self, which):
        """(3,) where obstacle `which`'s center is now, m."""
        out = np.zeros(3)
        self._check(self._c.af_obstacle_center(self._handle, self._obstacle(which),
                                               _pointer(out)), "af_obstacle_center")
        return out

    def obstacle_wrench(self, which):
        """(6,) the force on obstacle `which` at the last step's end, N, and its moment about
        its center, N m."""
        out = np.zeros(6)
        self._check(self._c.af_obstacle_wrench(self._handle, self._obstacle(which),
                                               _pointer(out)), "af_obstacle_wrench")
        return out

    def _obstacle(self, which):
        names = self.obstacles
        if which in names:
            return names.index(which)
        if isinstance(which, (int, np.integer)):
            return int(which)
        raise ValueError(f"obstacle: no obstacle {which!r}; the model has: "
                         f"{', '.join(names) or 'none'}")

    def reach(self, nodes, weights, target, low, high, tolerance=0.0):
        """af_reach: the controls within [low, high] (k,) that bring the effector sum_i
        weights[i] x[nodes[i]] to target (3,), m, at static equilibrium under the constant
        force. Returns (controls (k,), position (3,), reached, message); RuntimeError with the
        runtime's message for bad input."""
        nodes = np.ascontiguousarray(np.atleast_1d(nodes), dtype=np.int32)
        weights = np.ascontiguousarray(np.atleast_1d(weights), dtype=np.float64)
        arrays = [np.ascontiguousarray(a, dtype=np.float64) for a in (target, low, high)]
        controls, position = np.zeros(len(self.controls)), np.zeros(3)
        code = self._c.af_reach(self._handle,
                                nodes.ctypes.data_as(ctypes.POINTER(ctypes.c_int)),
                                _pointer(weights), nodes.size, *map(_pointer, arrays),
                                tolerance, _pointer(controls), _pointer(position))
        if code < 0:
            self._check(code, "af_reach")
        return controls, position, code == 0, self._c.af_error(self._handle).decode()


class CFramedSimulator(CModel):
    """A framed model's file stepped by the C runtime with framed_runtime.FramedSimulator's
    interface: a state flat (size,): the domains' centres and rotations, the coordinates, the
    base."""

    def __init__(self, path, lib=None, angle=None):
        super().__init__(path, lib, angle)
        if self.kind != FRAMED:
            raise ValueError(f"{path}: a reduced model, not a framed one: step it with "
                             f"CReducedSimulator")
        self.size = self.state_size // 2
        self._state = np.empty(self.state_size)
        self._c.af_rest_state(self._handle, _pointer(self._state))
        self._rest = self._state[:self.size].copy()

    def rest_state(self):
        """The rest state, flat (size,)."""
        return self._rest.copy()

    def step(self, now, before, force, dt, base=None, max_iter=50):
        """The state after now (before: a step earlier) under the constant force plus nodal
        forces (n, 3), N (None: none), the held nodes carried by base (3, 4) [R_g | c_g] (None:
        now's); RuntimeError with the runtime's message where it fails."""
        self.set_solver(1e-8, max_iter)
        state = self._state
        state[:self.size], state[self.size:] = now, before
        self.advance(state, force, dt, base)
        return state[:self.size].copy()

    def positions(self, state):
        """Positions (n, 3), m, of a state (size,)."""
        return self._positions(state)  # af_positions reads a state's first half: now


def _pointer(a):
    if a.dtype != np.float64 or not a.flags.c_contiguous:
        raise TypeError("expected a contiguous float64 array")
    return a.ctypes.data_as(_DOUBLE_P)
