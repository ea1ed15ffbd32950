"""The solver ladder: every method reaches Newton's answer at its tolerance, budgets behave as
budgets, kept factorizations are kept, and every rung is stable or says it failed at the
extremes."""
import warnings

import numpy as np
import scipy.sparse as sp
import pytest

import anisofem as af
from anisofem.solvers import methods, multigrid
from anisofem.physics.sparse import SparseOperator
from anisofem.physics.potential import Potential
from anisofem.studies.rungs import fem_rungs

TO_TOLERANCE = [("newton", {}), ("reuse", {}), ("lbfgs", {}), ("cg", {}),
                ("cg", {"preconditioner": "factor"}), ("cg", {"preconditioner": "amg"})]


def cantilever(mesh, kappa=1e5, nu=0.48):
    d = np.array([np.cos(np.radians(40)), 0.0, np.sin(np.radians(40))])
    return af.Scene(mesh, af.Material(1e5, nu, 1000.0, d, kappa),
                    fixed=af.metrics.end_vertices(mesh, 0, "min"), gravity=(0, 0, -9.81))


@pytest.fixture(scope="module")
def scene(beam):
    return cantilever(beam)


@pytest.fixture(scope="module")
def moving(scene):
    """A bent, moving state of the cantilever: (x, v) after 5 exact steps."""
    roll = af.simulate(scene, 5)
    return roll.positions[-1], roll.velocities[-1]


@pytest.mark.parametrize("method, options", TO_TOLERANCE)
def test_every_method_reaches_the_static_answer(scene, method, options):
    ref = af.solve(scene, rtol=1e-10)
    res = af.solve(scene, method=method, rtol=1e-10, **options)
    print(method, options, res)
    assert res.converged and res.method == method
    assert np.abs(res.x - ref.x).max() < 1e-8 * np.abs(ref.x - scene.mesh.vertices).max()


@pytest.mark.parametrize("method, options", TO_TOLERANCE)
def test_every_method_takes_newtons_step(scene, moving, method, options):
    x, v = moving
    ref = af.step(scene, x, v, 0.02, rtol=1e-10)
    res = af.step(scene, x, v, 0.02, method=method, rtol=1e-10, **options)
    assert res.converged
    assert np.abs(res.x - ref.x).max() < 1e-7 * np.abs(ref.x - x).max()


def test_one_newton_iteration_from_the_predictor_is_linearly_implicit_euler(scene, moving):
    """x = x_hat + p with (M / dt^2 + K(x_hat)) p = -grad G(x_hat): one full Newton step."""
    x, v = moving
    dt = 0.02
    x_hat = x + dt * v
    res = af.step(scene, x, v, dt, iterations=1)
    assert res.newton.iterations == 1 and not res.newton.failed
    free = scene.free_dofs
    H = af.hessian(scene, x_hat, x_hat, dt).toarray()[np.ix_(free, free)]
    g = af.gradient(scene, x_hat, x_hat, dt).ravel()[free]
    expected = x_hat.copy()
    expected.ravel()[free] -= np.linalg.solve(H, g)
    assert np.abs(res.x - expected).max() < 1e-10 * np.abs(expected - x).max()


@pytest.mark.parametrize("method", list(methods.METHODS))
def test_a_budget_is_spent_not_failed_and_rollouts_run_through_it(scene, method):
    """One iteration per step, more only where one would gain energy: the mechanical energy
    never grows, and the rollout runs through steps that stop short of the tolerance."""
    with warnings.catch_warnings():
        warnings.simplefilter("error", af.ConvergenceWarning)  # a budget does not warn
        roll = af.simulate(scene, 10, method=method, iterations=1)
    assert roll.completed and not roll.converged
    assert len(roll.steps) == 10
    its = [s.newton.iterations for s in roll.steps]
    print(method, "iterations per step", its)
    assert not any(s.newton.failed for s in roll.steps)
    assert min(its) == 1 and sum(i == 1 for i in its) >= 5
    assert any(s.newton.message == "iteration budget spent" for s in roll.steps)
    h = [_energy(scene, x, v) for x, v in zip(roll.positions, roll.velocities)]
    assert all(b <= a + 1e-12 * abs(a) for a, b in zip(h, h[1:]))


def test_warm_start_follows_the_budget():
    assert methods.make("newton").warm_start == "previous"
    assert methods.make("newton", iterations=2).warm_start == "inertial"
    assert methods.make("lbfgs", iterations=2, warm_start="previous").warm_start == "previous"


@pytest.mark.parametrize("method, options", [("reuse", {}), ("lbfgs", {}),
                                             ("cg", {"preconditioner": "factor"}),
                                             ("cg", {"preconditioner": "amg"})])
def test_factorizations_are_kept_across_steps(scene, method, options):
    roll = af.simulate(scene, 30, method=method, rtol=1e-6, **options)
    exact = af.simulate(scene, 30, rtol=1e-6)
    kept = sum(s.newton.factorizations for s in roll.steps)
    fresh = sum(s.newton.factorizations for s in exact.steps)
    print(method, "factorizations", kept, "newton's", fresh)
    assert roll.converged and kept < fresh / 2


def test_cg_with_the_jacobi_preconditioner_factors_nothing(scene):
    res = af.solve(scene, method="cg", rtol=1e-8)
    assert res.converged and res.factorizations == 0 and res.linear_iterations > 0


def test_rigid_body_modes_span_the_rest_hessians_null_space():
    mesh = af.box_beam(cells=(4, 2, 2))
    mesh = af.TetMesh(mesh.vertices + (0.3, -0.2, 0.5), mesh.tets)  # away from the origin
    scene = af.Scene(mesh, af.Material(1e5, 0.45, 1000.0, (0.6, 0.8, 0.0), 1e5))
    H = af.hessian(scene, mesh.vertices)
    modes = multigrid.rigid_body_modes(mesh.vertices, scene.free_dofs)
    assert np.linalg.matrix_rank(modes) == 6
    assert np.abs(H @ modes).max() <= 1e-9 * abs(H).max() * np.abs(modes).max()


def test_multigrid_with_rigid_modes_beats_the_diagonal():
    scene = af.default_scene(af.box_beam(cells=(20, 4, 4)))
    jacobi = af.solve(scene, method="cg", rtol=1e-8)
    amg = af.solve(scene, method="cg", preconditioner="amg", rtol=1e-8)
    print("CG iterations: jacobi", jacobi.linear_iterations, "amg", amg.linear_iterations)
    assert jacobi.converged and amg.converged
    assert amg.linear_iterations < jacobi.linear_iterations / 5
    assert amg.factorizations <= 3  # hierarchies built, kept across iterations


def test_quadratic_multigrid_goes_through_the_linear_tets_on_the_corners(monkeypatch):
    """The corner prolongation reproduces every linear field at every free node; CG with the
    V-cycle through it reaches the same Hessian solve to 1e-8 in fewer iterations than with
    smoothed aggregation on the quadratic matrix itself."""
    mesh = af.box_beam(cells=(12, 3, 3), order=2)
    scene = af.default_scene(mesh)
    free = scene.free_dofs
    P, corner_dofs = multigrid.corner_prolongation(mesh, free)
    field = np.outer(mesh.vertices[:, 0], [1.0, 2.0, -1.0])  # linear, zero at the clamped end
    assert np.abs(P @ field.ravel()[corner_dofs] - field.ravel()[free]).max() < 1e-15
    A = af.hessian(scene, mesh.vertices).tocsr()[free][:, free]
    g = np.random.default_rng(0).standard_normal(free.size)
    plain = multigrid.preconditioner(A, multigrid.rigid_body_modes(mesh.vertices, free))
    nested = multigrid.preconditioner(A, multigrid.rigid_body_modes(mesh.vertices, corner_dofs),
                                      P)
    (p1, its1), (p2, its2) = (methods.truncated_cg(A, g, M, 1e-8, 1000) for M in (plain, nested))
    print("CG iterations: smoothed aggregation", its1, "through the corners", its2)
    for p in (p1, p2):
        assert np.linalg.norm(A @ p + g) <= 1e-8 * np.linalg.norm(g)
    assert its2 < its1


@pytest.mark.parametrize("preconditioner, one_thread", [("jacobi", True), ("amg", True),
                                                       ("factor", False)])
def test_cg_without_a_factorization_runs_on_one_blas_thread(preconditioner, one_thread):
    from threadpoolctl import threadpool_info
    method = methods.make("cg", preconditioner=preconditioner)
    method.start(Potential(af.default_scene(af.box_beam(cells=(4, 2, 2)))))
    with method.threads():
        inside = {lib["num_threads"] for lib in threadpool_info() if lib["user_api"] == "blas"}
    outside = {lib["num_threads"] for lib in threadpool_info() if lib["user_api"] == "blas"}
    assert inside == ({1} if one_thread else outside)


def test_a_hierarchy_built_for_a_solve_is_kept_for_the_next():
    # with refactor_after=1 every solve needs more than the limit; a hierarchy is renewed
    # only after a solve with one built at an earlier iterate, so at most every other time
    scene = af.default_scene(af.box_beam(cells=(20, 4, 4)))
    result = af.solve(scene, method="cg", preconditioner="amg", refactor_after=1)
    assert result.converged
    assert result.factorizations <= (result.iterations + 1) // 2


@pytest.mark.parametrize("forcing, previous, miss, gnorm, expected", [
    (0.1, None, 1e-6, 1e6, 0.1),        # a solve's first iteration: the largest
    (0.1, 0.01, 1e-3, 1e6, 1e-3),       # a good model: as tight as its miss
    (0.9, 0.5, 1e-3, 1e6, 0.5 ** 1.618034),  # but not faster than previous^1.618 above 0.1
    (0.1, 0.01, 3.0, 1e6, 0.1),         # a poor model: capped at forcing
    (0.1, 0.01, 1e-9, 1e3, 5e-4),       # no digits past the Newton tolerance (1 N at 1000 N)
])
def test_forcing_follows_the_quadratic_models_miss(forcing, previous, miss, gnorm, expected):
    eta = methods.forcing_tolerance(forcing, previous, miss, gnorm, tolerance=1.0)
    assert eta == pytest.approx(expected, rel=1e-5)


def test_inexact_newton_on_a_nearly_linear_problem_takes_nearly_newtons_iterations():
    """Under a load 10^-4 of gravity G is nearly quadratic: the first iteration's model misses
    the new gradient by little, so the second iteration's CG runs to the tolerance at once
    (a fixed forcing of 0.1 would gain one digit per iteration: 8 or more)."""
    mesh = af.box_beam(cells=(10, 2, 2))
    scene = af.Scene(mesh, af.Material.paper(), fixed=af.metrics.end_vertices(mesh, 0, "min"),
                     gravity=(0.0, 0.0, -9.81e-4))
    newton = af.solve(scene)
    cg = af.solve(scene, method="cg", preconditioner="amg")
    print("Newton iterations: exact", newton.iterations, "cg", cg.iterations)
    assert cg.converged and cg.iterations <= newton.iterations + 1


def test_multigrid_on_a_matrix_too_small_to_coarsen():
    scene = af.default_scene(af.box_beam(cells=(2, 1, 1)))  # 24 unknowns: one level
    result = af.solve(scene, method="cg", preconditioner="amg")
    assert result.converged
    assert np.abs(result.x - af.solve(scene).x).max() <= 1e-9 * np.abs(
        result.x - scene.mesh.vertices).max()


def test_multigrid_v_cycle_is_pyamgs_own_in_single_precision():
    """anisofem's float32 V-cycle on numba's threads against pyamg's float64 one with the same
    smoothers on the same hierarchy: equal to float32 rounding, symmetric and positive."""
    from pyamg.relaxation.smoothing import change_smoothers
    scene = af.default_scene(af.box_beam(cells=(24, 8, 8)))
    free = scene.free_dofs
    A = af.hessian(scene, scene.mesh.vertices).tocsr()[free][:, free]
    hierarchy = multigrid.hierarchy(A, multigrid.rigid_body_modes(scene.mesh.vertices, free))
    assert len(hierarchy.levels) >= 3
    ours = multigrid.VCycle(hierarchy.levels)  # caches each level's spectral radius for pyamg's
    chebyshev = ("chebyshev", {"degree": multigrid.CHEBYSHEV_DEGREE,
                               "lower_bound": 1 / multigrid.CHEBYSHEV_LOWER,
                               "upper_bound": multigrid.CHEBYSHEV_UPPER})
    change_smoothers(hierarchy, [("gauss_seidel", {"sweep": "forward"}), chebyshev],
                     [("gauss_seidel", {"sweep": "backward"}), chebyshev])
    theirs = hierarchy.aspreconditioner(cycle="V")
    rng = np.random.default_rng(1)
    r, s = rng.standard_normal((2, len(free)))
    assert np.linalg.norm(ours(r) - theirs.matvec(r)) <= 1e-5 * np.linalg.norm(ours(r))
    assert abs(s @ ours(r) - r @ ours(s)) <= 1e-5 * np.linalg.norm(r) * np.linalg.norm(ours(s))
    assert r @ ours(r) > 0


def test_sparse_operator_products_are_scipys():
    """Every block shape the V-cycle meets (1 x 1, 1 x 6, 6 x 1, 6 x 6), in both precisions."""
    rng = np.random.default_rng(2)
    for shape in ((1, 1), (1, 6), (6, 1), (6, 6)):
        M = sp.random(12 * shape[0], 18 * shape[1], density=0.2, random_state=3).tobsr(shape)
        v, w = rng.standard_normal(M.shape[1]), rng.standard_normal(M.shape[0])
        for dtype, tol in ((np.float64, 1e-13), (np.float32, 1e-6)):
            op = SparseOperator.of(M, dtype)
            got = op.combine(v.astype(dtype), -2.0, w.astype(dtype))
            assert got.dtype == dtype
            want = w - 2.0 * (M @ v)
            assert np.abs(got - want).max() <= tol * np.abs(want).max(), (shape, dtype)
        assert np.allclose(SparseOperator.of(M, np.float64) @ v, M @ v, rtol=1e-13, atol=0)


def test_multigrid_repeats_exactly():
    """The hierarchy's random spectral radius estimates are seeded: two rollouts from different
    global random states agree to the bit, and numpy's global random state is left as it was."""
    scene = af.default_scene(af.box_beam(cells=(20, 4, 4)))
    np.random.seed(5)
    untouched = np.random.rand()
    np.random.seed(5)
    first = af.simulate(scene, 2, method="cg", preconditioner="amg").positions
    assert np.random.rand() == untouched
    np.random.seed(6)
    again = af.simulate(scene, 2, method="cg", preconditioner="amg").positions
    assert np.array_equal(first, again)


def test_auto_is_exact_newton_on_small_meshes_and_multigrid_on_large_ones(scene, monkeypatch):
    """The default method picks by the number of unknowns, and either pick reaches the same
    answer; it takes only the options both of its methods read."""
    small = af.solve(scene, rtol=1e-10)
    assert small.method == "newton" and small.linear_iterations == 0
    monkeypatch.setattr(methods, "AUTO_MULTIGRID_MIN", scene.n_free - 1)
    large = af.solve(scene, rtol=1e-10)
    assert large.method == "cg" and large.linear_iterations > 0 and large.converged
    assert np.abs(large.x - small.x).max() < 1e-6 * np.abs(small.x - scene.mesh.vertices).max()
    roll = af.simulate(scene, 3)
    assert roll.converged and all(s.newton.method == "cg" for s in roll.steps)
    assert af.Stepper(scene, 0.02).method.preconditioner == "amg"
    assert af.Stepper(scene, 0.02, linear_solver="superlu").method.name == "newton"
    with pytest.raises(TypeError, match="preconditioner: not an option of method 'auto'"):
        af.solve(scene, preconditioner="jacobi")
    with pytest.raises(ValueError, match="n_unknowns"):
        methods.make("auto")


def test_options_are_checked_by_name():
    with pytest.raises(TypeError, match="bogus: not an option of method 'newton'"):
        methods.make("newton", bogus=3)
    with pytest.raises(ValueError, match="method: expected one of"):
        methods.make("magic")
    with pytest.raises(ValueError, match="iterations"):
        methods.make("lbfgs", iterations=0)
    with pytest.raises(ValueError, match="preconditioner"):
        methods.make("cg", preconditioner="ilu")
    with pytest.raises(ValueError, match="warm_start"):
        methods.make("reuse", warm_start="random")
    with pytest.raises(TypeError, match="refactor: not an option of method 'auto'"):
        af.solve(af.default_scene(af.box_beam(cells=(2, 1, 1))), refactor=0.5)
    with pytest.raises(TypeError, match="refactor: not an option of method 'newton'"):
        af.solve(af.default_scene(af.box_beam(cells=(2, 1, 1))), method="newton", refactor=0.5)


def _energy(scene, x, v):
    return Potential(scene).energy(x) + 0.5 * float((scene.masses[:, None] * v * v).sum())


EXTREMES = {
    "nu 0.499": (lambda b: cantilever(b, nu=0.499), 0.02),
    "kappa 100 E": (lambda b: cantilever(b, kappa=1e7), 0.02),
    "dt 1e-4": (lambda b: cantilever(b), 1e-4),
    "dt 0.1": (lambda b: cantilever(b), 0.1),
    "flat elements": (lambda b: cantilever(af.box_beam((0.1, 0.02, 0.0005), (10, 2, 1))), 0.02),
}


@pytest.mark.parametrize("extreme", list(EXTREMES))
@pytest.mark.parametrize("rung", fem_rungs(), ids=lambda r: r.name)
def test_every_rung_is_stable_or_says_it_failed_at_the_extremes(beam, extreme, rung):
    make, dt = EXTREMES[extreme]
    scene = make(beam)
    advance = rung.make(scene, dt * rung.dt_factor)
    x = scene.initial_positions()
    v = np.zeros_like(x)
    h0 = _energy(scene, x, v)
    scale = abs(Potential(scene).energy(af.solve(scene).x))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", af.ConvergenceWarning)
        for k in range(8):
            x, v, info = advance(x, v)
            assert np.isfinite(x).all() and np.isfinite(v).all()
            if info["failed"]:
                assert info["message"]  # reported, with the reason
                break
            # backward Euler dissipates: a gain in energy is a blow-up in the making
            assert _energy(scene, x, v) <= h0 + 1e-3 * scale, f"energy grew at step {k + 1}"
