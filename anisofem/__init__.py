"""anisofem: finite elements for fiber-reinforced elastic solids."""

from .material import Material
from .mesh import TetMesh
from .potential import element_energy, energy, gradient, hessian
from .scene import Scene
from .meshgen import box_beam, cylinder_beam, hexes_to_tets, t_shape, y_shape
from .newton import ConvergenceWarning, NewtonResult
from .solve import Rollout, StepResult, default_scene, simulate, solve, step
from . import metrics
from .io import read_mesh, write_mesh
