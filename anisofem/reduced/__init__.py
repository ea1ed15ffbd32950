"""A scene's reduced model: positions x = x0 + U q in a basis U of r displacement directions
(the lowest vibration modes of the scene and their modal derivatives, Barbic and James 2005),
the exact reduced energy (a quartic polynomial in q for the StVK base and the fiber term), and
statics and backward Euler by Newton in r dimensions.

    model = ReducedModel(scene, modes=6)          # r = 27 coordinates
    q, v = np.zeros(model.r), np.zeros(model.r)
    q, v, report = model.step(q, v, dt=0.02)
    x = model.positions(q)                         # (n, 3) full positions

A basis fitted to the loads a scene declares (anisofem.reduced.loads; by default a drag of
up to half the body's weight at each free end) follows bending through large rotations:

    model = ReducedModel(scene, modes=4, snapshots=16)   # r = 20
    model.validation.tip_error                           # on unseen loads, against the FEM

Bodies whose parts swing far (a T's or a Y's arms, a tail) move better in FramedModel: the
body cut into domains at bands of distance from its held nodes, each domain in its own
rotating frame with a local basis (anisofem.reduced.framed):

    model = FramedModel(scene)                           # 4 bands, 12 coordinates per domain
    now = before = model.rest()
    after, report = model.step(now, before, dt=0.02)     # base=[R_g | c_g]: a moving base
    x = model.positions(after)

The Neo-Hookean base is not polynomial in q and is refused.
"""
from .framed import FramedModel, FramedState
from .loads import Carry, Drag, Loads, default_loads
from .model import MODES, NewtonReport, ReducedModel

__all__ = ["MODES", "Carry", "Drag", "FramedModel", "FramedState", "Loads", "NewtonReport",
           "ReducedModel", "default_loads"]
