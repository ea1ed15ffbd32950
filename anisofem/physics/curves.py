"""Loads in time: a load curve scales one load of a scene through a rollout.

A LoadCurve is piecewise linear in time, constant before its first point and after its last.
A Timed part is a load that follows a curve: nodal forces (n, 3) N, a pressure of the scene
(its index in Scene.pressures), a motion of held components or a control's value (its name in
Scene.controls), each as written at the factor 1. Scene.at(t) is the scene with each part at factor
curve(t).
"""
from dataclasses import dataclass

import numpy as np

from .._validate import as_float_array


class LoadCurve:
    """A piecewise linear factor of time.

    times : (k,) s, strictly increasing (k >= 1); values : (k,) the factor at each.
    """

    def __init__(self, times, values, name="curve"):
        self.name = name
        self.times = as_float_array(times, f"{name}: times", shape=(None,))
        self.values = as_float_array(values, f"{name}: values", shape=(None,))
        if self.times.size == 0:
            raise ValueError(f"{name}: times: a curve needs at least one point")
        if self.values.shape != self.times.shape:
            raise ValueError(f"{name}: values: {self.values.size} values for "
                             f"{self.times.size} times")
        if (np.diff(self.times) <= 0).any():
            at = int(np.flatnonzero(np.diff(self.times) <= 0)[0])
            raise ValueError(f"{name}: times must increase, got {self.times[at]:g} then "
                             f"{self.times[at + 1]:g}")

    def __call__(self, t):
        """The factor at time t, s."""
        return float(np.interp(t, self.times, self.values))

    def __repr__(self):
        return f"LoadCurve({self.name!r}, {self.times.size} points)"


@dataclass(frozen=True)
class Timed:
    """A load that follows `curve`: force (n, 3) N, pressure (an index into Scene.pressures),
    motion, a function of the factor c giving the displacement (n, 3) m of the held
    components (c times a displacement; a rotation by c times an angle), control (a name in
    Scene.controls: its value as the scene has it, times c), or obstacle, (name, move (3,) m):
    that contact obstacle where the scene has it plus c times move."""
    curve: LoadCurve
    force: object = None
    pressure: object = None
    motion: object = None
    control: object = None
    obstacle: object = None
