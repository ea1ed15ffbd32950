"""The speed/accuracy ladder measured on a user's own scene: every rung against the exact
rollout (`anisofem.trade`, `python -m anisofem trade`).

    table = anisofem.trade(scene, steps=100, dt=0.02)
    print(anisofem.trade_table(table))     # the rungs: .rungs; the table, the plot: .trade_report

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

import numpy as np

from .. import threads
from ..physics import metrics
from ..physics.inversion import volume_change
from ..physics.potential import Potential
from ..physics.scene import Scene
from ..solvers.solve import solve
from .rungs import (
    REDUCED_FITTED,
    Rung,
    body_rung,
    fem_rung,
    fem_rungs,
    physical_reference_only,
    registered_rungs,
    representable,
)

#: Energy gain (over |static potential|) above which a rung is called unstable.
ENERGY_GAIN_MAX = 0.01
#: Cores other processes keep busy during a rung's timing from which the trade times it again
#: and marks its row: beside another process spinning on one core, a step can be 2-3x slower
BUSY_CORES = 0.5


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
    tolerance = float(tolerance)
    if not 0 < tolerance < math.inf:
        raise ValueError(f"tolerance: a share of the static deflection > 0 (0.01: 1%), got "
                         f"{tolerance}")
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
    rungs = physical_reference_only(rungs, rows[0]["inverted"], notes)
    rungs = representable(rungs, scene, notes)
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
    note = linear_basis_note(rows, tolerance)
    if note:
        notes.append(note)
    return result


def linear_basis_note(rows, tolerance):
    """A note where every linear reduced rung misses the exact rollout by more than tolerance
    and a framed one does not: the body's motion is more than a linear basis holds (None
    otherwise)."""
    linear = [r for r in rows if r["kind"] == "reduced" and "framed" not in r["name"]]
    framed = [r for r in rows if r["kind"] == "reduced" and "framed" in r["name"]]
    if not linear or min(r["max_error"] for r in linear) <= tolerance:
        return None
    best = min(linear, key=lambda r: r["max_error"])
    within = [r for r in framed if r["stable"] and r["max_error"] <= tolerance]
    return (f"the linear reduced models miss by {100 * best['max_error']:.2g}% at best "
            f"({best['name']}): this body moves more than a linear basis holds"
            + (f"; the framed model ({within[0]['name']}) follows its frames' rotations"
               if within else "; a framed model (its parts in their own rotating frames) may "
                              "hold it"))


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


