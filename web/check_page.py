"""`make test-web`: the page in a real headless Chromium against export/runtime.py.

Serves web/ on 127.0.0.1, runs web/e2e.mjs (playwright-core driving the distribution's
Chromium), and checks that
- the positions of the cantilever in the page (onnxruntime-web, WASM) at each of CHECKPOINTS
  are within BOUNDS of the largest displacement of export/runtime.py's rollout of the same
  baked scene (onnxruntime, CPU);
- the page drew: the screenshot (web/out/page.png, kept as an artifact) is not blank;
- dragging the tip upwards with the mouse raises it by more than 1 mm;
- the other scenes (cylinder, T, Y), chosen from the menu, step without a message;
- a file that is not a model and a scene the model cannot step each show a readable message;
- with the reduced models (the stepper menu; the C runtime built to WebAssembly): the
  cantilever's positions at CHECKPOINTS within REDUCED_BOUND of runtime.ReducedSimulator's, the
  drag raises its tip, and every scene steps without a message; the T's framed model, its
  foot carried (the page's "swing the held end"), within REDUCED_BOUND of
  framed_runtime.FramedSimulator's stepped with the same bases, the page stating its
  validation error; the cantilever's reduced model and the T's and Y's framed ones under a
  swinging drag within DRAG_BOUND of the numpy runtimes at every step; the tentacle's
  reduced model with its four controls set every step within DRAG_BOUND of the numpy
  runtime's, with a slider per control that sets its control; a reduced model's corrupt file
  shows the runtime's message.
Prints the in-browser and the onnxruntime (CPU) ms per step, and each reduced model's step
time in the page (the median and mean over 300 steps).
"""
import functools
import http.server
import json
import os
import re
import subprocess
import sys
import threading
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.dirname(HERE))

from export.writers import bake
from export import framed_runtime, runtime

#: steps at which the page's positions are compared with runtime.py's, and the largest distance
#: allowed at each, over the largest displacement of the rollout. One step agrees to float32
#: rounding; over the transient the shipped step amplifies the two builds' different rounding
#: (README: float32 and float64 rollouts of the network part by up to 1e-2 of the deflection)
CHECKPOINTS = (1, 10, 50, 100, 200)
BOUNDS = (1e-5, 1e-3, 5e-2, 5e-2, 5e-2)
ANGLE = 45.0
#: the reduced model in the page against runtime.py's, over the largest displacement: the same
#: float64 arithmetic in another order
REDUCED_BOUND = 1e-6
#: the reduced models under the swinging drag in the page against the numpy runtimes, every
#: step, over the largest displacement
DRAG_BOUND = 1e-9
#: steps at which the T's framed model in the page is compared with framed_runtime.py's
FRAMED_CHECKPOINTS = (1, 10, 50)


class _Quiet(http.server.SimpleHTTPRequestHandler):
    """Serves quietly, the page cross-origin isolated: its performance.now() then ticks in
    microseconds rather than in 0.1 ms steps, fine enough to time a step."""

    def end_headers(self):
        self.send_header("Cross-Origin-Opener-Policy", "same-origin")
        self.send_header("Cross-Origin-Embedder-Policy", "require-corp")
        super().end_headers()

    def log_message(self, *args):
        pass


def serve(folder):
    """(server, base URL) of a thread serving folder on 127.0.0.1 (a free port)."""
    handler = functools.partial(_Quiet, directory=folder)
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    return server, f"http://127.0.0.1:{server.server_address[1]}"


def reference(model):
    """(positions at CHECKPOINTS (k, n, 3), largest displacement over the rollout (m), ms per
    step) of runtime.py's rollout of the baked cantilever at fiber angle ANGLE."""
    header, arrays = runtime.read_arrays(os.path.join(HERE, "scenes", "cantilever"))
    vertices, tets, held = bake.scene_mesh("cantilever")
    sim = runtime.OnnxSimulator(model, vertices, tets, fixed=held,
                                fiber_direction=bake.fiber_direction(ANGLE),
                                fiber_stiffness=header["trained_material"]["young"])
    for name, value in sim.constants.items():
        baked = arrays[name + f"@{ANGLE:g}"] if name in bake.FIBER_INPUTS else arrays[name]
        assert np.array_equal(baked, value), f"baked {name} differs from runtime.py's"
    force = sim.masses[:, None] * np.asarray(header["gravity"])
    steps = CHECKPOINTS[-1]
    start = time.perf_counter()
    positions = sim.rollout(steps, force)
    ms = 1e3 * (time.perf_counter() - start) / steps
    largest = float(np.linalg.norm(positions - vertices, axis=2).max())
    return positions[list(CHECKPOINTS)], largest, ms


def reduced_reference():
    """(positions at CHECKPOINTS (k, n, 3), largest displacement (m), ms per step) of
    runtime.ReducedSimulator's rollout of the cantilever's reduced model at fiber angle ANGLE."""
    path = os.path.join(HERE, "scenes", "cantilever-reduced")
    sim = runtime.ReducedSimulator(path, angle=ANGLE)
    force = sim.masses[:, None] * np.asarray(sim.header["gravity"])
    q, w = sim.rest_state()
    positions, start = [], time.perf_counter()
    for step in range(1, CHECKPOINTS[-1] + 1):
        q, w = sim.step(q, w, force, sim.header["dt"])
        if step in CHECKPOINTS:
            positions.append(sim.positions(q))
    ms = 1e3 * (time.perf_counter() - start) / CHECKPOINTS[-1]
    positions = np.asarray(positions)
    return positions, float(np.linalg.norm(positions - sim.rest_positions, axis=2).max()), ms


def drag_gaps(drags):
    """{scene: (the largest gap over every step of the page's drag rollout against the numpy
    runtime's of the same file, angle and forces, over the largest displacement; the largest
    displacement, m)} for the cantilever's reduced model and the T's and Y's framed ones."""
    gaps = {}
    for name, run in drags.items():
        path = os.path.join(HERE, "scenes", f"{name}-reduced")
        header, _ = runtime.read_arrays(path)
        framed = header["model_format"] == framed_runtime.FRAMED_FORMAT
        sim = (framed_runtime.FramedSimulator if framed else runtime.ReducedSimulator)(
            path, angle=run["fiberAngle"])
        gravity = sim.masses[:, None] * np.asarray(header["gravity"])
        now = before = sim.rest_state()
        expected = []
        for f in run["forces"]:
            force = gravity.copy()
            force[run["vertex"]] += f
            if framed:
                now, before = sim.step(now, before, force, header["dt"]), now
                expected.append(sim.positions(now))
            else:
                now = sim.step(*now, force, header["dt"])
                expected.append(sim.positions(now[0]))
        expected = np.asarray(expected)
        got = np.asarray(run["positions"]).reshape(expected.shape)
        largest = float(np.abs(expected - sim.rest_positions).max())
        gaps[name] = (float(np.abs(got - expected).max()) / largest, largest)
    return gaps


def controlled_gap(run):
    """(the largest gap over every step of the page's controlled rollout of the tentacle
    against runtime.ReducedSimulator's under the same controls and the same moves of its ball,
    over the largest displacement; the largest displacement, m; the gap between the two balls'
    centers at the end, m; the ball's y there, m)."""
    path = os.path.join(HERE, "scenes", "tentacle-reduced")
    sim = runtime.ReducedSimulator(path)
    gravity = sim.masses[:, None] * np.asarray(sim.header["gravity"])
    q, w = sim.rest_state()
    expected = []
    for values, move in zip(run["schedule"], run["moves"]):
        if move:
            sim.move_obstacle(int(move[0]), move[1:])
        q, w = sim.step(q, w, gravity, sim.header["dt"], controls=values)
        expected.append(sim.positions(q))
    expected = np.asarray(expected)
    got = np.asarray(run["positions"]).reshape(expected.shape)
    largest = float(np.abs(expected - sim.rest_positions).max())
    ball = sim.contact.obstacles[1]["center"]
    return (float(np.abs(got - expected).max()) / largest, largest,
            float(np.abs(np.asarray(run["obstacles"][1]) - ball).max()), float(ball[1]))


def framed_reference(bases):
    """(positions at FRAMED_CHECKPOINTS (k, n, 3), largest displacement (m), ms per step, the
    model's largest validation tip error) of framed_runtime.FramedSimulator's rollout of the
    T's framed model at fiber angle ANGLE, its held vertices at bases[k] ([R_g | c_g], 12
    numbers row by row, or None: unmoved) after step k + 1."""
    sim = framed_runtime.FramedSimulator(os.path.join(HERE, "scenes", "t-reduced"),
                                         angle=ANGLE)
    force = sim.masses[:, None] * np.asarray(sim.header["gravity"])
    now = before = sim.rest_state()
    positions, start = [], time.perf_counter()
    for step in range(1, FRAMED_CHECKPOINTS[-1] + 1):
        base = bases[step - 1]
        base = None if base is None else np.reshape(base, (3, 4))
        now, before = sim.step(now, before, force, sim.header["dt"], base=base), now
        if step in FRAMED_CHECKPOINTS:
            positions.append(sim.positions(now))
    ms = 1e3 * (time.perf_counter() - start) / FRAMED_CHECKPOINTS[-1]
    positions = np.asarray(positions)
    tip = sim.header["validation"][sim.header["fiber_angles"].index(ANGLE)]["tip_error"]
    return (positions, float(np.linalg.norm(positions - sim.rest_positions, axis=2).max()), ms,
            tip)


def drew(png):
    """True when the screenshot png shows a drawing: more than 1% of its pixels differ from
    the background color by more than 0.1."""
    import matplotlib.image
    image = matplotlib.image.imread(png)[..., :3]
    background = np.median(image.reshape(-1, 3), axis=0)
    return float((np.abs(image - background).max(axis=2) > 0.1).mean()) > 0.01


def main():
    out = os.path.join(HERE, "out")
    server, base = serve(HERE)
    try:
        subprocess.run(["node", os.path.join(HERE, "e2e.mjs"), base, out,
                        ",".join(map(str, CHECKPOINTS))], check=True, cwd=HERE, timeout=900)
    finally:
        server.shutdown()
    with open(os.path.join(out, "result.json")) as f:
        page = json.load(f)
    expected, largest, cpu_ms = reference(os.path.join(HERE, "models", "directional.onnx"))
    got = np.asarray(page["positions"]).reshape(expected.shape)
    gaps = np.abs(got - expected).max(axis=(1, 2)) / largest
    failures = [f"page against runtime.py at step {step}: {gap:.2e} of the largest "
                f"displacement, more than {bound}"
                for step, gap, bound in zip(CHECKPOINTS, gaps, BOUNDS) if not gap <= bound]
    if not drew(os.path.join(out, "page.png")):
        failures.append("the screenshot is blank")
    rise = page["drag"]["pulled"] - page["drag"]["before"]
    if not rise > 1e-3:
        failures.append(f"dragging the tip up moved it by {rise * 1e3:.2f} mm")
    for name, scene in page["scenes"].items():
        if scene["message"] or not scene["finite"]:
            failures.append(f"scene {name}: {scene['message'] or 'a non-finite state'}")
    expected, largest_r, reduced_ms = reduced_reference()
    got = np.asarray(page["reduced"]["positions"]).reshape(expected.shape)
    reduced_gap = float(np.abs(got - expected).max() / largest_r)
    if not reduced_gap <= REDUCED_BOUND:
        failures.append(f"reduced model in the page against runtime.py: {reduced_gap:.2e} of the "
                        f"largest displacement, more than {REDUCED_BOUND}")
    reduced_rise = page["reducedDrag"]["pulled"] - page["reducedDrag"]["before"]
    if not reduced_rise > 1e-3:
        failures.append(f"dragging the reduced model's tip up moved it by "
                        f"{reduced_rise * 1e3:.2f} mm")
    for name, scene in page["reducedScenes"].items():
        if scene["message"] or not scene["finite"]:
            failures.append(f"reduced scene {name}: {scene['message'] or 'a non-finite state'}")
    bases = page["framed"]["bases"]
    if not any(bases):
        failures.append("the T's framed rollout did not carry its foot")
    expected, largest_f, framed_ms, framed_tip = framed_reference(bases)
    got = np.asarray(page["framed"]["positions"]).reshape(expected.shape)
    framed_gap = float(np.abs(got - expected).max() / largest_f)
    if not framed_gap <= REDUCED_BOUND:
        failures.append(f"the T's framed model in the page against framed_runtime.py: "
                        f"{framed_gap:.2e} of the largest displacement, more than "
                        f"{REDUCED_BOUND}")
    stated = re.search(r"within ([0-9.]+)% of the FEM's on \d+ unseen drags",
                       page["framed"]["stats"])
    if not stated or abs(float(stated.group(1)) - 100 * framed_tip) > 0.05 * 100 * framed_tip:
        failures.append(f"the T's framed model: the page says {page['framed']['stats']!r}, "
                        f"its file {100 * framed_tip:.2g}%")
    dragged = drag_gaps(page["drags"])
    for name, (gap, largest_d) in dragged.items():
        if not gap <= DRAG_BOUND:
            failures.append(f"{name}'s reduced model under the drag in the page against the numpy "
                            f"runtime: {gap:.2e} of the largest displacement, more than "
                            f"{DRAG_BOUND}")
    tentacle = page["tentacle"]
    controlled, largest_c, ball_gap, ball_y = controlled_gap(tentacle)
    if not controlled <= DRAG_BOUND:
        failures.append(f"the tentacle's controlled rollout in the page against the numpy "
                        f"runtime: {controlled:.2e} of the largest displacement, more than "
                        f"{DRAG_BOUND}")
    if not (ball_gap <= 1e-12 and ball_y < 0.045):
        failures.append(f"the tentacle's ball: {ball_gap:.2e} m from the numpy runtime's, at "
                        f"y = {ball_y:.4f} m (pushed from 0.05 m)")
    if (tentacle["message"] or tentacle["sliders"] != 4
            or abs(tentacle["slid"][1] - 0.07) > 1e-12):
        failures.append(f"the tentacle's sliders: {tentacle['sliders']} of 4, a slide to 0.07 "
                        f"left its control at {tentacle['slid'][1]}; {tentacle['message']}")
    if "cannot load" not in page["bad_model_message"]:
        failures.append(f"bad model message: {page['bad_model_message']!r}")
    if "cannot step" not in page["cut_scene_message"]:
        failures.append(f"cut scene message: {page['cut_scene_message']!r}")
    if "array W4@45 is float32, expected float64" not in page["bad_reduced_message"]:
        failures.append(f"bad reduced model message: {page['bad_reduced_message']!r}")
    print(f"cantilever, {page['n']} vertices, fiber angle {page['fiberAngle']}: the page against "
          f"runtime.py over the largest displacement ({largest * 1e3:.1f} mm), at steps "
          + ", ".join(f"{s} {g:.1e} (bound {b:g})" for s, g, b in zip(CHECKPOINTS, gaps, BOUNDS))
          + f"\nms per step: browser (onnxruntime-web, WASM, 1 thread) {page['msPerStep']:.2f}, "
          f"onnxruntime CPU {cpu_ms:.2f}; screenshot {out}/page.png")
    scenes = [f"{k} ({v['n']} vertices) {'failed' if v['message'] or not v['finite'] else 'ok'}"
              for k, v in page["scenes"].items()]
    print(f"drag: the tip rose {rise * 1e3:.1f} mm while pulled up; other scenes: "
          + ", ".join(scenes))
    print(f"reduced model: the page against runtime.py {reduced_gap:.1e} of the largest "
          f"displacement ({largest_r * 1e3:.1f} mm) over {CHECKPOINTS[-1]} steps; ms per step: "
          f"browser {page['reduced']['msPerStep']:.3f}, numpy {reduced_ms:.3f}; the drag raised "
          f"the tip {reduced_rise * 1e3:.1f} mm; scenes "
          + ", ".join(f"{k} {'failed' if v['message'] or not v['finite'] else 'ok'}"
                      for k, v in page["reducedScenes"].items()))
    print(f"the T's framed model: the page against framed_runtime.py {framed_gap:.1e} of the "
          f"largest displacement ({largest_f * 1e3:.1f} mm) over {FRAMED_CHECKPOINTS[-1]} "
          f"steps; ms per step: browser {page['framed']['msPerStep']:.2f}, numpy "
          f"{framed_ms:.2f}; the page says: {page['framed']['stats']}")
    for name, (gap, largest_d) in dragged.items():
        times = np.asarray(page["stepTimes"][name])
        print(f"{name}'s reduced model under a swinging drag: the page against the numpy runtime "
              f"{gap:.1e} of the largest displacement ({largest_d * 1e3:.1f} mm) over "
              f"{len(page['drags'][name]['forces'])} steps; a step in the page: median "
              f"{np.median(times):.3f} ms, mean {times.mean():.3f} ms over {len(times)} steps")
    print(f"the tentacle's controls ({', '.join(tentacle['controls'])}) set every step: the page "
          f"against the numpy runtime {controlled:.1e} of the largest displacement "
          f"({largest_c * 1e3:.1f} mm) over {len(tentacle['schedule'])} steps, its ball pushed "
          f"into it to y = {ball_y * 1e3:.1f} mm ({ball_gap:.1e} m from numpy's); "
          f"{tentacle['sliders']} sliders")
    print(f"bad model: {page['bad_model_message']}")
    print(f"cut scene: {page['cut_scene_message']}")
    print(f"bad reduced model: {page['bad_reduced_message']}")
    if failures:
        sys.exit("FAILED: " + "; ".join(failures))
    print("web check passed")


if __name__ == "__main__":
    main()
