"""The package's layout: anisofem's concerns import one way, with no cycle, and the module
paths from before the layout still import (the same module objects)."""
import ast
import importlib
import pathlib

import pytest

import anisofem
from anisofem._moved import MOVED

ROOT = pathlib.Path(anisofem.__file__).parent

#: concern -> level: a module may import its own level's and lower levels' modules, never higher
LEVELS = {"_validate": 0, "threads": 0, "_moved": 0, "physics": 1, "solvers": 2, "io": 3,
          "inverse": 3, "reduced": 3, "distributed": 3, "studies": 4, "cli": 5, "__main__": 5,
          "": 5}


def modules():
    """{dotted module name: path} of every module of anisofem."""
    found = {}
    for path in ROOT.rglob("*.py"):
        parts = ("anisofem",) + path.relative_to(ROOT).with_suffix("").parts
        if parts[-1] == "__init__":
            parts = parts[:-1]
        found[".".join(parts)] = path
    return found


def imports(name, path, known):
    """The anisofem modules that module `name` imports anywhere in its file (function-level
    imports included), as dotted names in `known`."""
    package = name.split(".") if path.name == "__init__.py" else name.split(".")[:-1]
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            targets = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = package[:len(package) - node.level + 1] if node.level else []
            module = ".".join(base + ([node.module] if node.module else []))
            targets = [f"{module}.{alias.name}" if f"{module}.{alias.name}" in known else module
                       for alias in node.names]
        else:
            continue
        for target in targets:
            while target and target not in known:
                target = target.rpartition(".")[0]
            if target and target != name:
                found.add(target)
    return found


def concern(name):
    parts = name.split(".")
    return parts[1] if len(parts) > 1 else ""


def graph():
    known = modules()
    return {name: imports(name, path, known) for name, path in known.items()}


def test_every_module_has_a_concern():
    assert {concern(name) for name in graph()} <= set(LEVELS)


def test_imports_point_down():
    upward = sorted(f"{name} -> {target}" for name, targets in graph().items()
                    for target in targets if LEVELS[concern(target)] > LEVELS[concern(name)])
    assert upward == []


def test_no_import_cycle():
    edges = graph()
    # a package's __init__ importing its own modules is how a package re-exports, not a cycle
    edges = {name: {t for t in targets if not t.startswith(name + ".")}
             for name, targets in edges.items()}
    state, cycles = {}, []

    def visit(name, path):
        state[name] = "open"
        for target in sorted(edges[name]):
            if state.get(target) == "open":
                cycles.append(path[path.index(target):] + [target])
            elif target not in state:
                visit(target, path + [target])
        state[name] = "done"

    for name in sorted(edges):
        if name not in state:
            visit(name, [name])
    assert cycles == []


def test_the_checks_see_an_upward_import(tmp_path):
    """The graph reader finds what the two checks above forbid in a file written for it."""
    physics = tmp_path / "anisofem" / "physics"
    physics.mkdir(parents=True)
    (physics / "x.py").write_text("from ..solvers.solve import solve\n"
                                  "def f():\n    from .. import cli\n")
    known = {"anisofem.physics.x": physics / "x.py", "anisofem.solvers.solve": None,
             "anisofem.cli": None, "anisofem": None}
    assert imports("anisofem.physics.x", physics / "x.py", known) == {
        "anisofem.solvers.solve", "anisofem.cli"}


@pytest.mark.parametrize("old", sorted(MOVED))
def test_old_paths_import_the_moved_module(old):
    module = importlib.import_module(f"anisofem.{old}")
    assert module is importlib.import_module(f"anisofem.{MOVED[old]}")
    assert module.__name__ == f"anisofem.{MOVED[old]}"
    assert module.__spec__.name == module.__name__


def test_old_paths_of_names_users_import():
    from anisofem.methods import Newton
    from anisofem.ladder import trade
    from anisofem.elements.tet10 import TET10
    from anisofem.scenefile import load_scene
    from anisofem.solvers.methods import Newton as newton
    from anisofem.studies.trade import trade as trade_now
    from anisofem.physics.elements.tet10 import TET10 as tet10
    assert (Newton, trade, TET10, load_scene) == (newton, trade_now, tet10, anisofem.load_scene)


def test_an_old_module_path_keeps_the_public_function_of_its_name():
    import anisofem.solve  # noqa: F401  (the module, at its old path)
    assert callable(anisofem.solve) and anisofem.solve.__name__ == "solve"
    assert anisofem.material is importlib.import_module("anisofem.physics.material")
    with pytest.raises(AttributeError, match="no attribute 'nothing'"):
        anisofem.nothing
