"""What an installed copy sees: the FEM stands alone without the network's dependencies, and a
wheel installed into a fresh environment finds its shipped files (models, ONNX files) and its
trade rungs from any folder."""
import os
import subprocess
import sys
import sysconfig
import tarfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

#: makes the network's and the plots' packages unimportable, as on a `pip install .` of the FEM
WITHOUT_EXTRAS = """
import sys
class Absent:
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in {"torch", "onnx", "onnxruntime", "matplotlib", "tqdm"}:
            raise ModuleNotFoundError(f"No module named {name!r}")
sys.meta_path.insert(0, Absent())
"""

FEM_ALONE = WITHOUT_EXTRAS + """
import anisofem as af
mesh = af.box_beam(cells=(4, 2, 2))
scene = af.default_scene(mesh)
assert af.solve(scene).converged
assert af.simulate(scene, 3).converged
result = af.trade(scene, steps=10, progress=False)
assert {r["kind"] for r in result["rungs"]} == {"fem", "reduced"}
assert len(result["rungs"]) == len(af.studies.rungs.fem_rungs())
print("\\n".join(result["notes"]))
assert not {"torch", "onnxruntime", "matplotlib"} & set(sys.modules)
"""


def test_the_fem_solves_simulates_and_trades_without_the_networks_packages(tmp_path):
    run = subprocess.run([sys.executable, "-c", FEM_ALONE], cwd=tmp_path, capture_output=True,
                         text=True, timeout=600)
    assert run.returncode == 0, run.stderr[-3000:]
    assert "anisognn rungs skipped: No module named 'torch'" in run.stdout
    assert "export rungs skipped" in run.stdout or "ONNX rung skipped" in run.stdout


INSTALLED = """
import os, sys
import anisofem, anisognn, export
for module in (anisofem, anisognn, export):
    assert module.__file__.startswith(sys.prefix), module.__file__
anisognn.pretrained("directional")
mesh = anisofem.box_beam(cells=(4, 2, 2))
scene = anisofem.Scene(mesh, anisofem.Material.paper((1, 0, 0), 1e5),
                       fixed=anisofem.physics.metrics.end_vertices(mesh, 0, "min"),
                       gravity=(0, 0, -9.81))
notes = []
rungs = anisofem.studies.rungs.registered_rungs(scene, 0.02, notes)
result = anisofem.trade(scene, steps=10, rungs=[anisofem.studies.rungs.fem_rung("exact")] + rungs,
                        progress=False)
for row in result["rungs"]:
    print(row["name"], row["max_error"])
print("notes:", notes)
"""


def _wheel(tmp_path):
    """A wheel built from the checkout's files (tracked and not ignored), the way pip builds
    one for `pip install .`."""
    files = subprocess.run(["git", "ls-files", "-co", "--exclude-standard", "-z"], cwd=ROOT,
                           capture_output=True, check=True).stdout.decode().split("\0")
    source = tmp_path / "source"
    with tarfile.open(tmp_path / "source.tar", "w") as tar:
        for name in filter(None, files):
            if os.path.exists(os.path.join(ROOT, name)):
                tar.add(os.path.join(ROOT, name), arcname=name, recursive=False)
    with tarfile.open(tmp_path / "source.tar") as tar:
        tar.extractall(source, filter="data")
    subprocess.run([sys.executable, "-m", "pip", "wheel", "--quiet", "--no-deps",
                    "--no-build-isolation", "--wheel-dir", str(tmp_path / "wheel"),
                    str(source)], check=True, capture_output=True, timeout=300)
    return next((tmp_path / "wheel").glob("anisofem-*.whl"))


def test_a_wheel_in_a_fresh_environment_finds_its_models_onnx_files_and_rungs(tmp_path):
    wheel = _wheel(tmp_path)
    env = tmp_path / "env"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(env)], check=True)
    python = str(env / "bin" / "python")
    # pip --python installs into that environment and leaves this one's packages alone
    subprocess.run([sys.executable, "-m", "pip", "--python", python, "install", "--quiet",
                    "--no-deps", "--no-index", str(wheel)], check=True, capture_output=True)
    site = subprocess.run([python, "-c", "import sysconfig; print(sysconfig.get_paths()"
                           "['purelib'])"], capture_output=True, text=True, check=True)
    # the dependencies (numpy, numba, torch, ...) from this environment, not this checkout
    with open(os.path.join(site.stdout.strip(), "dependencies.pth"), "w") as f:
        f.write(sysconfig.get_paths()["purelib"] + "\n")
    work = tmp_path / "elsewhere"
    work.mkdir()
    run = subprocess.run([python, "-c", INSTALLED], cwd=work, capture_output=True, text=True,
                         timeout=900)
    assert run.returncode == 0, run.stderr[-3000:]
    names = run.stdout.split("\n")
    assert any(n.startswith("directional (shipped) ") for n in names), run.stdout
    assert any(n.startswith("directional.onnx (shipped) ") for n in names), run.stdout
    assert "notes: []" in run.stdout
    bench = subprocess.run([python, "-m", "export", "bench", "--sizes", "1e2"], cwd=work,
                           capture_output=True, text=True, timeout=600)
    assert bench.returncode == 0, bench.stderr[-3000:]
    assert (work / "results" / "bench_export.json").is_file()
    assert f"wrote {os.path.join('results', 'bench_export.json')}" in bench.stdout
