"""Module paths from before the package was laid out by concern (`anisofem.methods`,
`anisofem.ladder`, ...) keep working: importing one gives the module where it now lives, the
same object, so `from anisofem.methods import Newton` and `anisofem.solvers.methods.Newton` are
one class. New code imports the new paths (docs/layout.md)."""
import importlib
import importlib.abc
import importlib.util
import sys
import types

#: old path under anisofem -> new path under anisofem; a package's modules follow it
MOVED = {
    **{name: f"physics.{name}" for name in (
        "assembly", "curves", "densities", "elements", "fibers", "inversion", "kernels",
        "material", "mesh", "meshgen", "metrics", "potential", "pressure", "reference_numpy",
        "scene", "sparse", "sym3")},
    **{name: f"solvers.{name}" for name in (
        "continuation", "frames", "linsolve", "methods", "multigrid", "newton", "solve",
        "stability")},
    **{name: f"inverse.{name}" for name in ("design", "fit", "lbfgsb", "sensitivity")},
    **{name: f"studies.{name}" for name in (
        "bench", "bench_large", "bench_load", "convergence", "robustness", "timing")},
    "ladder": "studies.trade",
    "distributed.bench": "studies.bench_distributed",
    "files": "io.output",
    "scenefile": "io.scenefile",
    "draw": "io.draw",
}


def new_path(name):
    """The module's path now, for an old full name ("anisofem.methods"), or None."""
    package, _, rest = name.partition(".")
    if package != "anisofem" or not rest:
        return None
    for old in sorted(MOVED, key=len, reverse=True):
        if rest == old or rest.startswith(old + "."):
            return f"anisofem.{MOVED[old]}{rest[len(old):]}"
    return None


class _Alias(importlib.abc.Loader):
    """Loads an old path as the module at its new one."""

    def __init__(self, target):
        self.target = target
        self.spec = None

    def create_module(self, spec):
        module = importlib.import_module(self.target)
        self.spec = module.__spec__
        return module

    def exec_module(self, module):
        # the import system stamped the old path's spec on the module: give it its own back
        module.__spec__ = self.spec


class MovedFinder(importlib.abc.MetaPathFinder):
    """Finds the old paths of MOVED (first on sys.meta_path, so that they resolve before any
    other finder looks for a file)."""

    def find_spec(self, name, path=None, target=None):
        moved = new_path(name)
        if moved is None:
            return None
        return importlib.util.spec_from_loader(name, _Alias(moved))


class _Package(types.ModuleType):
    """The anisofem package, whose public functions outlive their old modules' paths: importing
    the old module `anisofem.solve` makes the import system bind it on the package, and that
    must not hide `anisofem.solve`, the function."""

    def __setattr__(self, name, value):
        current = self.__dict__.get(name)
        if isinstance(value, types.ModuleType) and callable(current):
            return
        super().__setattr__(name, value)


def attribute(name):
    """The package's attribute `name` where it is an old module's name (af.material, af.ladder):
    the module where it now lives; else AttributeError."""
    if name in MOVED and "." not in name:
        return importlib.import_module(f"anisofem.{MOVED[name]}")
    raise AttributeError(f"module 'anisofem' has no attribute {name!r}")


def install(package):
    """Put MovedFinder on sys.meta_path once and guard `package`'s public functions."""
    if not any(isinstance(finder, MovedFinder) for finder in sys.meta_path):
        sys.meta_path.insert(0, MovedFinder())
    package.__class__ = _Package
