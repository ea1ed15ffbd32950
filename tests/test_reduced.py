"""The reduced model (anisofem.reduced): its polynomial equals the full FEM projected on the
basis, its Hessian matches finite differences, its solves converge or say so and approach the
full FEM, and bad input is refused."""
import os

import numpy as np
import pytest

import anisofem as af
from anisofem.studies import rungs as ladder_rungs
from anisofem.reduced import ReducedModel
from anisofem.reduced.polynomial import polynomial
from test_elements import Quadratic

E = 1e5
FIBER = (np.cos(np.radians(40)), 0.0, np.sin(np.radians(40)))


def cantilever(cells=(10, 2, 2), nu=0.48, kappa=E, model="stvk", length=0.1, g=9.81):
    mesh = af.box_beam(cells=cells, size=(length, 0.02, 0.02))
    x = mesh.vertices[:, 0]
    return af.Scene(mesh, af.Material(E, nu, 1000.0, FIBER, kappa, model=model),
                    fixed=np.flatnonzero(x <= x.min() + 1e-9), gravity=(0, 0, -g))


@pytest.fixture(scope="module")
def model():
    return ReducedModel(cantilever(), modes=4)


def random_q(model, rng, size=0.2):
    """Reduced coordinates that move the beam by about `size` of its length."""
    q = rng.standard_normal(model.r)
    u = (model.basis @ q).reshape(-1, 3)
    return q * size * 0.1 / np.abs(u).max()


def test_polynomial_equals_the_projected_fem(model):
    scene = model.scene
    f_ext = scene.external_force
    rng = np.random.default_rng(0)
    assert model.r == 4 + 10
    for _ in range(3):
        q = random_q(model, rng)
        x = model.positions(q)
        elastic = af.energy(scene, x) + np.sum(f_ext * x)
        assert abs(model.energy(q) - elastic) <= 1e-10 * abs(elastic)
        f, H = model.force(q, hessian=True)
        expected_f = model.basis.T @ (af.gradient(scene, x) + f_ext).ravel()
        assert np.linalg.norm(f - expected_f) <= 1e-10 * np.linalg.norm(expected_f)
        expected_H = model.basis.T @ (af.hessian(scene, x) @ model.basis)
        assert np.linalg.norm(H - expected_H) <= 1e-10 * np.linalg.norm(expected_H)


def test_polynomial_of_quadratic_tets_equals_their_energy():
    """The coefficients are summed per quadrature point, so a 10-node element's 14 points
    give its exact energy, gradient and Hessian along any basis."""
    mesh = af.box_beam(cells=(2, 1, 1), size=(0.1, 0.02, 0.02))
    p2 = Quadratic(mesh, af.Material(E, 0.45, 1000.0, FIBER, 10 * E))
    rng = np.random.default_rng(3)
    basis = rng.standard_normal((p2.nodes.size, 7)) * 0.01
    P = polynomial(p2.elements, p2.nodes, basis)
    for _ in range(3):
        q = rng.standard_normal(7)
        x = p2.nodes + (basis @ q).reshape(-1, 3)
        assert abs(P.energy(q) - p2.energy(x)) <= 1e-10 * abs(p2.energy(x))
        g, H = P.gradient(q, hessian=True)
        expected = basis.T @ p2.gradient(x).ravel()
        assert np.linalg.norm(g - expected) <= 1e-10 * np.linalg.norm(expected)
        expected = basis.T @ (p2.hessian(x) @ basis)
        assert np.linalg.norm(H - expected) <= 1e-10 * np.linalg.norm(expected)


def test_reduced_hessian_matches_finite_differences(model):
    rng = np.random.default_rng(1)
    q = random_q(model, rng)
    _, H = model.force(q, hessian=True)
    h = 1e-6 * np.linalg.norm(q)
    fd = np.column_stack([(model.force(q + h * e) - model.force(q - h * e)) / (2 * h)
                          for e in np.eye(model.r)])
    assert np.linalg.norm(H - fd) <= 1e-7 * np.linalg.norm(H)
    g = model.force(q)
    fd_g = np.array([(model.energy(q + h * e) - model.energy(q - h * e)) / (2 * h)
                     for e in np.eye(model.r)])
    assert np.linalg.norm(g - fd_g) <= 1e-7 * np.linalg.norm(g)


def test_basis_is_mass_orthonormal_and_zero_on_fixed_components(model):
    scene = model.scene
    M = np.repeat(scene.masses, 3)
    assert np.abs(model.basis.T @ (M[:, None] * model.basis) - np.eye(model.r)).max() < 1e-10
    assert np.abs(model.basis[scene.fixed_mask.ravel()]).max() == 0.0


def tip(scene, x):
    X = scene.mesh.vertices
    return x[X[:, 0] >= X[:, 0].max() - 1e-9, 2].mean() - X[X[:, 0] >= X[:, 0].max() - 1e-9,
                                                            2].mean()


def test_static_sag_approaches_the_full_solve():
    scene = cantilever()
    full = af.solve(scene)
    exact = tip(scene, full.x)
    errors = []
    for modes in (4, 6):
        reduced = ReducedModel(scene, modes=modes)
        q, report = reduced.solve()
        assert report.converged
        errors.append(abs(tip(scene, reduced.positions(q)) - exact) / abs(exact))
    linear = ReducedModel(scene, modes=6, derivatives=False)
    q, _ = linear.solve()
    assert errors[1] < 0.01 and errors[1] < errors[0] + 1e-3
    assert errors[1] < abs(tip(scene, linear.positions(q)) - exact) / abs(exact)


def test_backward_euler_does_not_gain_energy(model):
    q, v = np.zeros(model.r), np.zeros(model.r)
    dt = 0.02

    def mechanical(q, v):
        return model.energy(q) - model.external @ q + 0.5 * v @ v
    before = mechanical(q, v)
    for _ in range(50):
        q, v, report = model.step(q, v, dt)
        assert report.converged
        now = mechanical(q, v)
        assert now <= before + 1e-12 * abs(before)
        before = now


def test_nodal_force_is_projected(model):
    """A sideways pull on a tip vertex moves it sideways, as in the full FEM's answer."""
    scene = model.scene
    force = np.zeros((scene.mesh.n_vertices, 3))
    tip = np.argmax(scene.mesh.vertices[:, 0])
    force[tip, 1] = 0.3
    q, report = model.solve(force=force)
    full = af.solve(af.Scene(scene.mesh, scene.material, fixed=scene.fixed_mask,
                             nodal_force=force, gravity=(0, 0, -9.81)))
    moved = model.positions(q)[tip, 1] - scene.mesh.vertices[tip, 1]
    expected = full.x[tip, 1] - scene.mesh.vertices[tip, 1]
    assert report.converged and moved > 0 and abs(moved - expected) < 0.05 * expected


@pytest.mark.parametrize("nu,kappa,dt,g", [(0.499, E, 0.02, 9.81), (0.48, 100 * E, 0.02, 9.81),
                                           (0.48, E, 1e-4, 9.81), (0.48, E, 0.1, 9.81),
                                           (0.48, E, 0.02, 98.1)])
def test_extremes_converge(nu, kappa, dt, g):
    reduced = ReducedModel(cantilever(nu=nu, kappa=kappa, g=g), modes=4)
    q, v = np.zeros(reduced.r), np.zeros(reduced.r)
    for _ in range(10):
        q, v, report = reduced.step(q, v, dt)
        assert np.isfinite(q).all() and np.isfinite(v).all()
        assert report.converged


def test_bad_input_is_refused():
    with pytest.raises(ValueError, match="Neo-Hookean"):
        ReducedModel(cantilever(model="neohookean"))
    scene = cantilever(cells=(2, 1, 1))
    with pytest.raises(ValueError, match="modes"):
        ReducedModel(scene, modes=scene.n_free)
    with pytest.raises(ValueError, match="modes"):
        ReducedModel(scene, modes=0)
    mesh = af.box_beam(cells=(2, 1, 1))
    with pytest.raises(ValueError, match="fixed"):
        ReducedModel(af.Scene(mesh, af.Material()))
    with pytest.raises(ValueError, match="dt"):
        ReducedModel(scene, modes=2).step(np.zeros(5), np.zeros(5), 0.0)


def test_static_solve_at_ten_g_converges():
    reduced = ReducedModel(cantilever(g=98.1), modes=5)
    q, report = reduced.solve()
    assert report.converged and np.isfinite(q).all()


def test_failure_is_reported_not_hidden(model):
    q, v = np.zeros(model.r), np.zeros(model.r)
    _, _, report = model.step(q, v, 0.02, rtol=0.0, max_iter=1)
    assert not report.converged and report.message == "1 iterations spent"


def test_trade_lists_reduced_rungs_beside_the_exact_one():
    scene = cantilever()
    result = af.trade(scene, steps=10, rungs=[ladder_rungs.fem_rung("exact"),
                                              ladder_rungs.reduced_rung(5)],
                      progress=False)
    row = result["rungs"][1]
    assert row["name"] == "reduced m5" and row["kind"] == "reduced" and row["stable"]
    assert row["setup_seconds"] > 0 and row["max_error"] < 0.01


def test_trade_leaves_reduced_rungs_out_of_neo_hookean_scenes():
    scene = cantilever(model="neohookean")
    result = af.trade(scene, steps=2, rungs=[ladder_rungs.fem_rung("exact"),
                                             ladder_rungs.reduced_rung(4)],
                      progress=False)
    assert [r["name"] for r in result["rungs"]] == ["exact"]
    assert any("StVK" in note for note in result["notes"])


def test_select_rungs_keeps_exact_and_refuses_unknown_names():
    rungs = ladder_rungs.fem_rungs()
    assert [r.name for r in ladder_rungs.select_rungs(rungs, ["reduced m5"])] == ["exact",
                                                                            "reduced m5"]
    with pytest.raises(ValueError, match="no rung named 'reduced m7'"):
        ladder_rungs.select_rungs(rungs, ["reduced m7"])


def test_basis_at_points_of_the_same_body_interpolates_it(model):
    mesh = model.scene.mesh
    U = model.basis.reshape(mesh.n_vertices, 3, -1)
    assert np.abs(model.basis_at(mesh.vertices) - U).max() <= 1e-12 * np.abs(U).max()
    centroids = mesh.vertices[mesh.tets].mean(axis=1)
    expected = U[mesh.tets].mean(axis=1)
    assert np.abs(model.basis_at(centroids) - expected).max() <= 1e-12 * np.abs(U).max()
    coarse = af.box_beam(cells=(5, 1, 1), size=(0.1, 0.02, 0.02))  # its vertices are fine ones
    q = random_q(model, np.random.default_rng(4))
    moved = coarse.vertices + model.basis_at(coarse.vertices) @ q
    fine = model.positions(q)
    match = [np.flatnonzero(np.all(np.abs(mesh.vertices - v) < 1e-12, axis=1))[0]
             for v in coarse.vertices]
    assert np.abs(moved - fine[match]).max() <= 1e-12
    with pytest.raises(ValueError, match="lies in no tet"):
        model.basis_at([[0.5, 0.0, 0.0]])


def test_non_finite_forces_raise_like_the_runtime(model):
    force = np.zeros((model.scene.mesh.n_vertices, 3))
    force[4, 2] = np.nan
    q = np.zeros(model.r)
    for call in (lambda: model.step(q, q, 0.02, force=force), lambda: model.solve(force=force),
                 lambda: model.project(force)):
        with pytest.raises(ValueError, match=r"force: contains NaN or inf \(at index \[\[4, 2\]\]"):
            call()
    with pytest.raises(ValueError, match=r"force: expected shape \(\d+, 3\)"):
        model.step(q, q, 0.02, force=np.zeros(3))


def test_a_polynomial_past_the_memory_is_refused_before_it_is_built(monkeypatch):
    from anisofem.reduced import model as module
    from anisofem.reduced.polynomial import build_bytes
    scene = cantilever()
    monkeypatch.setattr(module, "_available_bytes", lambda: 2 ** 30)
    points = scene.elements.weights.size
    need = [build_bytes(module.coordinates(m, True, scene.n_free), points) for m in (12, 13, 14)]
    assert need[0] <= 2 ** 30 < need[2]  # 12 modes fit in 1 GiB, 14 do not
    fits = 12 if need[1] > 2 ** 30 else 13
    with pytest.raises(ValueError, match=rf"modes: 14 modes make a basis of up to 119 coordinates"
                                         rf", whose polynomial needs about .* GiB .* 1 GiB "
                                         rf"available; at most {fits} modes fit"):
        ReducedModel(scene, modes=14)


@pytest.mark.skipif(not os.path.exists("/proc/self/status"), reason="Linux's /proc")
def test_the_memory_estimate_bounds_a_real_build():
    import subprocess
    import sys
    # the peak of this process image (VmHWM; ru_maxrss would start at the forking parent's)
    code = ("import anisofem as af\n"
            "from anisofem.reduced import ReducedModel\n"
            "from anisofem.reduced.polynomial import build_bytes\n"
            "def peak():\n"
            "    line = [l for l in open('/proc/self/status') if l.startswith('VmHWM')][0]\n"
            "    return int(line.split()[1]) * 1024\n"
            "scene = af.default_scene(af.box_beam(cells=(10, 2, 2)))\n"
            "before = peak()\n"
            "m = ReducedModel(scene, modes=10, validate=False)\n"
            "print((peak() - before) / build_bytes(m.r, scene.elements.weights.size))\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    assert 0.4 < float(done.stdout) < 1.3  # the estimate is the build's size, a little over
