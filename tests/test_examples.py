"""Every example runs as a user would run it and draws its picture (identify.py: fits)."""
import os
import subprocess
import sys

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


@pytest.mark.parametrize("script, picture, says", [
    ("cantilever.py", "cantilever.png", "fibers along the beam :  4 Newton iterations, "
                                        "converged True"),
    ("onnx_cantilever.py", "onnx_cantilever.png", "wrote out/onnx_cantilever.png"),
    ("squeeze.py", "squeeze.png", "monotone under Neo-Hookean: True"),
    ("finger_control.py", "finger_control_directional.png",
     "wrote out/finger_control_directional.png"),
    ("finger_control.py reduced", "finger_control_reduced.png",
     "wrote out/finger_control_reduced.png"),
    ("finger_control.py framed", "finger_control_framed.png",
     "wrote out/finger_control_framed.png"),
    ("tail.py", "tail.png", "wrote out/tail.png"),
    ("actuator.py", "actuator.png", "bending grows with pressure: True"),
    ("actuator.py twist", "actuator_twist.png", "bending grows with pressure: True"),
    ("two_region_part.py", "two_region_part.png", "converged: True"),
    ("tentacle.py", "tentacle.png", "drew out/tentacle.png"),
    ("actuator_control.py", "actuator_control.png", "drew out/actuator_control.png"),
    ("cable_finger.py", "cable_finger.png", "drew out/cable_finger.png"),
    ("tentacle_drop.py", "tentacle_drop.png", "drew out/tentacle_drop.png"),
    ("gripper.py", "gripper.png", "drew out/gripper.png"),
    ("tee_wall.py", "tee_wall.png", "drew out/tee_wall.png"),
    ("gripper.py --friction 0.1 --seconds 0.8", "gripper.png", "drew out/gripper.png"),
    ("gripper_reduced.py --seconds 1.3", None, "reduced steps that intersected: 0, failed: 0"),
    ("mujoco_arm.py --seconds 2", "mujoco_arm.png", "drew out/mujoco_arm.png"),
    ("mujoco_gripper.py", "mujoco_gripper.png", "drew out/mujoco_gripper.png"),
    ("identify.py", None, "stopped after")])
def test_example_runs_and_draws(tmp_path, script, picture, says):
    script, *args = script.split()
    r = subprocess.run([sys.executable, os.path.join(ROOT, "examples", script), *args],
                       cwd=tmp_path, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    assert says in r.stdout
    if picture is not None:
        assert (tmp_path / "out" / picture).stat().st_size > 30_000
    if script == "identify.py":  # the fit recovers the truth the example made (10 deg, 2e5 Pa)
        values = dict(line.split()[:3:2] for line in r.stdout.splitlines()
                      if line.startswith("  ") and "+-" in line)
        assert abs(float(values["fiber_elevation"]) - 10.0) < 2.0, r.stdout
        assert abs(float(values["kappa"]) / 2e5 - 1.0) < 0.1, r.stdout
        assert (tmp_path / "out" / "identify" / "fitted.toml").exists()
    if script == "tentacle.py":  # each target in reach: reached in the model, and the FEM at
        # the controls found within 1% of the tentacle's 0.2 m; the last one out of reach
        rows = [line.split("|") for line in r.stdout.splitlines() if line.count("|") == 5][1:]
        assert len(rows) == 5 and "out of reach" in r.stdout.splitlines()[-2]
        for row in rows[:4]:
            assert float(row[2]) < 0.02 and float(row[3]) < 2.0, row
    if script == "tentacle_drop.py":  # never through the ground, nothing inverted, at rest
        line = next(x for x in r.stdout.splitlines() if x.startswith("smallest gap"))
        gap = float(line.split("every step: ")[1].split()[0])
        speed = float(line.split("at rest: ")[1].split()[0])
        assert gap > 0 and "inverted elements: 0;" in line and "converged: True" in line, line
        assert speed < 1e-3, line
    if script == "gripper.py":  # lifted 30 mm by friction and held (slip under 0.1 mm), never
        # intersecting; with friction 0.1 the box stays on the ground as the bases rise
        rows = [x.split("|") for x in r.stdout.splitlines() if x.count("|") == 6][1:]
        assert "steps that intersected: 0; inverted elements: 0; every step converged: True" \
            in r.stdout, r.stdout
        box_up = float(rows[-1][3])
        if args:
            assert float(rows[-1][2]) == 18.0 and box_up < 0.2, rows[-1]
        else:
            assert abs(box_up - 30.0) < 0.5, rows[-1]
            slip = float(r.stdout.split("mm up, slipped ")[1].split()[0])
            assert 0 <= slip < 0.1, r.stdout
    if script == "mujoco_arm.py":  # the soft finger swings off where the hand carries it
        line = next(x for x in r.stdout.splitlines() if x.startswith("the finger's tip"))
        assert 2.0 < float(line.split("is up to ")[1].split()[0]) < 60.0, line
    if script == "mujoco_gripper.py":  # the MuJoCo box lifted 3 cm, held 2 s, slipping < 1 mm
        line = next(x for x in r.stdout.splitlines() if x.startswith("held from"))
        assert line.startswith("held from 1.0 s to 3.00 s"), line
        assert abs(float(line.split("the box ")[1].split()[0]) - 30.0) < 2.0, line
        assert float(line.split("against the hand ")[1].split()[0]) < 1.0, line
        line = next(x for x in r.stdout.splitlines() if x.startswith("least gap"))
        assert float(line.split("fingers-box ")[1].split()[0]) > 0, line
    if script == "gripper_reduced.py":  # the reduced box lifted within 3% of the FEM's
        line = next(x for x in r.stdout.splitlines() if x.startswith("held from"))
        assert float(line.split("(reduced): ")[1].split("%")[0]) < 3.0, line
    if script == "tee_wall.py":  # pushed to the wall and squeezed there, never through either
        line = next(x for x in r.stdout.splitlines() if x.startswith("smallest gaps"))
        gaps = [float(g.split()[1]) for g in line.split(";")[0].split(": ")[1].split(", ")]
        assert len(gaps) == 3 and min(gaps) > 0, line
        assert "inverted elements: 0; every step converged: True" in line, line
        rows = [x.split("|") for x in r.stdout.splitlines() if x.count("|") == 6][1:]
        assert float(rows[-1][2]) < 99.0 and float(rows[-1][4]) < 100.0, rows[-1]
    if script == "actuator_control.py":  # the tip follows the 10 mm path within 0.5 mm in
        # closed loop, and the full FEM under the same pressures within 0.1 mm of the runtime
        line = next(x for x in r.stdout.splitlines() if x.startswith("tip: largest error"))
        assert float(line.split()[3]) < 0.5, line
        line = next(x for x in r.stdout.splitlines() if x.startswith("full FEM"))
        assert float(line.split("tip within ")[1].split()[0]) < 0.1, line
    if script == "cable_finger.py":  # three targets reached, the FEM within 0.1 mm under the
        # tensions found, the last out of reach; the closed loop within 0.2 mm of its path
        rows = [line.split("|") for line in r.stdout.splitlines() if line.count("|") == 3][1:]
        assert len(rows) == 4 and all(float(row[3]) < 0.1 for row in rows[:3]), rows
        line = next(x for x in r.stdout.splitlines() if x.startswith("closed loop"))
        assert float(line.split("tip within ")[1].split()[0]) < 0.2, line
    if script == "actuator.py":  # the ramp's ParaView collection: one .vtu per pressure; the
        # crossed winding bends without twisting, the graded one twists as it bends
        assert len(list((tmp_path / "out").glob("actuator*_0*.vtu"))) == 11
        last = [line for line in r.stdout.splitlines() if "kPa" in line][-1]
        bent, twisted = (float(last.split(word)[1].split()[0]) for word in ("bent", "twisted"))
        assert bent > 20 and (abs(twisted) > 20 if args else abs(twisted) < 2), last
    if script == "tail.py":  # the framed runtime follows the full FEM through the whip
        error = float(r.stdout.split("the framed model within ")[1].split("%")[0])
        assert error < 5.0, r.stdout
    if script == "finger_control.py":  # the controller brings the tip to both targets
        assert r.stdout.count(": reached") == 2 and "missed" not in r.stdout, r.stdout
