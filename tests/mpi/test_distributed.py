"""The petsc engine (anisofem.distributed) on 1 and 2 MPI ranks against the serial solver: the
static answer and 10 backward-Euler steps of several scenes, and its bad input. Each case runs
under mpirun in a subprocess (`make test-mpi`)."""
import os
import subprocess
import sys

import numpy as np
import pytest

import anisofem as af
from anisofem.studies.bench_distributed import MPIRUN
from cases import scene

pytest.importorskip("petsc4py")
pytest.importorskip("mpi4py")

HERE = os.path.dirname(os.path.abspath(__file__))
STEPS = 10
RTOL = 1e-10
#: the distributed answer against the serial one, relative to the largest displacement
AGREE = 1e-8


def mpirun(ranks, *args, cwd=HERE, timeout=300, env=None):
    return subprocess.run([*MPIRUN, "-n", str(ranks), sys.executable, *args], cwd=cwd,
                          capture_output=True, text=True, timeout=timeout,
                          env=None if env is None else {**os.environ, **env})


@pytest.fixture(scope="module")
def serial(tmp_path_factory):
    """name -> (scene, static positions, rollout positions) by the serial solver."""
    folder = tmp_path_factory.mktemp("serial")
    cache = {}

    def get(name):
        if name not in cache:
            s = scene(name, folder)
            static = af.solve(s, rtol=RTOL, warn=False)
            roll = af.simulate(s, STEPS, 0.02, rtol=RTOL, warn=False)
            assert static.converged and roll.converged
            cache[name] = s, static.x, roll.positions
        return cache[name]
    return get


@pytest.mark.parametrize("name, method", [
    ("cantilever", "newton"), ("cantilever", "cg"), ("t", "newton"), ("cylinder", "newton"),
    ("part", "newton"), ("part", "cg"), ("quadratic", "newton"), ("neohookean", "newton")])
@pytest.mark.parametrize("ranks", [1, 2])
def test_ranks_give_the_serial_answer(name, method, ranks, serial, tmp_path):
    s, static, rollout = serial(name)
    out = tmp_path / "out.npz"
    r = mpirun(ranks, "run_case.py", name, method, str(STEPS), str(out), str(RTOL),
               str(tmp_path))
    assert r.returncode == 0, r.stderr[-3000:]
    got = np.load(out)
    assert bool(got["converged"]) and int(got["ranks"]) == ranks
    scale = np.abs(static - s.mesh.vertices).max()
    assert np.abs(got["static"] - static).max() <= AGREE * scale
    tip = af.metrics.tip_displacement(s.mesh, static)
    assert np.linalg.norm(af.metrics.tip_displacement(s.mesh, got["static"]) - tip) <= \
        AGREE * np.linalg.norm(tip)
    assert got["rollout"].shape == rollout.shape
    assert np.abs(got["rollout"] - rollout).max() <= AGREE * scale


def test_the_command_line_engine_writes_the_gathered_result(tmp_path):
    mesh = tmp_path / "beam.msh"
    af.write_mesh(mesh, af.box_beam(cells=(10, 2, 2)))
    r = mpirun(2, "-m", "anisofem", "solve", str(mesh), "--engine", "petsc", "--fiber", "1",
               "0", "1", "--kappa", "1e5", "--rtol", "1e-10", "-o", str(tmp_path / "p.vtu"))
    assert r.returncode == 0, r.stderr
    assert "on 2 ranks (newton)" in r.stdout
    serial = subprocess.run([sys.executable, "-m", "anisofem", "solve", str(mesh), "--fiber",
                             "1", "0", "1", "--kappa", "1e5", "--rtol", "1e-10", "-o",
                             str(tmp_path / "s.vtu")], capture_output=True, text=True)
    p, s = (af.read_mesh(tmp_path / f) for f in ("p.vtu", "s.vtu"))
    import meshio
    up, us = (meshio.read(tmp_path / f).point_data["displacement"] for f in ("p.vtu", "s.vtu"))
    assert serial.returncode == 0 and p.n_tets == s.n_tets
    assert np.abs(up - us).max() <= AGREE * np.abs(us).max()


def test_xdmf_output_is_written_by_every_rank(tmp_path):
    """--engine petsc with an .xdmf output: an XDMF over HDF5 that meshio reads, nodes in the
    partition's order, the same displacements as the serial solve's at the same points."""
    import meshio
    mesh = tmp_path / "beam.msh"
    af.write_mesh(mesh, af.box_beam(cells=(10, 2, 2)))
    r = mpirun(2, "-m", "anisofem", "solve", str(mesh), "--engine", "petsc", "--rtol",
               "1e-10", "-o", str(tmp_path / "p.xdmf"))
    assert r.returncode == 0, r.stderr
    assert "written by the 2 ranks" in r.stdout and (tmp_path / "p.h5").exists()
    got = meshio.read(tmp_path / "p.xdmf")
    s = af.default_scene(af.read_mesh(mesh))
    expected = af.solve(s, rtol=1e-10).x - s.mesh.vertices
    assert got.cells[0].data.shape == (s.mesh.n_tets, 4)
    order = np.lexsort(got.points.T)
    serial_order = np.lexsort(s.mesh.vertices.T)
    assert np.allclose(got.points[order], s.mesh.vertices[serial_order], rtol=0, atol=1e-15)
    u = got.point_data["displacement"][order]
    assert np.abs(u - expected[serial_order]).max() <= AGREE * np.abs(expected).max()
    # the cells name the same tets: their rest volumes sum to the body's
    X = got.points[got.cells[0].data]
    volumes = np.einsum("ij,ij->i", np.cross(X[:, 1] - X[:, 0], X[:, 2] - X[:, 0]),
                        X[:, 3] - X[:, 0]) / 6
    assert np.isclose(np.abs(volumes).sum(), s.mesh.rest_volumes.sum(), rtol=1e-12)


def test_fewer_elements_than_ranks_is_one_clear_error(tmp_path):
    mesh = tmp_path / "one.msh"
    af.write_mesh(mesh, af.TetMesh(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1.0]]),
                                   np.array([[0, 1, 2, 3]])))
    r = mpirun(2, "-m", "anisofem", "solve", str(mesh), "--engine", "petsc", "-o",
               str(tmp_path / "o.vtu"), timeout=60)
    assert r.returncode != 0
    assert "1 elements cannot be split over 2 ranks" in r.stderr


def test_ranks_that_disagree_on_options_fail_on_every_rank(tmp_path):
    script = tmp_path / "disagree.py"
    script.write_text(
        "import anisofem as af\nfrom anisofem import distributed\n"
        "from petsc4py import PETSc\n"
        "s = af.default_scene(af.box_beam(cells=(4, 2, 2)))\n"
        "rank = PETSc.COMM_WORLD.getRank()\n"
        "try:\n    distributed.solve(s, rtol=1e-8 if rank == 0 else 1e-6)\n"
        "except ValueError as err:\n"
        "    open(f'rank{rank}.txt', 'w').write(f'refused: {err}')\n")
    r = mpirun(2, str(script), cwd=tmp_path, timeout=60)
    assert r.returncode == 0, r.stderr
    for rank in (0, 1):
        assert (tmp_path / f"rank{rank}.txt").read_text().startswith("refused: ranks disagree")


def test_a_krylov_solve_that_fails_ends_unconverged_with_petscs_reason(tmp_path):
    """PETSc options reach the solver (prefix anisofem_): a divergence tolerance below 1 fails
    CG on both Hessians, and the solve says so on every rank instead of hanging or returning NaN."""
    script = tmp_path / "broken.py"
    script.write_text(
        "import numpy as np\nimport anisofem as af\nfrom anisofem import distributed\n"
        "from petsc4py import PETSc\n"
        "r = distributed.solve(af.default_scene(af.box_beam(cells=(10, 4, 4))), method='cg')\n"
        "assert np.isfinite(r.x).all()\n"
        "open(f'rank{PETSc.COMM_WORLD.getRank()}.txt', 'w').write(f'{r.converged} "
        "{r.newton.message}')\n")
    r = mpirun(2, str(script), cwd=tmp_path, timeout=120, env={
        "PETSC_OPTIONS": "-anisofem_ksp_divtol 1e-3"})
    assert r.returncode == 0, r.stderr
    for rank in (0, 1):
        said = (tmp_path / f"rank{rank}.txt").read_text()
        assert said.startswith("False no step made progress") and "KSP reason" in said


def test_the_cg_multigrid_coarsens_the_box_split_as_the_serial_one(tmp_path):
    """The "cg" method's multigrid (ML where PETSc has it, as Debian's does) on the 5-tet box
    split: its coarse operators hold less than 3x the fine matrix's nonzeros (the serial pyamg
    hierarchy: 2.2; GAMG's MIS aggregation: about 6 here, 8.5 at 10^5 tets), and it takes CG
    to 1e-8 on the rest Hessian in fewer than 100 iterations."""
    script = tmp_path / "levels.py"
    script.write_text(
        "import anisofem as af\nfrom anisofem import distributed\n"
        "from anisofem.distributed.newton import Solver\n"
        "from anisofem.distributed.system import RankSystem\n"
        "from petsc4py import PETSc\n"
        "scene = af.default_scene(af.box_beam(cells=(25, 8, 10)), af.Material(poisson=0.48))\n"
        "comm, part, _ = distributed._context(scene, None)\n"
        "solver = Solver(RankSystem(scene, part, comm), 'cg')\n"
        "x = scene.initial_positions()\n"
        "_, g = solver.system.energy_gradient(x)\n"
        "solver.direction(x, g, g.norm(), 0.0, False)\n"
        "ksp, pc = solver.ksp, solver.multigrid\n"
        "ksp.setTolerances(rtol=1e-8, max_it=1000)\n"
        "ksp.solve(g, g.duplicate())\n"
        "nnz = [pc.getMGSmoother(k).getOperators()[0].getInfo(PETSc.Mat.InfoType.GLOBAL_SUM)"
        "['nz_used'] for k in range(pc.getMGLevels())]\n"
        "if comm.getRank() == 0:\n"
        "    open('levels.txt', 'w').write(f'{pc.getType()} {sum(nnz) / nnz[-1]} "
        "{ksp.getIterationNumber()} {ksp.getConvergedReason()}')\n")
    r = mpirun(2, str(script), cwd=tmp_path, timeout=120)
    assert r.returncode == 0, r.stderr[-3000:]
    kind, complexity, iterations, reason = (tmp_path / "levels.txt").read_text().split()
    assert kind == "ml", "this PETSc has no ML: the cg method falls back on GAMG"
    assert float(complexity) < 3.0
    assert int(reason) > 0 and int(iterations) < 100
