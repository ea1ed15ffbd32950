"""Input checks shared by the public API: each raises TypeError / ValueError naming the field."""
import numbers

import numpy as np


def as_float_array(value, name, shape=None):
    """value as a float64 array, checked for a real dtype, the shape and finite entries.

    shape: tuple with None for a free dimension, or None for any shape.
    """
    arr = np.asarray(value)
    if arr.dtype.kind not in "fiu":  # bool, complex, object, strings...
        raise TypeError(f"{name}: expected a real-valued numeric array, got dtype {arr.dtype}")
    arr = np.array(arr, dtype=np.float64, order="C")
    if shape is not None:
        check_shape(arr, name, shape)
    if not np.isfinite(arr).all():
        if arr.ndim == 0:
            raise ValueError(f"{name}: must be finite, got {arr}")
        bad = np.argwhere(~np.isfinite(arr))[:3].tolist()
        raise ValueError(f"{name}: contains NaN or inf (at index {bad})")
    return arr


def as_index_array(value, name, shape=None):
    """value as an int64 array; floats (even integral ones) and bools are a TypeError."""
    arr = np.asarray(value)
    if arr.dtype.kind not in "iu":
        raise TypeError(f"{name}: expected an integer array, got dtype {arr.dtype}")
    arr = np.array(arr, dtype=np.int64, order="C")
    if shape is not None:
        check_shape(arr, name, shape)
    return arr


def check_shape(arr, name, shape):
    ok = arr.ndim == len(shape) and all(s is None or s == d for s, d in zip(shape, arr.shape))
    if not ok:
        want = "(" + ", ".join("*" if s is None else str(s) for s in shape) + ")"
        raise ValueError(f"{name}: expected shape {want}, got {arr.shape}")


def as_scalar(value, name):
    """A finite real scalar as float."""
    if isinstance(value, bool) or not isinstance(value, (numbers.Real, np.floating, np.integer)):
        raise TypeError(f"{name}: expected a real number, got {type(value).__name__}")
    value = float(value)
    if not np.isfinite(value):
        raise ValueError(f"{name}: must be finite, got {value}")
    return value


def per_element(value, name, m, width=None):
    """A scalar or (m,) array (width None), or a (width,) or (m, width) array, as float64
    broadcast to (m,) or (m, width)."""
    arr = as_float_array(value, name)
    if width is None:
        if arr.ndim == 0 or arr.shape == (m,):
            return np.broadcast_to(arr, (m,)).copy()
        raise ValueError(f"{name}: expected a scalar or shape ({m},), got {arr.shape}")
    if arr.shape == (width,) or arr.shape == (m, width):
        return np.broadcast_to(arr, (m, width)).copy()
    raise ValueError(f"{name}: expected shape ({width},) or ({m}, {width}), got {arr.shape}")


def as_count(value, name):
    """value as an int >= 0; a float (even an integral one) or a bool is a TypeError."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise TypeError(f"{name}: expected a whole number, got {value!r}")
    if value < 0:
        raise ValueError(f"{name}: must be >= 0, got {value}")
    return int(value)
