"""Gradient and Hessian of the element energy (StVK and Neo-Hookean bases) against central
finite differences, at ordinary and extreme parameters; rigid-rotation invariance; properties
of the PSD projections."""
import itertools

import numpy as np
import pytest

import anisofem as af

E = 1e5


def rotation(rng):
    q, r = np.linalg.qr(rng.standard_normal((3, 3)))
    q *= np.sign(np.diag(r))
    return q if np.linalg.det(q) > 0 else -q


def random_tet(rng, flatness=1.0):
    """A random positively oriented rest tet; flatness < 1 squashes it towards a plane."""
    while True:
        X = rng.standard_normal((4, 3)) * 0.01
        X[:, 2] *= flatness
        X = X @ rotation(rng).T
        a, b, c = X[1] - X[0], X[2] - X[0], X[3] - X[0]
        if np.dot(a, np.cross(b, c)) < 0:
            X[[2, 3]] = X[[3, 2]]
        try:
            return af.TetMesh(X, [[0, 1, 2, 3]])
        except ValueError:
            continue


def deformed(rng, mesh, stretches):
    """x = R1 diag(stretches) R2 X + noise-free translation: a homogeneous deformation."""
    F = rotation(rng) @ np.diag(stretches) @ rotation(rng)
    return mesh.vertices @ F.T + rng.standard_normal(3) * 0.01


def fd_gradient(scene, x, h):
    g = np.zeros(x.size)
    for k in range(x.size):
        xp, xm = x.copy(), x.copy()
        xp.flat[k] += h
        xm.flat[k] -= h
        g[k] = (af.energy(scene, xp) - af.energy(scene, xm)) / (2 * h)
    return g.reshape(x.shape)


def fd_hessian(scene, x, h):
    H = np.zeros((x.size, x.size))
    for k in range(x.size):
        xp, xm = x.copy(), x.copy()
        xp.flat[k] += h
        xm.flat[k] -= h
        H[:, k] = (af.gradient(scene, xp) - af.gradient(scene, xm)).ravel() / (2 * h)
    return H


def rel_err(a, b):
    return np.linalg.norm(a - b) / np.linalg.norm(b)


def min_altitude(mesh):
    return 1.0 / np.linalg.norm(mesh.shape_gradients[0], axis=1).max()


CASES = list(itertools.product(
    [0.0, E / 5, E, 10 * E, 100 * E],                        # kappa
    [0.0, 0.3, 0.48, 0.499],                                 # nu
    [(1.1, 0.9, 1.05), (0.2, 1.0, 1.3), (3.0, 2.0, 0.5)],    # principal stretches
))


@pytest.mark.parametrize("model", af.physics.material.MODELS)
@pytest.mark.parametrize("kappa,nu,stretches", CASES)
def test_gradient_and_hessian_match_finite_differences(kappa, nu, stretches, model):
    rng = np.random.default_rng(hash((kappa, nu, stretches)) % 2**32)
    mesh = random_tet(rng)
    d = rng.standard_normal(3)
    mat = af.Material(E, nu, 1000.0, d / np.linalg.norm(d), kappa, model=model)
    scene = af.Scene(mesh, mat)
    x = deformed(rng, mesh, stretches)
    h = 1e-6 * min_altitude(mesh)
    g = af.gradient(scene, x)
    assert rel_err(g, fd_gradient(scene, x, h)) < 1e-6
    H = af.hessian(scene, x).toarray()
    assert rel_err(H, fd_hessian(scene, x, h)) < 1e-6
    assert np.abs(H - H.T).max() <= 1e-12 * np.abs(H).max()


@pytest.mark.parametrize("model", af.physics.material.MODELS)
@pytest.mark.parametrize("flatness", [1e-2, 1e-3])
@pytest.mark.parametrize("kappa", [0.0, E, 100 * E])
def test_derivatives_on_nearly_flat_elements(flatness, kappa, model):
    rng = np.random.default_rng(int(flatness * 1e4) + int(kappa))
    mesh = random_tet(rng, flatness)
    quality = 6 * mesh.rest_volumes[0] / np.linalg.norm(
        mesh.vertices[1:] - mesh.vertices[0], axis=1).max() ** 3
    assert quality < 10 * flatness  # the element really is nearly flat
    d = rng.standard_normal(3)
    scene = af.Scene(mesh, af.Material(E, 0.48, 1000.0, d / np.linalg.norm(d), kappa,
                                       model=model))
    x = deformed(rng, mesh, (1.2, 0.8, 1.0))
    h = 1e-6 * min_altitude(mesh)
    assert rel_err(af.gradient(scene, x), fd_gradient(scene, x, h)) < 1e-6
    assert rel_err(af.hessian(scene, x).toarray(), fd_hessian(scene, x, h)) < 1e-6


def test_incremental_potential_derivatives():
    rng = np.random.default_rng(7)
    mesh = af.box_beam(cells=(2, 2, 2))
    d = np.array([1.0, 1.0, 0.0]) / np.sqrt(2)
    scene = af.Scene(mesh, af.Material(E, 0.45, 1100.0, d, 2 * E), fixed=[0, 1],
                     gravity=(0, 0, -9.81), nodal_force=rng.standard_normal((mesh.n_vertices, 3)))
    x = mesh.vertices + 1e-3 * rng.standard_normal(mesh.vertices.shape)
    x_hat = mesh.vertices + 1e-3 * rng.standard_normal(mesh.vertices.shape)
    dt = 0.02
    h = 1e-8
    g = af.gradient(scene, x, x_hat, dt)
    gfd = np.zeros(x.size)
    for k in range(x.size):
        xp, xm = x.copy(), x.copy()
        xp.flat[k] += h
        xm.flat[k] -= h
        gfd[k] = (af.energy(scene, xp, x_hat, dt) - af.energy(scene, xm, x_hat, dt)) / (2 * h)
    assert rel_err(g.ravel(), gfd) < 1e-6
    H = af.hessian(scene, x, x_hat, dt).toarray()
    Hfd = np.stack([(af.gradient(scene, x + h * np.eye(x.size)[k].reshape(x.shape), x_hat, dt)
                     - af.gradient(scene, x - h * np.eye(x.size)[k].reshape(x.shape), x_hat, dt)
                     ).ravel() / (2 * h) for k in range(x.size)], axis=1)
    assert rel_err(H, Hfd) < 1e-6


@pytest.mark.parametrize("kappa", [0.0, E, 100 * E])
def test_energy_is_invariant_to_rigid_rotation(kappa):
    rng = np.random.default_rng(3)
    mesh = af.box_beam(cells=(3, 2, 2))
    scene = af.Scene(mesh, af.Material(E, 0.48, 1000.0, (0.0, 0.6, 0.8), kappa))
    x = mesh.vertices + 2e-3 * rng.standard_normal(mesh.vertices.shape)
    ref = af.metrics.energy_split(scene, x)
    for _ in range(5):
        Q = rotation(rng)
        rot = af.metrics.energy_split(scene, x @ Q.T + rng.standard_normal(3))
        for term in ("isotropic", "fiber"):
            assert abs(rot[term] - ref[term]) <= 1e-12 * max(abs(ref["isotropic"]), 1e-300)


def test_projected_hessian_is_psd_and_exact_in_tension():
    rng = np.random.default_rng(11)
    for stretches, compressed in [((0.5, 0.9, 0.7), True), ((1.3, 1.2, 1.1), False)]:
        mesh = random_tet(rng)
        d = rng.standard_normal(3)
        scene = af.Scene(mesh, af.Material(E, 0.3, 1000.0, d / np.linalg.norm(d), E))
        x = deformed(rng, mesh, stretches)
        H = af.hessian(scene, x).toarray()
        Hp = af.hessian(scene, x, project=True).toarray()
        lam_true = np.linalg.eigvalsh(H)
        lam_proj = np.linalg.eigvalsh(Hp)
        assert lam_proj.min() >= -1e-9 * lam_proj.max()
        if compressed:
            assert lam_true.min() < -1e-6 * lam_true.max()  # the true Hessian is indefinite
        else:
            assert np.abs(Hp - H).max() <= 1e-12 * np.abs(H).max()  # nothing to project


def test_closed_form_eigen_decomposition_holds_for_nearly_repeated_eigenvalues():
    from anisofem.physics.sym3 import eigen
    rng = np.random.default_rng(12)
    w, V = np.empty(3), np.empty((3, 3))
    worst = 0.0
    for k in range(3000):
        Q = rotation(rng)
        gap = 10.0 ** rng.uniform(-15, 0)
        d = [(1.0, 1.0 + gap, rng.uniform(0.01, 9)), (1.0, 1.0 + gap, 1.0 - gap),
             (1e-6, 1.0, 9.0), tuple(rng.standard_normal(3))][k % 4]
        A = Q @ np.diag(d) @ Q.T
        eigen(A.copy(), w, V)
        assert np.abs(V.T @ V - np.eye(3)).max() < 1e-14
        worst = max(worst, np.abs(A @ V - V * w).max() / np.abs(A).max())
    assert worst < 1e-14
    eigen(np.eye(3) * 2.0, w, V)
    assert np.array_equal(w, [2.0, 2.0, 2.0]) and np.array_equal(V, np.eye(3))
