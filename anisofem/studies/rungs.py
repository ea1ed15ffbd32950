"""The rungs of the speed/accuracy ladder: each a way of rolling a scene forward (a method of
anisofem.solvers.methods, the exact rollout at a larger step, a reduced or framed model of the
scene, a reduced model of a finer body), the list `python -m anisofem trade` runs, the rungs
installed packages register (entry-point group RUNG_GROUP: anisognn's networks, export's ONNX
runtime), and which of them can model a given scene."""
from dataclasses import dataclass
from importlib.metadata import entry_points
from typing import Callable

import numpy as np

from ..reduced import FramedModel, ReducedModel
from ..reduced.framed import refusal as framed_refusal
from ..solvers import methods
from ..solvers.solve import Stepper

#: The entry-point group of rung providers: functions (scene, dt, notes) -> [Rung] that say in
#: notes (a list of str) what they cannot run.
RUNG_GROUP = "anisofem.rungs"


@dataclass
class Rung:
    """One way of rolling a scene forward.

    name: shown in tables. kind: "fem", "reduced" (a reduced model of the scene), or
    "surrogate" for a learned model's rung. make(scene,
    dt) returns advance(x, v) -> (x, v, info) for one step of dt, with info a dict holding
    "failed" (bool) and any of "iterations", "factorizations", "linear_iterations". dt_factor:
    the rung steps dt_factor times the scene's dt. refusal(scene): None where the rung can
    model the scene, else the note that says why not (rungs refused alike share one note).
    """
    name: str
    kind: str
    make: Callable
    dt_factor: int = 1
    refusal: Callable = None


def fem_rung(name, method="auto", dt_factor=1, **options):
    """A Rung stepping by anisofem.step with `method` and its options (anisofem.solvers.methods),
    through the scene's load curves from time 0 (Scene.at)."""
    def make(scene, dt):
        stepper = Stepper(scene, dt, method, **options)
        taken = 0

        def advance(x, v):
            nonlocal taken
            taken += 1
            stepper.scene = scene.at(taken * dt)  # loads on curves: at the step's end
            res = stepper(x, v)
            n = res.newton
            return res.x, res.v, {"failed": n.failed, "message": n.message,
                                  "iterations": n.iterations,
                                  "factorizations": n.factorizations,
                                  "linear_iterations": n.linear_iterations}
        return advance
    methods.make(method, 0, **options)  # bad options fail here (at any size), before any rollout
    return Rung(name, "fem", make, dt_factor)


def _stepping(build_seconds, dt, step):
    """advance(x, v) of a reduced rung: step() -> (the next positions (n, 3), NewtonReport);
    the first step's info carries the model's build time as "setup_seconds"."""
    setup = {"setup_seconds": build_seconds}

    def advance(x, v):
        nonlocal setup
        x_next, report = step()
        info = {"failed": not report.converged, "message": report.message,
                "iterations": report.iterations, **setup}
        setup = {}
        return x_next, (x_next - x) / dt, info
    return advance


def _schedule(scene, dt):
    """at(k) -> (extra nodal force (n, 3) N or None, controls (k,) or None) at the end of step
    k of dt s: the scene's forces and controls on load curves (Scene.at), over the scene as
    written, which the reduced models are built from."""
    if not scene.timed:
        return lambda k: (None, None)

    def at(k):
        now = scene.at(k * dt)
        force = now.external_force - scene.external_force
        return force, (now.control_values if scene.controls else None)
    return at


def reduced_rung(modes, snapshots=0):
    """A Rung stepping the scene's ReducedModel (anisofem.reduced) with `modes` vibration
    modes and their modal derivatives, or with `snapshots` > 0 the modes and that many
    principal directions of static equilibria under the scene's default declared loads. The
    model is built before the rollout, and follows the scene's forces and controls on load
    curves; its first step reports the build time as "setup_seconds"."""
    def make(scene, dt):
        model = ReducedModel(scene, modes=modes, snapshots=snapshots, validate=False)
        q, w = np.zeros(model.r), np.zeros(model.r)
        at, k = _schedule(scene, dt), 0

        def step():
            nonlocal q, w, k
            k += 1
            force, controls = at(k)
            q, w, report = model.step(q, w, dt, force=force, controls=controls)
            return model.positions(q), report
        return _stepping(model.build_seconds, dt, step)
    return Rung(f"reduced m{modes}" + (f" s{snapshots}" if snapshots else ""), "reduced",
                make)


def framed_rung(bands, coordinates):
    """A Rung stepping the scene's FramedModel (anisofem.reduced.framed): the body cut into
    `bands` bands of distance from its held nodes, each band's pieces in their own rotating
    frames with `coordinates` local coordinates, fitted to the scene's default declared loads.
    Its first step reports the build time as "setup_seconds"."""
    def make(scene, dt):
        model = FramedModel(scene, bands=bands, coordinates=coordinates, validate=False)
        now = before = model.rest()
        at, k = _schedule(scene, dt), 0

        def step():
            nonlocal now, before, k
            k += 1
            after, report = model.step(now, before, dt, force=at(k)[0])
            now, before = after, now
            return model.positions(now), report
        return _stepping(model.build_seconds, dt, step)
    def refusal(scene):
        why = framed_refusal(scene)
        return why and f"framed rungs not run: {why}"
    return Rung(f"reduced framed b{bands} c{coordinates}", "reduced", make, refusal=refusal)


def body_rung(body, modes, snapshots):
    """A Rung stepping a ReducedModel with `modes` modes and `snapshots` fitted directions
    built on `body`, a finer mesh of the scene's body whose first n vertices are the scene's
    (TetMesh.raised, TetMesh.refined), and drawn on the scene's mesh: the body's accuracy at the
    cost of a reduced step on the user's mesh. Returns (Rung, on_body): on_body() gives the
    last rollout's states on the body's whole mesh, {step: (x, v)}, formed after the timing
    (for the row's energy and volumes, which are the body's)."""
    steps = []
    model = None

    def make(scene, dt):
        nonlocal model
        model = model or ReducedModel(body, modes=modes, snapshots=snapshots, validate=False)
        n = scene.mesh.n_vertices
        rest, basis = model.x0[:n], model.basis[:3 * n]
        q, w = np.zeros(model.r), np.zeros(model.r)
        steps[:] = [(q, w)]

        def step():
            nonlocal q, w
            q, w, report = model.step(q, w, dt)
            steps.append((q, w))
            return rest + (basis @ q).reshape(n, 3), report
        return _stepping(model.build_seconds, dt, step)

    def on_body():
        return {k: (model.positions(q), (model.basis @ w).reshape(-1, 3))
                for k, (q, w) in enumerate(steps)}
    return Rung(f"reduced m{modes} s{snapshots} of the body", "reduced", make), on_body


#: Vibration modes of the listed modal reduced rungs (their bases hold 20, 27 and 44
#: coordinates): on the 0.1 m trade cantilevers 5 modes is the cheapest within 1% of the exact
#: rollout, 8 about 10x more accurate at 3-8x the cost, and past 8 the cost grows as r^4 for
#: little.
REDUCED_MODES = (5, 6, 8)


#: (modes, snapshots) of the listed load-fitted reduced rungs (r = 20 and 28): they follow the
#: 0.2 m cantilever's bending through large rotations, where the modal ones do not.
REDUCED_FITTED = ((4, 16), (8, 20))


#: (bands, coordinates) of the listed framed rungs: domains in their own frames, for bodies
#: whose parts swing far (a T's or a Y's arms under drags), where one linear basis drifts.
FRAMED = ((4, 12),)


def fem_rungs():
    """The anisofem ladder, exact first (the default method, "auto", to rtol 1e-8: exact
    Newton, or multigrid CG on large meshes): "xK" is a budget of K iterations per step, "rtol
    R" iterates to the relative tolerance R (1e-8 where none is named), "dt xK" steps K times
    longer, "reduced mK" the scene's reduced model with K vibration modes and their modal
    derivatives, "reduced mK sS" with K modes and S directions fitted to its declared loads,
    "reduced framed bB cC" its framed model in B bands with C local coordinates per domain."""
    return [fem_rung("exact"),
            fem_rung("newton x1", "newton", iterations=1),
            fem_rung("newton x2", "newton", iterations=2),
            fem_rung("reuse rtol 1e-2", "reuse", rtol=1e-2),
            fem_rung("reuse x3", "reuse", iterations=3),
            fem_rung("lbfgs rtol 1e-2", "lbfgs", rtol=1e-2),
            fem_rung("lbfgs x5", "lbfgs", iterations=5),
            fem_rung("cg jacobi rtol 1e-3", "cg", rtol=1e-3),
            fem_rung("cg factor x2", "cg", preconditioner="factor", forcing=0.01,
                     iterations=2),
            fem_rung("cg amg", "cg", preconditioner="amg"),
            fem_rung("cg amg rtol 1e-2", "cg", preconditioner="amg", rtol=1e-2),
            fem_rung("exact dt x2", dt_factor=2),
            fem_rung("exact dt x5", dt_factor=5)] + [reduced_rung(m) for m in REDUCED_MODES] + [
                reduced_rung(m, s) for m, s in REDUCED_FITTED] + [
                framed_rung(b, c) for b, c in FRAMED]


def select_rungs(rungs, names):
    """The exact rung and the rungs named in names (str list), in the ladder's order; an
    unknown name raises ValueError listing the known ones."""
    known = [r.name for r in rungs]
    unknown = [n for n in names if n not in known]
    if unknown:
        raise ValueError(f"rungs: no rung named {', '.join(map(repr, unknown))}; the rungs are "
                         f"{', '.join(map(repr, known))}")
    return [r for r in rungs if r.name == "exact" or r.name in names]


def physical_reference_only(rungs, inverted, notes):
    """rungs without the surrogate's when the exact rollout turns `inverted` elements inside
    out: a network is scored against the FEM's answer, and that answer is not physical."""
    if not inverted or all(r.kind != "surrogate" for r in rungs):
        return rungs
    notes.append(f"surrogate rungs not scored: the exact rollout turns {inverted} elements "
                 f"inside out (StVK), so it is no physical reference (--material neohookean "
                 f"keeps the scene physical)")
    return [r for r in rungs if r.kind != "surrogate"]


def representable(rungs, scene, notes):
    """rungs without those that cannot model the scene, saying so in notes: the reduced ones
    where it has Neo-Hookean elements (the reduced model's energy is exact only for the StVK
    base), held vertices or unnamed pressures on load curves; the surrogates where it has
    pressure, cables, load curves or activated fibers; any rung its own refusal turns away
    (Rung.refusal)."""
    left = {}
    if scene.neohookean.any():
        left["reduced"] = "the reduced model needs the StVK base material"
    if scene.pressures:
        left["surrogate"] = "the surrogates take nodal forces, not pressure"
    if scene.cables:
        left["surrogate"] = "the surrogates take nodal forces, not cables"
    if any(p.motion is not None or p.pressure is not None for p in scene.timed):
        left["reduced"] = ("the reduced rungs follow forces and controls on load curves, not "
                           "held vertices moved or unnamed pressures on them")
    if scene.timed:
        left["surrogate"] = "the surrogates take constant nodal forces, not load curves"
    if (scene.elements.rest2 != 1.0).any():
        left["surrogate"] = "the surrogates were trained on passive fibers, not activated ones"
    for kind, why in left.items():
        if any(r.kind == kind for r in rungs):
            notes.append(f"{kind} rungs not run: {why}")
            rungs = [r for r in rungs if r.kind != kind]
    kept = []
    for r in rungs:
        note = r.refusal(scene) if r.refusal else None
        if not note:
            kept.append(r)
        elif note not in notes:
            notes.append(note)
    return kept


def registered_rungs(scene, dt, notes):
    """The rungs for scene at dt (s) of every provider installed under RUNG_GROUP, by provider
    name; a provider that cannot be imported (its dependencies missing) is named in notes."""
    providers = sorted(entry_points(group=RUNG_GROUP), key=lambda e: e.name)
    if not providers:
        notes.append(f"surrogate rungs: none installed (no {RUNG_GROUP!r} entry points)")
    rungs = []
    for provider in providers:
        try:
            make = provider.load()
        except ImportError as err:
            notes.append(f"{provider.name} rungs skipped: {err}")
            continue
        rungs += make(scene, dt, notes)
    return rungs
