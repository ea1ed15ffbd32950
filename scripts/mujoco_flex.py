"""The same isotropic cantilever in MuJoCo two ways: MuJoCo's own flex (a 3D flexcomp grid
with its elasticity, integrator "discrete", the one it steps flex elasticity implicitly with)
and this library's models through the plugin "anisofem.soft" (export/mujoco.py); their sag
under gravity against the FEM's static equilibrium on quadratic tets, and the wall time per
simulated second of each at the largest time step at which it stays stable (every step
finite, the sag under BOUNDED times the FEM's).

    python scripts/mujoco_flex.py [--json results/mujoco_flex.json]

The beam: 0.2 x 0.02 x 0.02 m held at x = 0, E = 1 MPa, nu = 0.45, 1000 kg/m^3, gravity
along -z; 10 x 2 x 2 cells: the flex's grid (its linear tets) and the plugin models' mesh
(quadratic tets on the same grid, as the FEM's). Each is stepped 4 s from rest at each of
STEPS (the flex with a small damping, so that it settles); its sag is the tip's mean over
the last second.
"""
import argparse
import os
import sys
import tempfile
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), os.pardir))

import anisofem as af  # noqa: E402
from anisofem.io.output import publish, result_path  # noqa: E402
from anisofem.reduced import FramedModel, Loads, ReducedModel  # noqa: E402
from export import mujoco as plugin  # noqa: E402
from export import native  # noqa: E402
from export.writers import reduced as writer  # noqa: E402

SIZE, CELLS = (0.2, 0.02, 0.02), (10, 2, 2)
YOUNG, POISSON, DENSITY = 1e6, 0.45, 1000.0
GRAVITY = np.array([0.0, 0.0, -9.81])
STEPS = (0.001, 0.002, 0.005, 0.01, 0.02, 0.05)
SECONDS, SETTLED = 4.0, 1.0
FLEX_DAMPING = 0.002
#: A run is stable where its sag stays under this many times the FEM's (and finite).
BOUNDED = 10.0


def scene(order=1):
    mesh = af.box_beam(SIZE, CELLS, order=order)
    return af.Scene(mesh, af.Material(YOUNG, POISSON, DENSITY),
                    fixed=af.metrics.end_vertices(mesh, 0, "min"), gravity=GRAVITY)


def fem_sag(order=2):
    """The tip's static sag (m, negative) of the FEM on quadratic (order 2) or linear tets."""
    s = scene(order=order)
    x = af.solve(s, warn=False).x
    tip = af.metrics.end_vertices(s.mesh, 0, "max")
    return float((x[tip, 2] - s.mesh.vertices[tip, 2]).mean())


def flex_xml(dt):
    (L, W, H), (nx, ny, nz) = SIZE, CELLS
    mass = DENSITY * L * W * H
    return f"""<mujoco>
  <option timestep="{dt}" gravity="{' '.join(map(str, GRAVITY))}" integrator="discrete"/>
  <worldbody>
    <flexcomp name="beam" type="grid" count="{nx + 1} {ny + 1} {nz + 1}"
              spacing="{L / nx} {W / ny} {H / nz}" pos="{L / 2} 0 0" dim="3"
              radius="0.0005" mass="{mass}" dof="full">
      <elasticity young="{YOUNG}" poisson="{POISSON}" damping="{FLEX_DAMPING}"/>
      <contact contype="0" conaffinity="0" selfcollide="none"/>
      <edge equality="false"/>
      <pin gridrange="0 0 0 0 {ny} {nz}"/>
    </flexcomp>
  </worldbody>
</mujoco>"""


def run(xml, tip_of, dt):
    """(sag m or nan where a step is not finite, wall seconds per simulated second)."""
    import mujoco
    model = mujoco.MjModel.from_xml_string(xml)
    model.opt.timestep = dt
    data = mujoco.MjData(model)
    steps, settled = int(round(SECONDS / dt)), int(round(SETTLED / dt))
    tips = []
    t0 = time.perf_counter()
    for k in range(steps):
        mujoco.mj_step(model, data)
        if k >= steps - settled:
            tips.append(tip_of(model, data))
    wall = (time.perf_counter() - t0) / SECONDS
    sag = float(np.mean(tips))
    return (sag if np.isfinite(sag) else float("nan")), wall


def flex_tip(model, data):
    x = data.flexvert_xpos
    far = x[:, 0] > x[:, 0].max() - 1e-9 if np.isfinite(x).all() else None
    return float(x[far, 2].mean()) if far is not None else float("nan")


def plugin_tip(path):
    runtime = native.CModel(path)
    tip = runtime.rest_positions[:, 0] > SIZE[0] - 1e-9

    def tip_of(model, data):
        state = data.plugin_state[plugin.HEADER:plugin.HEADER + runtime.state_size]
        if not np.isfinite(state).all():
            return float("nan")
        x = runtime._positions(state)
        return float((x[tip, 2] - runtime.rest_positions[tip, 2]).mean())
    return tip_of


def measure():
    plugin.load_plugin()
    reference = fem_sag()
    rows = {}
    with tempfile.TemporaryDirectory() as folder:
        s = scene(order=2)
        reduced = ReducedModel(s, modes=4, snapshots=8, loads=Loads(), validate=False)
        models = {f"plugin, reduced (r = {reduced.r})": os.path.join(folder, "reduced"),
                  "plugin, framed": os.path.join(folder, "framed")}
        paths = list(models.values())
        writer.write(reduced, paths[0])
        writer.write_framed(FramedModel(s, validate=False), paths[1])
        cases = {"MuJoCo flex": (flex_xml, flex_tip)}   # its tip starts at z = 0
        for name, path in models.items():
            cases[name] = (lambda dt, path=path: plugin.mjcf(path).replace(
                "<worldbody>", f'<option gravity="{" ".join(map(str, GRAVITY))}"/><worldbody>'),
                plugin_tip(path))
        for name, (xml, tip_of) in cases.items():
            runs = []
            for dt in STEPS:
                sag, wall = run(xml(dt), tip_of, dt)
                runs.append({"dt": dt, "sag": sag, "wall_per_second": wall})
            stable = [r for r in runs if np.isfinite(r["sag"])
                      and abs(r["sag"]) < BOUNDED * abs(reference)]
            best = max(stable, key=lambda r: r["dt"]) if stable else None
            rows[name] = {"runs": runs, "largest_stable_dt": best and best["dt"],
                          "sag": best and best["sag"],
                          "sag_error": best and best["sag"] / reference - 1.0,
                          "wall_per_second": best and best["wall_per_second"]}
    return {"fem_sag": reference, "fem_linear_sag": fem_sag(order=1), "cases": rows}


def _print(report):
    print(f"FEM sag: {1e3 * report['fem_sag']:.3f} mm on quadratic tets (the reference), "
          f"{1e3 * report['fem_linear_sag']:.3f} mm on linear tets of the same grid")
    print(f"{'model':<42} | {'largest dt (s)':>14} | {'sag (mm)':>9} | {'off FEM':>7} | "
          f"wall per simulated s (s)")
    for name, row in report["cases"].items():
        if row["largest_stable_dt"] is None:
            print(f"{name:<42} | {'none':>14} |")
            continue
        print(f"{name:<42} | {row['largest_stable_dt']:14g} | {1e3 * row['sag']:9.3f} | "
              f"{100 * row['sag_error']:6.1f}% | {row['wall_per_second']:.4f}")


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--json", default=result_path("mujoco_flex.json"))
    args = parser.parse_args()
    publish(measure(), _print, args.json)


if __name__ == "__main__":
    main()
