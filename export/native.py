"""The C runtime of the reduced models (export/c/anisofem_reduced.c: the linear model and the
framed one), built with the system C compiler and called through ctypes: how the tests check
it against runtime.ReducedSimulator and framed_runtime.FramedSimulator and how `python -m
export bench-reduced` times it. An engine links the C file pair itself
(export/README.md).

    lib = build("build/c")                  # compiles once; returns the shared library's path
    sim = CReducedSimulator("cantilever", lib)
    q, w = sim.rest_state()
    sim.step(q, w, force, 0.02)             # in place; force (n, 3) N
    x = sim.positions(q)
"""
import ctypes
import os
import shutil
import subprocess

import numpy as np

SOURCE = os.path.join(os.path.dirname(os.path.abspath(__file__)), "c", "anisofem_reduced.c")

#: The C runtime's return codes (anisofem_reduced.h).
CODES = {-1: "bad file", -2: "bad input", -3: "not converged", -4: "no memory"}


def compiler():
    """The system C compiler's command (cc, gcc or clang), or None."""
    for name in ("cc", "gcc", "clang"):
        path = shutil.which(name)
        if path:
            return path
    return None


#: Compiler flags, best first: for this machine's processor (vector units, fused multiply-add:
#: the framed step 1.7-1.9x faster than at -O2), and what any C99 compiler takes.
FLAGS = (["-O3", "-march=native"], ["-O2"])


def build(folder):
    """Compile the C runtime into folder/libanisofem_reduced.so (C99, the first of FLAGS the
    compiler takes) unless it is newer than its source; returns its path. RuntimeError without
    a C compiler or where it fails."""
    cc = compiler()
    if cc is None:
        raise RuntimeError("no C compiler (cc, gcc or clang) on the PATH")
    os.makedirs(folder, exist_ok=True)
    lib = os.path.join(folder, "libanisofem_reduced.so")
    newest = max(os.path.getmtime(SOURCE), os.path.getmtime(SOURCE[:-1] + "h"))
    if os.path.exists(lib) and os.path.getmtime(lib) >= newest:
        return lib
    tmp = lib + f".{os.getpid()}.tmp"
    for flags in FLAGS:
        done = subprocess.run([cc, "-std=c99", *flags, "-shared", "-fPIC", "-o", tmp, SOURCE,
                               "-lm"], capture_output=True, text=True)
        if done.returncode == 0:
            break
    if done.returncode != 0:
        raise RuntimeError(f"compiling {SOURCE} failed:\n{done.stderr}")
    os.replace(tmp, lib)
    return lib


class _CSimulator:
    """What both C simulators share, their functions named PREFIX_*: the model handle, nodal
    forces handed to C, a constant force, iterations and positions."""
    PREFIX = ""

    def __init__(self, path, lib, angle, counts):
        c, handle = _open(lib, self.PREFIX, path, angle,
                          tuple(f"{self.PREFIX}_{name}" for name in ("vertices", "iterations")
                                + counts))
        self._c, self._handle = c, handle
        double_p = ctypes.POINTER(ctypes.c_double)
        self._function("positions").argtypes = [ctypes.c_void_p, double_p, double_p]
        self._function("set_constant_force").argtypes = [ctypes.c_void_p, double_p]
        self.n = self._function("vertices")(handle)

    def _function(self, name):
        return getattr(self._c, f"{self.PREFIX}_{name}")

    def __del__(self):
        if getattr(self, "_handle", None):
            self._function("free")(self._handle)
            self._handle = None

    def _call(self, name, *args):
        """PREFIX_name(handle, *args); RuntimeError naming the C runtime's code where it
        fails."""
        code = self._function(name)(self._handle, *args)
        if code != 0:
            raise RuntimeError(f"{self.PREFIX}_{name}: {CODES.get(code, code)}")

    def _forces(self, force):
        """A pointer to force as a contiguous float64 (n, 3) array (kept alive on self), or
        None."""
        if force is None:
            return None
        self._force_buffer = _force_array(force, self.n)
        return _pointer(self._force_buffer)

    def set_constant_force(self, force):
        """A force (n, 3), N, added to every later step, projected once (None clears it)."""
        self._call("set_constant_force", self._forces(force))

    @property
    def iterations(self):
        """Newton iterations of the last step."""
        return self._function("iterations")(self._handle)

    def positions(self, state):
        """Positions (n, 3), m, of a state (the reduced model's: its coordinates q)."""
        x = np.empty((self.n, 3))
        self._function("positions")(self._handle, _pointer(state), _pointer(x))
        return x


class CReducedSimulator(_CSimulator):
    """A reduced model's arrays files (path without extension) stepped by the C runtime at
    `lib` (build's path); angle: the fiber angle of a file of several, as its header writes it."""
    PREFIX = "af_reduced"

    def __init__(self, path, lib, angle=None):
        super().__init__(path, lib, angle, ("coordinates",))
        double_p = ctypes.POINTER(ctypes.c_double)
        self._c.af_reduced_step.argtypes = [ctypes.c_void_p, double_p, double_p, double_p,
                                            ctypes.c_double, ctypes.c_double, ctypes.c_int]
        self.r = self._c.af_reduced_coordinates(self._handle)

    def rest_state(self):
        """(q, w): zeros (r,), float64."""
        return np.zeros(self.r), np.zeros(self.r)

    def step(self, q, w, force, dt, rtol=1e-8, max_iter=50):
        """One backward-Euler step of q, w (float64 (r,), contiguous) in place under the
        constant force plus nodal forces (n, 3), N (None: none); RuntimeError naming the C
        runtime's code where it fails."""
        self._call("step", _pointer(q), _pointer(w), self._forces(force), dt, rtol, max_iter)


def _open(lib, prefix, path, angle, counts):
    """(ctypes library, model handle) of PREFIX_load(path, angle) in the shared library lib,
    PREFIX_free and the functions `counts` (of the handle alone) typed; ValueError with the C
    runtime's message where the file cannot be stepped."""
    c = ctypes.CDLL(lib)
    load = getattr(c, prefix + "_load")
    load.restype = ctypes.c_void_p
    load.argtypes = [ctypes.c_char_p, ctypes.c_char_p, ctypes.c_char_p, ctypes.c_size_t]
    for name in (prefix + "_free",) + tuple(counts):
        getattr(c, name).argtypes = [ctypes.c_void_p]
    error = ctypes.create_string_buffer(512)
    handle = load(str(path).encode(), None if angle is None else str(angle).encode(), error,
                  len(error))
    if not handle:
        raise ValueError(error.value.decode())
    return c, handle


def _force_array(force, n):
    """force as a contiguous float64 (n, 3) array; ValueError naming its shape otherwise."""
    force = np.ascontiguousarray(force, dtype=np.float64)
    if force.shape != (n, 3):
        raise ValueError(f"force: expected shape ({n}, 3), got {force.shape}")
    return force


def _pointer(a):
    if a.dtype != np.float64 or not a.flags.c_contiguous:
        raise TypeError("expected a contiguous float64 array")
    return a.ctypes.data_as(ctypes.POINTER(ctypes.c_double))


class CFramedSimulator(_CSimulator):
    """A framed model's arrays files (path without extension) stepped by the C runtime at
    `lib`: framed_runtime.FramedSimulator's interface, a state flat (af_framed_state_size,):
    centres, rotations, coordinates, base."""
    PREFIX = "af_framed"

    def __init__(self, path, lib, angle=None):
        super().__init__(path, lib, angle, ("state_size",))
        double_p = ctypes.POINTER(ctypes.c_double)
        c = self._c
        c.af_framed_rest_state.argtypes = [ctypes.c_void_p, double_p]
        c.af_framed_step.argtypes = [ctypes.c_void_p, double_p, double_p, double_p, double_p,
                                     double_p, ctypes.c_double, ctypes.c_int]
        self.size = c.af_framed_state_size(self._handle)
        self._rest = np.empty(self.size)
        c.af_framed_rest_state(self._handle, _pointer(self._rest))

    def rest_state(self):
        """The rest state, flat (af_framed_state_size,)."""
        return self._rest.copy()

    def step(self, now, before, force, dt, base=None, max_iter=50):
        """The state after now (flat states; before a step earlier) under the constant force
        plus nodal forces (n, 3), N (None: none), the held nodes carried by base (3, 4)
        [R_g | c_g] (None: now's); RuntimeError naming the C runtime's code where it fails."""
        after = np.empty(self.size)
        if base is not None:
            base = np.ascontiguousarray(np.concatenate([np.asarray(base, float)[:, :3].ravel(),
                                                        np.asarray(base, float)[:, 3]]))
        self._call("step", _pointer(now), _pointer(before), _pointer(after),
                   self._forces(force), None if base is None else _pointer(base), dt,
                   max_iter)
        return after
