"""The speed/accuracy ladder measured on a user's own scene: every rung against the exact
rollout (`anisofem.trade`, `python -m anisofem trade`).

    table = anisofem.trade(scene, steps=100, dt=0.02)
    print(anisofem.trade_table(table))

A rung is one way of rolling the scene forward: the exact rollout (the reference: the default
method to rtol 1e-8, exact Newton or, on large meshes, multigrid CG), Newton with a fixed
iteration budget, factorization reuse, L-BFGS, inexact Newton (CG with the diagonal, a kept
factorization or multigrid as preconditioner), the exact rollout at a larger time step, the
scene's reduced model (anisofem.reduced) at a few basis sizes, and the rungs that installed packages register under the entry-point group "anisofem.rungs"
(anisognn's shipped networks alone, with their Galerkin passes and as the warm start of one
Newton iteration; export's ONNX runtime). Each rung rolls the scene out from rest
in the same process; what is compared:

- errors: at each checked time, the tip error |u(tip) - u_exact(tip)| / |u_static(tip)|, where
  the tip is the set of vertices whose static displacement is within 1% of the largest (for a
  cantilever: its free end) and u_static the converged static solution;
- field_errors: max over vertices |u - u_exact| over the largest static displacement;
- tip: the tip's mean displacement (3,) in m at each checked time;
- continuum_errors (with bodies: the same body on finer meshes, e.g. quadratic or refined):
  at each checked time |tip - tip of the reference| over the reference's static tip
  deflection, the reference being the exact rollout of the finest body; the error a user
  gets against the body rather than against the same mesh. The bodies' own rows (kind
  "discretization") have for errors their tip's difference from the scene's exact rollout;
- ms_per_step: wall time per step of the scene's dt, all steps but the first (which holds
  one-time set-up and compilation) averaged, so amortized refactorizations count; a rung with a
  larger step reports its time per dt of simulated time (ms per own step / dt_factor);
- setup_seconds (reduced rungs): building the model before the rollout (basis and
  polynomial), not in ms_per_step;
- energy_drift: max over time of H(t) - H(0), H = kinetic + elastic - f_ext . x, over |the
  static potential|: backward Euler never gains energy (<= 0), a rung that does is unstable;
- stable: every step was taken (none failed), every state finite, energy_drift <= 0.01;
- busy_cores: the cores other processes kept busy while the rung was timed
  (anisofem.threads.LoadMeter); from BUSY_CORES on, the rung is timed twice, the calmer run
  kept (timed_twice), its row marked * and the table notes it. The result's "machine" holds
  the core count and the load average at the start and the end;
- min_volume_ratio: the smallest det(F) over tets and time (<= 0: an inverted element);
  inverted: the most tets turned inside out (det F <= 0) at any recorded state;
  max_volume_change: the largest |det(F) - 1|.
"""
import math
import os
import sys
import time
from dataclasses import dataclass
from importlib.metadata import entry_points
from typing import Callable

import numpy as np

from . import methods, metrics, threads
from .files import atomic_path
from .inversion import volume_change
from .potential import Potential
from .reduced import FramedModel, ReducedModel
from .reduced.framed import refusal as framed_refusal
from .scene import Scene
from .solve import Stepper, solve

#: Energy gain (over |static potential|) above which a rung is called unstable.
ENERGY_GAIN_MAX = 0.01
#: Cores other processes keep busy during a rung's timing from which the trade times it again
#: and marks its row: beside another process spinning on one core, a step can be 2-3x slower
BUSY_CORES = 0.5
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
    """A Rung stepping by anisofem.step with `method` and its options (anisofem.methods),
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


def reduced_rung(modes, snapshots=0):
    """A Rung stepping the scene's ReducedModel (anisofem.reduced) with `modes` vibration
    modes and their modal derivatives, or with `snapshots` > 0 the modes and that many
    principal directions of static equilibria under the scene's default declared loads. The
    model is built before the rollout; its first step reports the build time as
    "setup_seconds"."""
    def make(scene, dt):
        model = ReducedModel(scene, modes=modes, snapshots=snapshots, validate=False)
        q, w = np.zeros(model.r), np.zeros(model.r)

        def step():
            nonlocal q, w
            q, w, report = model.step(q, w, dt)
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

        def step():
            nonlocal now, before
            after, report = model.step(now, before, dt)
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


def checked_steps(steps, multiple):
    """Steps (of the scene's dt) at which errors are measured: about steps/10 (early
    transient), steps/4, steps/2 and the last, rounded up to multiples of `multiple` so that
    rungs with a larger step land on them."""
    picks = {max(multiple, multiple * math.ceil(steps * f / multiple)) for f in
             (0.1, 0.25, 0.5)}
    return sorted(k for k in picks | {steps} if k <= steps)


def trade(scene, steps=100, dt=0.02, rungs=None, tolerance=0.01, progress=True, name="",
          bodies=()):
    """Run every rung on scene and compare it with the exact rollout.

    scene: an anisofem.Scene (held enough for a static solve: its static deflection is the
    error scale). steps: steps of dt (s) from rest. rungs: Rungs (default fem_rungs() plus
    registered_rungs(); fem_rungs() alone leaves the surrogates out). tolerance: recommend the
    cheapest stable rung whose errors are all within it. progress: report each
    rung's progress on stderr. name: what the scene is called in tables and plots.
    bodies: the same body on finer meshes, [(name, Scene)], each mesh nested in the scene's
    (its first n vertices are the scene's, as TetMesh.raised and TetMesh.refined keep them):
    each is rolled out exactly as a row of kind "discretization" (its errors: its tip's
    difference from the scene's exact rollout), and the one with the most unknowns is the
    continuum reference. Every row then gains continuum_errors and max_continuum_error
    (module docstring), and the result "reference" and "recommended_continuum".

    Returns a dict: {"scene": {...}, "times": [s], "rungs": [{"name", "kind", "ms_per_step",
    "errors", "max_error", "stable", "on_front", ...}], "recommended": name or None,
    "notes": [...]} (see the module docstring for the quantities).
    """
    if not isinstance(scene, Scene):
        raise TypeError(f"scene: expected an anisofem.Scene, got {type(scene).__name__}")
    steps, dt = int(steps), float(dt)
    if steps < 1:
        raise ValueError(f"steps: must be >= 1, got {steps}")
    if not dt > 0:
        raise ValueError(f"dt: must be > 0 s, got {dt}")
    notes = []
    if rungs is None:
        rungs = fem_rungs() + registered_rungs(scene, dt, notes)
    if not rungs or rungs[0].name != "exact":
        raise ValueError("rungs: the first rung must be the exact one (named 'exact')")
    multiple = math.lcm(*(r.dt_factor for r in rungs))
    if steps % multiple:
        raise ValueError(f"steps: must be a multiple of {multiple} (the rungs' dt factors)")
    check = checked_steps(steps, multiple)
    load_start = os.getloadavg()
    static = solve(scene)
    if not static.converged:
        raise RuntimeError(f"trade: the static solve failed ({static.message}); no error scale")
    u_static = static.x - scene.mesh.vertices
    size = np.linalg.norm(u_static, axis=1)
    tip = metrics.moving_tip(u_static)
    deflection = float(np.linalg.norm(u_static[tip].mean(0)))
    if deflection == 0:
        raise ValueError("scene: the static solution does not move; nothing to compare")
    static_energy = abs(Potential(scene).energy(static.x))
    exact = _roll(rungs[0], scene, dt, steps, "exact" if progress else None)
    ref = exact["positions"]

    def row(rung, run):
        return _row(rung, run, ref, check, tip, deflection, size.max(), static_energy, scene,
                    dt)
    rows = [row(rungs[0], exact)]
    rungs = _physical_reference_only(rungs, rows[0]["inverted"], notes)
    rungs = _representable(rungs, scene, notes)
    for i, rung in enumerate(rungs[1:], 2):
        label = f"[{i}/{len(rungs)}] {rung.name}"
        rows.append(row(rung, _roll(rung, scene, dt, steps, label if progress else None)))
    result = {"scene": {"name": name, "tets": scene.mesh.n_tets,
                        "vertices": scene.mesh.n_vertices, "unknowns": scene.n_free, "dt": dt,
                        "steps": steps, "deflection": deflection, "tip_vertices": tip.size},
              "times": [k * dt for k in check], "tolerance": tolerance, "rungs": rows,
              "notes": notes, "machine": _machine(rows, load_start)}
    if bodies:
        _against_the_body(result, scene, bodies, ref, check, tip, dt, steps, progress)
    mark_front(rows)
    good = [r for r in rows if r["stable"] and r["max_error"] <= tolerance]
    result["recommended"] = min(good, key=lambda r: r["ms_per_step"])["name"] if good else None
    return result


def _against_the_body(result, scene, bodies, ref, check, tip, dt, steps, progress):
    """Roll out each (name, Scene) of bodies exactly, add their rows and the row of a reduced
    model of the finest drawn on the scene's mesh (body_rung), and give every row its continuum
    errors against the finest (trade's bodies)."""
    n = scene.mesh.n_vertices
    for label, body in bodies:
        if body.mesh.n_vertices < n or not np.allclose(body.mesh.vertices[:n], scene.mesh.vertices,
                                                       rtol=0, atol=1e-12 * scene.mesh.size):
            raise ValueError(f"bodies: {label!r} is not the scene's mesh refined or raised "
                             f"(its first {n} vertices must be the scene's)")
    runs = []
    for i, (label, body) in enumerate(bodies, 1):
        run = _roll(fem_rung(label), body, dt, steps,
                    f"[body {i}/{len(bodies)}] {label}" if progress else None)
        static = solve(body)
        rung = Rung(label, "discretization", None)
        row = _row(rung, run, ref, check, tip, result["scene"]["deflection"],
                   float(np.linalg.norm(static.x - body.mesh.vertices, axis=1).max()),
                   abs(Potential(body).energy(static.x)), body, dt, shared=n)
        row.update(tets=body.mesh.n_tets, unknowns=body.n_free, order=body.mesh.order)
        result["rungs"].append(row)
        runs.append((label, body, run, static))
    name, body, run, static = max(runs, key=lambda b: b[1].n_free)
    if not body.neohookean.any():
        rung, on_body = body_rung(body, *REDUCED_FITTED[0])
        drawn = _roll(rung, scene, dt, steps, f"[body] {rung.name}" if progress else None)
        row = _row(rung, dict(drawn, positions=on_body()), ref, check, tip,
                   result["scene"]["deflection"],
                   float(np.linalg.norm(static.x - body.mesh.vertices, axis=1).max()),
                   abs(Potential(body).energy(static.x)), body, dt, shared=n)
        row.update(body=name)
        result["rungs"].append(row)
    else:
        result["notes"].append("no reduced rung of the body: it needs the StVK base material")
    reference = {k: run["positions"][k][0][tip].mean(0) - body.mesh.vertices[tip].mean(0)
                 for k in check if k in run["positions"]}
    deflection = float(np.linalg.norm((static.x - body.mesh.vertices)[tip].mean(0)))
    for row in result["rungs"]:
        row["continuum_errors"] = [
            float(np.linalg.norm(np.asarray(t) - reference[k])) / deflection
            if t is not None and k in reference else float("inf")
            for k, t in zip(check, row["tip"])]
        row["max_continuum_error"] = max(row["continuum_errors"])
    result["reference"] = {"name": name, "tets": body.mesh.n_tets, "order": body.mesh.order,
                           "unknowns": body.n_free, "deflection": deflection}
    good = [r for r in result["rungs"]
            if r["stable"] and r["max_continuum_error"] <= result["tolerance"]]
    result["recommended_continuum"] = (min(good, key=lambda r: r["ms_per_step"])["name"]
                                       if good else None)


def mark_front(rows):
    """Set each row's "on_front": stable, and no other stable rung is at least as fast and at
    least as accurate at every checked time (and better in one of these)."""
    stable = [r for r in rows if r["stable"]]
    for r in rows:
        r["on_front"] = r["stable"] and not any(
            o is not r and o["ms_per_step"] <= r["ms_per_step"]
            and all(a <= b for a, b in zip(o["errors"], r["errors"]))
            and (o["ms_per_step"] < r["ms_per_step"] or o["errors"] != r["errors"])
            for o in stable)


def _physical_reference_only(rungs, inverted, notes):
    """rungs without the surrogate's when the exact rollout turns `inverted` elements inside
    out: a network is scored against the FEM's answer, and that answer is not physical."""
    if not inverted or all(r.kind != "surrogate" for r in rungs):
        return rungs
    notes.append(f"surrogate rungs not scored: the exact rollout turns {inverted} elements "
                 f"inside out (StVK), so it is no physical reference (--material neohookean "
                 f"keeps the scene physical)")
    return [r for r in rungs if r.kind != "surrogate"]


def _representable(rungs, scene, notes):
    """rungs without those that cannot model the scene, saying so in notes: the reduced ones
    where it has Neo-Hookean elements (the reduced model's energy is exact only for the StVK
    base) or load curves; the surrogates where it has pressure or load curves; any rung its
    own refusal turns away (Rung.refusal)."""
    left = {}
    if scene.neohookean.any():
        left["reduced"] = "the reduced model needs the StVK base material"
    if scene.pressures:
        left["surrogate"] = "the surrogates take nodal forces, not pressure"
    if scene.timed:
        left["reduced"] = "the reduced rungs hold the loads constant, not on their curves"
        left["surrogate"] = "the surrogates take constant nodal forces, not load curves"
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


def _roll(rung, scene, dt, steps, label):
    """_rollout, timed again once if other processes kept BUSY_CORES or more cores busy while
    it ran (the calmer of the two kept): the result of _rollout with "busy_cores", the cores
    the others kept busy (anisofem.threads.LoadMeter; 0 where it cannot measure), and
    "timed_twice"."""
    run = _rollout(rung, scene, dt, steps, label)
    timed_twice = run["busy_cores"] >= BUSY_CORES
    if timed_twice:
        again = _rollout(rung, scene, dt, steps, label and f"{label} (timed again: the machine "
                                                             f"was busy)")
        run = min(run, again, key=lambda r: r["busy_cores"])
    run["timed_twice"] = timed_twice
    return run


def _rollout(rung, scene, dt, steps, label):
    """Roll rung out for steps of dt: positions and velocities at every scene step it lands on
    (dict keyed by scene step), per-step seconds, infos, whether it completed, the cores other
    processes kept busy meanwhile."""
    h = dt * rung.dt_factor
    n_own = steps // rung.dt_factor
    live = sys.stderr.isatty()
    advance = rung.make(scene, h)
    x = scene.at(0.0).initial_positions()
    v = np.zeros_like(x)
    states = {0: (x, v)}
    seconds, infos, completed = [], [], True
    t_last = time.perf_counter()
    meter = threads.LoadMeter()
    for k in range(n_own):
        try:
            x, v, info = advance(x, v)
        except FloatingPointError as err:
            info = {"failed": True, "message": str(err)}
        now = time.perf_counter()
        seconds.append(now - t_last)
        t_last = now
        infos.append(info)
        if info["failed"] or not (np.isfinite(x).all() and np.isfinite(v).all()):
            completed = False
            break
        states[(k + 1) * rung.dt_factor] = (x, v)
        if label is not None and live and (k + 1) % max(1, n_own // 20) == 0:
            print(f"\r{label}: step {k + 1}/{n_own}", end="", file=sys.stderr, flush=True)
    if label is not None:
        end = "" if completed else (f", stopped at step {len(seconds)}: "
                                    f"{infos[-1].get('message', 'failed')}")
        print(f"\r{label}: {sum(seconds):.1f} s{end}" + " " * 20, file=sys.stderr, flush=True)
    return {"positions": states, "seconds": seconds, "infos": infos, "completed": completed,
            "busy_cores": meter.others(wait=True) or 0.0}


def _machine(rows, load_start):
    """What the trade ran on: cores, the load average (1, 5, 15 minutes) at its start and end,
    the thread count the user fixed (None: chosen by load, anisofem.threads), and the most
    cores other processes kept busy during a rung's timing."""
    return {"cores": len(threads.cores()), "load_average_start": list(load_start),
            "load_average_end": list(os.getloadavg()), "threads": threads.fixed(),
            "busy_cores": max(r["busy_cores"] for r in rows)}


def _row(rung, run, ref, check, tip, deflection, u_max, static_energy, scene, dt, shared=None):
    """One rung's table row (see the module docstring for the quantities); shared: compare the
    first `shared` vertices only (a finer mesh of the same body), default all."""
    states = run["positions"]
    errors, field_errors, tips = [], [], []
    rest = scene.mesh.vertices[tip].mean(0)
    for k in check:
        if k not in states:
            errors.append(float("inf"))
            field_errors.append(float("inf"))
            tips.append(None)
            continue
        x = states[k][0]
        d = x[:shared] - ref[k][0]
        errors.append(float(np.linalg.norm(d[tip].mean(0))) / deflection)
        field_errors.append(float(np.linalg.norm(d, axis=1).max()) / u_max)
        tips.append((x[tip].mean(0) - rest).tolist())
    pot = Potential(scene)
    mass = scene.masses
    energies = [pot.energy(x) + 0.5 * float((mass[:, None] * v * v).sum())
                for x, v in states.values()]
    drift = (max(energies) - energies[0]) / static_energy
    change = [volume_change(scene.mesh, x) for x, _ in states.values()]
    ratio = min(float(c.min()) for c in change) + 1.0
    inverted = max(int((c <= -1.0).sum()) for c in change)
    secs = run["seconds"]
    timed = secs[1:] if len(secs) > 1 else secs
    per_step = 1e3 * float(np.mean(timed)) / rung.dt_factor
    row = {"name": rung.name, "kind": rung.kind, "dt": dt * rung.dt_factor,
           "ms_per_step": per_step,
           "ms_median": 1e3 * float(np.median(timed)) / rung.dt_factor,
           "errors": errors, "max_error": max(errors), "field_errors": field_errors,
           "energy_drift": drift, "min_volume_ratio": ratio, "inverted": inverted,
           "max_volume_change": max(float(np.abs(c).max()) for c in change),
           "stable": bool(run["completed"] and drift <= ENERGY_GAIN_MAX),
           "steps_taken": len(secs), "tip": tips, "busy_cores": run.get("busy_cores", 0.0),
           "timed_twice": run.get("timed_twice", False)}
    setup = [info["setup_seconds"] for info in run["infos"] if "setup_seconds" in info]
    if setup:
        row["setup_seconds"] = setup[0]
    for key in ("iterations", "factorizations", "linear_iterations"):
        values = [info[key] for info in run["infos"] if key in info]
        if values:
            row[key + "_per_step"] = float(np.mean(values))
    return row


def trade_table(result):
    """The trade result as a text table."""
    times = "/".join(f"{t:g}" for t in result["times"])
    body = "reference" in result
    vs_body = f"{'vs body':>9}" if body else ""
    head = (f"{'rung':<27} {'ms/step':>8} {'x exact':>8} {'tip error at t = ' + times + ' s':<36}"
            f"{vs_body} {'its':>5} {'drift':>8} {'min J':>6} stable")
    exact = result["rungs"][0]["ms_per_step"]
    lines = [head, "-" * len(head)]
    for r in result["rungs"]:
        errs = " / ".join(f"{e:.2g}" for e in r["errors"])
        its = r.get("iterations_per_step")
        vs_body = f" {r['max_continuum_error']:8.2g}" if body else ""
        mark = "*" if r.get("busy_cores", 0.0) >= BUSY_CORES else " "
        lines.append(f"{r['name']:<27}{mark}{r['ms_per_step']:8.3g} {exact / r['ms_per_step']:8.2f} "
                     f"{errs:<36}{vs_body} {'' if its is None else f'{its:.1f}':>5} "
                     f"{r['energy_drift']:8.1e} {r['min_volume_ratio']:6.2f} {r['stable']}")
    s = result["scene"]
    lines.append(f"{s['tets']} tets, {s['unknowns']} unknowns, dt = {s['dt']} s, {s['steps']} "
                 f"steps; errors relative to the static tip deflection {s['deflection']:.4g} m")
    rec = result["recommended"]
    lines.append(f"cheapest stable rung within {result['tolerance']:g} at every checked time: "
                 f"{rec if rec else 'none'}")
    if body:
        ref = result["reference"]
        rec = result["recommended_continuum"]
        lines.append(f"vs body: the largest tip error against {ref['name']} ({ref['tets']} tets, "
                     f"order {ref['order']}, {ref['unknowns']} unknowns), over its static "
                     f"deflection {ref['deflection']:.4g} m; cheapest within "
                     f"{result['tolerance']:g} of it: {rec if rec else 'none'}")
    lines += [f"note: {n}" for n in result["notes"]]
    busy = [r for r in result["rungs"] if r.get("busy_cores", 0.0) >= BUSY_CORES]
    if busy:
        lines.append(
            f"warning: the machine was busy: other processes kept up to "
            f"{max(r['busy_cores'] for r in busy):.1f} of {result['machine']['cores']} cores "
            f"busy while {len(busy)} rungs were timed (marked *, timed twice and the calmer "
            f"run kept); their ms/step are slower than on an idle machine")
    return "\n".join(lines)


def _label_positions(ax, rows, y_of, xlim, ylim, reference="exact"):
    """Where the plot's rung labels go, lowest rung first, each moved up while it would overlap
    a label already placed or another rung's marker: ([(text, (x, y) of the rung, (x, y) of
    the label, moved)], the y of the highest label's top), in data coordinates of the log-log
    axes ax with limits xlim, ylim."""
    # sizes in decades: about 6.5 and 11 pixels per character width and line height, markers
    # about 5 pixels across from their centre
    box = ax.get_window_extent()
    char_w = 6.5 * math.log10(xlim[1] / xlim[0]) / box.width
    line_h = 11.0 * math.log10(ylim[1] / ylim[0]) / box.height
    mark_x, mark_y = 5.0 * char_w / 6.5, 5.0 * line_h / 11.0
    markers = [(math.log10(r["ms_per_step"]), math.log10(y_of(r))) for r in rows]
    placed, labels = [], []
    for r in sorted(rows, key=y_of):
        x, y = r["ms_per_step"], y_of(r)
        text = r["name"] + (" (reference)" if r["name"] == reference else "")
        lx, ly, w = math.log10(x) + 1.2 * mark_x, math.log10(y) - 0.4 * line_h, len(text) * char_w

        def hits(ly):
            return any(lx < px + pw and px < lx + w and abs(ly - py) < line_h
                       for px, py, pw in placed) or any(
                lx - mark_x < mx < lx + w + mark_x and ly - mark_y < my < ly + line_h + mark_y
                for mx, my in markers if (mx, my) != (math.log10(x), math.log10(y)))
        start = ly
        while hits(ly):
            ly += 0.5 * line_h
        placed.append((lx, ly, w))
        labels.append((text, (x, y), (10 ** lx, 10 ** ly), ly > start))
    top = max((py for _, py, _ in placed), default=-math.inf) + 1.5 * line_h
    return labels, 10 ** top


def plot(result, path):
    """Save the Pareto plot of a trade result to path (PNG): ms/step against the largest tip
    error over the checked times, log-log, one marker per rung, the front joined."""
    try:
        import matplotlib
    except ImportError:
        raise ImportError("png: the trade plot needs matplotlib (pip install matplotlib)") from None
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker

    rows = result["rungs"]
    # against the body where the trade has a continuum reference, else against exact
    error = "max_continuum_error" if "reference" in result else "max_error"
    finite = [r[error] for r in rows if 0 < r[error] < math.inf]
    floor = min(finite) / 10 if finite else 1e-6
    ceiling = max(finite) * 10 if finite else 1.0
    fig, ax = plt.subplots(figsize=(10, 5.5))
    ax.axhline(result["tolerance"], color="0.6", lw=0.8, ls="--")
    def y_of(r):
        return min(max(r[error], floor), ceiling)

    # the front in this plot's two numbers: stable rungs no other is faster and more exact than
    front, best = [], math.inf
    for r in sorted((r for r in rows if r["stable"]), key=lambda r: (r["ms_per_step"],
                                                                     r[error])):
        if r[error] < best:
            front.append(r)
            best = r[error]
    xs = [r["ms_per_step"] for r in front]
    ys = [y_of(r) for r in front]
    ax.step(xs, ys, where="post", color="tab:green", lw=6, alpha=0.25,
            solid_capstyle="round", label="Pareto front")
    styles = {"fem": ("o", "tab:blue", "anisofem"), "reduced": ("D", "tab:purple", "reduced model"),
              "surrogate": ("s", "tab:orange", "surrogate"),
              "discretization": ("^", "tab:brown", "finer mesh, exact")}
    recommended = result.get("recommended_continuum") if error != "max_error" else \
        result["recommended"]
    reference = result["reference"]["name"] if error != "max_error" else "exact"
    ax.set_xscale("log")
    ax.set_yscale("log")
    ms = [r["ms_per_step"] for r in rows]
    xlim = (min(ms) / 1.5, max(ms) * 4)
    ylim = (floor / 2, ceiling * 2)
    ax.set_xlim(*xlim)
    ax.set_ylim(*ylim)
    ax.xaxis.set_major_locator(matplotlib.ticker.LogLocator(subs=(1, 2, 5)))
    ax.xaxis.set_major_formatter(matplotlib.ticker.FuncFormatter(lambda v, _: f"{v:g}"))
    ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
    ax.text(xlim[1] / 1.1, result["tolerance"] * 1.1, f"tolerance {result['tolerance']:g}",
            color="0.4", fontsize=8, ha="right")
    shown = set()
    for r in rows:
        marker, color, label = styles[r["kind"]]
        if not r["stable"]:
            marker, color, label = "x", "tab:red", "unstable or failed"
        ax.scatter(r["ms_per_step"], y_of(r), marker=marker, color=color, s=50, zorder=3,
                   label=None if label in shown else label)
        shown.add(label)
        if r["name"] == recommended:
            ax.scatter(r["ms_per_step"], y_of(r), marker="o", s=220, facecolors="none",
                       edgecolors="tab:green", linewidths=2, zorder=4,
                       label=f"recommended (within {result['tolerance']:g}"
                             f"{' of the body' if error != 'max_error' else ''})")
    labels, top = _label_positions(ax, rows, y_of, xlim, ylim, reference)
    for _ in range(3):  # the axes grow to hold the highest label; the labels are placed anew
        if top <= ylim[1]:
            break
        ylim = (ylim[0], top)
        ax.set_ylim(*ylim)
        labels, top = _label_positions(ax, rows, y_of, xlim, ylim, reference)
    for text, xy, xytext, moved in labels:
        ax.annotate(text, xy, xytext=xytext, fontsize=7.5, va="bottom",
                    arrowprops={"arrowstyle": "-", "color": "0.7", "lw": 0.5} if moved else None)
    ax.set_xlabel("ms per step of dt (this machine, one process)")
    times = ", ".join(f"{t:g}" for t in result["times"])
    against = (f"against {result['reference']['name']}" if error != "max_error"
               else "against the exact step")
    ax.set_ylabel(f"largest tip error {against}\nat t = {times} s (fraction of the static "
                  f"deflection)")
    sc = result["scene"]
    ax.set_title(f"{os.path.basename(sc['name']) or 'scene'}: {sc['tets']:,} tets, "
                 f"dt = {sc['dt']:g} s, {sc['steps']} steps", fontsize=10)
    ax.grid(True, which="major", alpha=0.3)
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)
    fig.tight_layout()
    with atomic_path(path, ".png") as tmp:
        fig.savefig(tmp, dpi=120, format="png")
    plt.close(fig)
