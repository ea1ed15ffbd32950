"""Controls: the named inputs of a scene that a controller sets every step.

A scene's controls are its named pressures (Pressure(..., name=...)), each a value in Pa,
and its activations (Activation), each the fibers' contraction a in [0, 1) of a set of
elements (their rest stretch is 1 - a). Scene.controls lists their names, pressures first,
in the order given; Scene.with_controls sets their values; simulate takes them in time.
"""
import math

import numpy as np

from .._validate import as_index_array


class Activation:
    """The fibers' activation a of a set of elements, a control named `name`.

    elements : indices (k,) of the tets, or a per-tet bool mask (m,).
    value : a in [0, 1) (default 0: passive): the fibers' rest stretch is 1 - a there.
    """

    def __init__(self, elements, value=0.0, name="activation"):
        if not isinstance(name, str) or not name:
            raise ValueError(f"activation name: expected a non-empty string, got {name!r}")
        self.name = name
        self.elements = np.asarray(elements)
        self.value = activation_value(value, name)

    def bound(self, n_tets, kappa, activation):
        """This activation with its elements as sorted indices (k,) into the scene's n_tets
        tets; ValueError where one is out of range, none is given, or one has no fibers
        (kappa (m,) 0) or an activation of its material (activation (m,))."""
        where = f"activation {self.name!r}: elements"
        idx = self.elements
        if idx.dtype == bool:
            if idx.shape != (n_tets,):
                raise ValueError(f"{where}: a bool mask must have shape ({n_tets},), got "
                                 f"{idx.shape}")
            idx = np.flatnonzero(idx)
        else:
            idx = as_index_array(idx if idx.size else np.zeros(0, np.int64), where,
                                 shape=(None,))
        if idx.size == 0:
            raise ValueError(f"{where}: no element given")
        if idx.min() < 0 or idx.max() >= n_tets:
            raise ValueError(f"{where}: index out of range [0, {n_tets})")
        idx = np.unique(idx)
        bare = idx[kappa[idx] == 0]
        if bare.size:
            raise ValueError(f"activation {self.name!r}: {bare.size} of its elements have no "
                             f"fibers (fiber_stiffness 0, first {int(bare[0])}): only fibers "
                             f"contract")
        set_twice = idx[activation[idx] != 0]
        if set_twice.size:
            raise ValueError(f"activation {self.name!r}: {set_twice.size} of its elements "
                             f"have an activation of their Material too (first "
                             f"{int(set_twice[0])}); the control sets it there")
        out = object.__new__(Activation)
        out.name, out.elements, out.value = self.name, idx, self.value
        return out

    def at(self, value):
        """The same activation at `value`."""
        out = object.__new__(Activation)
        out.name, out.elements = self.name, self.elements
        out.value = activation_value(value, self.name)
        return out

    def __repr__(self):
        return f"Activation({self.name!r}, {self.elements.size} elements, {self.value:g})"


def activation_value(value, name):
    """value as a float in [0, 1); ValueError naming the control otherwise."""
    a = control_number(value, name)
    if not 0.0 <= a < 1.0:
        raise ValueError(f"control {name!r}: an activation must be in [0, 1) (the fibers' "
                         f"rest stretch is 1 - activation), got {a:g}")
    return a


def control_number(value, name):
    """value as a finite float; ValueError naming the control otherwise."""
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"control {name!r}: expected a number, got {value!r}") from None
    if isinstance(value, bool) or not math.isfinite(number):
        raise ValueError(f"control {name!r}: expected a finite number, got {value!r}")
    return number


def control_mapping(values, names):
    """values (a mapping name -> number, or a sequence in the order of `names`) as a dict
    name -> value; ValueError for an unknown name or a sequence of the wrong length."""
    if isinstance(values, dict):
        unknown = [k for k in values if k not in names]
        if unknown:
            raise ValueError(f"controls: no control {unknown[0]!r}; the scene has: "
                             f"{', '.join(names) or 'none'}")
        return dict(values)
    flat = np.asarray(values, dtype=object).ravel() if not np.isscalar(values) else None
    if flat is None or flat.size != len(names):
        raise ValueError(f"controls: expected a mapping of names to values or "
                         f"{len(names)} values ({', '.join(names) or 'none'}), got {values!r}")
    return dict(zip(names, flat))
