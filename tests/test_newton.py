"""Newton: quadratic convergence, the adaptive Hessian choice, linear solvers, failures."""

import warnings

import numpy as np
import pytest

import anisofem as af
from anisofem.solvers import linsolve
from anisofem.physics.potential import Potential


def test_quadratic_convergence_near_the_solution(beam):
    result = af.solve(af.default_scene(beam), rtol=1e-10)
    print("relative residuals:", ["%.3e" % r for r in result.residuals])
    assert result.converged and result.projected == 0
    r = result.residuals
    # steps near the solution and above round-off (1e-10): log r_k / log r_{k-1} >= 1.8
    tail = [k for k in range(1, len(r)) if r[k - 1] < 1e-1 and r[k] > 1e-10]
    assert len(tail) >= 2
    for k in tail:
        assert np.log(r[k]) / np.log(r[k - 1]) > 1.8


def test_projecting_every_iteration_converges_only_linearly(beam):
    adaptive = af.solve(af.default_scene(beam), rtol=1e-10)
    always = af.solve(af.default_scene(beam), rtol=1e-10, projection="always")
    print("iterations: adaptive", adaptive.iterations, "always projected", always.iterations)
    assert always.converged and always.projected == always.iterations
    assert always.iterations > adaptive.iterations + 5
    assert np.abs(always.x - adaptive.x).max() < 1e-8


CHOLMOD = pytest.param("cholmod", marks=pytest.mark.skipif(
    not linsolve.cholmod_available(), reason="scikit-sparse (CHOLMOD) not installed"))


@pytest.mark.parametrize("solver", ["banded", "superlu", "superlu-colamd", CHOLMOD])
def test_linear_solvers_agree(beam, solver):
    ref = af.solve(af.default_scene(beam), linear_solver="dense", rtol=1e-10)
    res = af.solve(af.default_scene(beam), linear_solver=solver, rtol=1e-10)
    assert res.converged
    assert np.abs(res.x - ref.x).max() < 1e-9


@pytest.mark.parametrize("kind", ["dense", "banded"])
def test_hessian_layouts_hold_the_same_matrix(beam, kind):
    """The dense and banded layouts (over the free DOFs) hold the CSR layout's matrix, the
    banded one with few subdiagonals (reverse Cuthill-McKee)."""
    scene = af.default_scene(beam)
    x = scene.initial_positions() + 1e-3 * np.random.default_rng(0).standard_normal(
        (beam.n_vertices, 3))
    pot = Potential(scene, x, 0.02)
    ref = scene.layout("csr").matrix(pot.hessian_data(x, scene.layout("csr"))[2]).toarray()
    layout = scene.layout(kind)
    got = layout.matrix(pot.hessian_data(x, layout)[2])
    got = got.toarray() if hasattr(got, "toarray") else got
    assert np.abs(got - ref).max() <= 1e-14 * np.abs(ref).max()
    if kind == "banded":
        print("unknowns", scene.n_free, "subdiagonals", layout.kd)
        assert layout.kd < scene.n_free / 2


def test_auto_picks_the_banded_cholesky_for_small_systems():
    assert isinstance(linsolve.make("auto", 135), linsolve.BandedCholesky)
    assert not isinstance(linsolve.make("auto", linsolve.BANDED_MAX + 1),
                          linsolve.BandedCholesky)


def buckling_scene():
    """Beam ends pushed 30% together: the straight state is a saddle, the answer buckles."""
    mesh = af.box_beam(cells=(10, 2, 2))
    X = mesh.vertices
    lo, hi = np.flatnonzero(X[:, 0] == 0), np.flatnonzero(X[:, 0] > 0.0999)
    fixed = np.concatenate([lo, hi])
    pos = X[fixed].copy()
    pos[len(lo):, 0] -= 0.03
    scene = af.Scene(mesh, fixed=fixed, fixed_positions=pos)
    x0 = scene.initial_positions()
    x0[:, 0] = 0.7 * X[:, 0]
    x0[:, 2] += 1e-4 * np.sin(np.pi * X[:, 0] / 0.1)
    return scene, x0


@pytest.mark.filterwarnings("ignore::anisofem.InversionWarning")  # the true-Hessian-only run
@pytest.mark.parametrize("solver", ["dense", "banded", "superlu", CHOLMOD])
def test_buckling_needs_the_projected_fallback(solver):
    scene, x0 = buckling_scene()
    result = af.solve(scene, x0=x0, linear_solver=solver)
    assert result.converged and result.projected > 0
    assert result.x[:, 2].max() > 0.01  # buckled sideways by about a centimetre
    # a minimum, not the saddle: the true Hessian at the answer is positive definite
    H = af.hessian(scene, result.x).toarray()
    free = ~scene.fixed_mask.ravel()
    assert np.linalg.eigvalsh(H[np.ix_(free, free)]).min() > 0
    straight = af.energy(scene, x0 * [1, 1, 0] + [0, 0, 1] * scene.mesh.vertices)
    assert result.energy < straight
    with pytest.warns(af.ConvergenceWarning):
        never = af.solve(scene, x0=x0, linear_solver=solver, projection="never")
    assert not never.converged and np.isfinite(never.x).all()


def test_stall_is_reported_not_returned_as_success(beam):
    with pytest.warns(af.ConvergenceWarning):
        # below round-off: the search stalls
        result = af.solve(af.default_scene(beam), rtol=1e-30, atol=0)
    assert not result.converged
    assert "stalled" in result.message
    assert np.isfinite(result.x).all() and result.residuals[-1] < 1e-9


def test_max_iter_is_reported(beam):
    with pytest.warns(af.ConvergenceWarning):
        result = af.solve(af.default_scene(beam), max_iter=2, continuation="never")
    assert not result.converged and result.iterations == 2
    assert result.message == "max_iter reached"


def test_step_from_equilibrium_stays_put(beam):
    scene = af.default_scene(beam)
    static = af.solve(scene, rtol=1e-12).x
    res = af.step(scene, static, np.zeros_like(static), 0.02)
    assert res.converged and res.newton.iterations <= 1
    assert np.abs(res.x - static).max() < 1e-12


@pytest.mark.parametrize("model", ["stvk", "neohookean"])
@pytest.mark.parametrize("nu,kappa", [(0.48, 1e5), (0.499, 1e7)])
def test_converged_means_small_against_a_scale_the_start_cannot_change(beam, model, nu, kappa):
    """A far-off first guess or a violent step must not loosen the test: whenever a result says
    converged, its free-gradient norm is within rtol of the problem's own force scale (the
    load, the elastic force at the start and, in a step, the inertial force), or at the
    round-off level."""
    scene = af.Scene(beam, af.Material(1e5, nu, 1000.0, (1, 0, 0), kappa, model=model),
                     fixed=af.metrics.end_vertices(beam, 0, "min"), gravity=(0, 0, -9.81))
    free = scene.free_dofs
    rng = np.random.default_rng(1)

    def tolerance(pot):
        return max(1e-8 * pot.force_scale(), scene.gradient_roundoff) * 1.0001
    checked = 0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # far starts may not converge, or end inverted
        for size in (1e-3, 3e-3):
            x0 = beam.vertices + size * rng.standard_normal(beam.vertices.shape)
            if scene.outside_domain(scene.with_fixed(x0)):
                continue  # refused with a message (tested elsewhere)
            res = af.solve(scene, x0=x0)
            g = af.gradient(scene, res.x).ravel()[free]
            assert not res.converged or np.linalg.norm(g) <= tolerance(Potential(scene))
            checked += res.converged
        x = scene.initial_positions()
        v = np.zeros_like(x)
        v[af.metrics.end_vertices(beam, 0, "max"), 2] = -5.0
        for dt in (0.02, 0.2, 1.0):
            res = af.step(scene, x, v, dt)
            pot = Potential(scene, x + dt * v, dt, x_start=x)
            g = af.gradient(scene, res.x, x + dt * v, dt).ravel()[free]
            print(dt, res.newton)
            assert not res.converged or np.linalg.norm(g) <= tolerance(pot)
            checked += res.converged
    assert checked >= 2  # the test is not vacuous


@pytest.mark.parametrize("cells,offset", [((10, 2, 2), 0.0), ((10, 2, 2), 1.0),
                                          ((20, 4, 4), 0.0), ((20, 4, 4), 1.0)])
def test_default_atol_sits_a_few_times_above_the_reachable_residual(cells, offset):
    # nearly incompressible with stiff fibers: where a constant atol was 35-80x too loose
    mesh = af.box_beam(cells=cells)
    mesh = af.TetMesh(mesh.vertices + offset, mesh.tets)
    x = mesh.vertices[:, 0]
    d = (np.cos(np.radians(40)), np.sin(np.radians(40)), 0.0)
    scene = af.Scene(mesh, af.Material(1e5, 0.4999, 1000.0, d, 1e8),
                     fixed=np.flatnonzero(x <= x.min() + 1e-9), gravity=(0, 0, -9.81))
    scale = Potential(scene).force_scale()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", af.ConvergenceWarning)
        reachable = min(af.solve(scene, rtol=1e-30, atol=0, max_iter=60).residuals) * scale
    print(f"atol / smallest reachable residual: {scene.gradient_roundoff / reachable:.1f}")
    assert 2 * reachable <= scene.gradient_roundoff <= 40 * reachable
    result = af.solve(scene, rtol=1e-14)  # asks for more than float64 holds: atol decides
    assert result.converged and result.residuals[-1] * scale <= scene.gradient_roundoff
