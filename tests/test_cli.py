"""The command line: generate a mesh, solve it, read the result back."""
import subprocess
import sys

import meshio
import numpy as np


def run(*args, cwd):
    return subprocess.run([sys.executable, "-m", "anisofem", *args], cwd=cwd,
                          capture_output=True, text=True, timeout=300)


def test_mesh_then_solve(tmp_path):
    r = run("mesh", "box", "--cells", "4", "2", "2", "-o", "beam.msh", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    r = run("solve", "beam.msh", "--fiber", "1", "0", "0", "--kappa", "1e5", "-o", "out.vtu",
            cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert "converged: True" in r.stdout
    out = meshio.read(tmp_path / "out.vtu")
    u = out.point_data["displacement"]
    assert u[:, 2].min() < -1e-4 and np.abs(u[out.points[:, 0] == 0]).max() == 0
    assert {"energy", "fiber_direction"} <= set(out.cell_data)


def test_bad_fixed_spec_is_a_clear_error(tmp_path):
    run("mesh", "box", "--cells", "2", "2", "2", "-o", "b.vtu", cwd=tmp_path)
    r = run("solve", "b.vtu", "--fixed", "left", "-o", "o.vtu", cwd=tmp_path)
    assert r.returncode != 0 and "--fixed: expected AXIS-SIDE" in r.stderr
