"""A scene's reduced model: positions x = x0 + U q in a basis U of r displacement directions
(the lowest vibration modes of the scene and their modal derivatives, Barbic and James 2005),
the exact reduced energy (a quartic polynomial in q for the StVK base and the fiber term), and
statics and backward Euler by Newton in r dimensions.

    model = ReducedModel(scene, modes=6)          # r = 27 coordinates
    q, v = np.zeros(model.r), np.zeros(model.r)
    q, v, report = model.step(q, v, dt=0.02)
    x = model.positions(q)                         # (n, 3) full positions

The Neo-Hookean base is not polynomial in q and is refused.
"""
from .model import MODES, NewtonReport, ReducedModel

__all__ = ["MODES", "NewtonReport", "ReducedModel"]
