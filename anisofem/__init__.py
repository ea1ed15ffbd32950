"""anisofem: finite elements for fiber-reinforced (transversely isotropic) elastic solids.

Laid out by concern, importing one way (docs/layout.md): the physics (`physics`) <- the solvers
(`solvers`) <- files (`io`), inverse problems (`inverse`), reduced models (`reduced`), the petsc
engine (`distributed`) <- studies (`studies`) <- the command line (`cli`)."""
import sys

from . import _moved

_moved.install(sys.modules[__name__])

from .physics import inversion, metrics
from .solvers import methods
from .io.meshes import read_mesh, read_surface, write_mesh
from .studies.trade import trade
from .studies.trade_report import trade_table
from .physics.material import Material
from .physics.mesh import TetMesh
from .physics.meshgen import (actuator, box_beam, cylinder_beam, hexes_to_tets, t_shape, tube,
                              y_shape)
from .solvers.newton import ConvergenceWarning, InversionWarning, NewtonResult
from .physics.potential import element_energy, energy, gradient, hessian
from .physics.pressure import Pressure
from .physics.controls import Activation
from .physics.cables import Cable
from .physics.contact import Contact
from .physics.obstacles import Box, Capsule, Plane, Sphere, Surface
from .physics.curves import LoadCurve
from .physics.scene import Scene, default_scene
from .io.scenefile import load_scene
from .solvers.solve import Rollout, StepResult, Stepper, simulate, solve, step

__all__ = ["inversion", "methods", "metrics", "read_mesh", "read_surface", "write_mesh", "trade", "trade_table", "Material",
           "TetMesh", "actuator", "box_beam", "cylinder_beam", "hexes_to_tets", "t_shape", "tube", "y_shape",
           "ConvergenceWarning", "InversionWarning", "NewtonResult", "element_energy", "energy",
           "gradient", "hessian", "Pressure", "Activation", "Cable", "Contact", "Plane", "Sphere", "Box", "Capsule", "Surface", "LoadCurve", "Scene", "Rollout", "StepResult", "Stepper", "default_scene",
           "simulate", "solve", "step", "load_scene"]


def __getattr__(name):
    """Old module paths as attributes (af.material, af.ladder): the module where each lives now."""
    return _moved.attribute(name)
