"""anisofem: finite elements for fiber-reinforced (transversely isotropic) elastic solids."""
from . import inversion, methods, metrics
from .io import read_mesh, write_mesh
from .ladder import trade, trade_table
from .material import Material
from .mesh import TetMesh
from .meshgen import actuator, box_beam, cylinder_beam, hexes_to_tets, t_shape, tube, y_shape
from .newton import ConvergenceWarning, InversionWarning, NewtonResult
from .potential import element_energy, energy, gradient, hessian
from .pressure import Pressure
from .scene import Scene, default_scene
from .scenefile import load_scene
from .solve import Rollout, StepResult, Stepper, simulate, solve, step

__all__ = ["inversion", "methods", "metrics", "read_mesh", "write_mesh", "trade", "trade_table", "Material",
           "TetMesh", "actuator", "box_beam", "cylinder_beam", "hexes_to_tets", "t_shape", "tube", "y_shape",
           "ConvergenceWarning", "InversionWarning", "NewtonResult", "element_energy", "energy",
           "gradient", "hessian", "Pressure", "Scene", "Rollout", "StepResult", "Stepper", "default_scene",
           "simulate", "solve", "step", "load_scene"]
