"""Element types (anisofem.physics.elements) and the element loop on quadratic tets: quadrature
exactness, shape functions, raising a mesh to quadratic, and the quadratic element's energy,
gradient and Hessian against an independent quadrature and finite differences at ordinary and
extreme parameters, for both base laws."""
import itertools
import math

import numpy as np
import pytest

import anisofem as af
from anisofem.physics import kernels
from anisofem.physics.assembly import DenseLayout
from anisofem.physics.elements.tet4 import TET4
from anisofem.physics.elements.tet10 import TET10, quadratic_nodes
from anisofem.physics.scene import element_data
from test_derivatives import random_tet, rotation

E = 1e5


def monomial_integral(a, b, c):
    """Integral of xi^a eta^b zeta^c over the reference tet, as a fraction of its volume 1/6."""
    return 6.0 * math.factorial(a) * math.factorial(b) * math.factorial(c) / math.factorial(
        a + b + c + 3)


@pytest.mark.parametrize("element,degree", [(TET4, 1), (TET10, 5)])
def test_quadrature_is_positive_inside_and_exact_to_its_degree(element, degree):
    assert (element.weights > 0).all()
    assert abs(element.weights.sum() - 1.0) < 1e-15
    L = np.column_stack([1.0 - element.points.sum(1), element.points])
    assert (L > 0).all()
    for a, b, c in itertools.product(range(degree + 1), repeat=3):
        if a + b + c <= degree:
            p = element.points
            value = (element.weights * p[:, 0] ** a * p[:, 1] ** b * p[:, 2] ** c).sum()
            assert abs(value - monomial_integral(a, b, c)) < 1e-14


def test_tet10_rule_is_not_exact_beyond_degree_five():
    p, w = TET10.points, TET10.weights
    errors = [abs((w * p[:, 0] ** a * p[:, 1] ** b * p[:, 2] ** (6 - a - b)).sum()
                  - monomial_integral(a, b, 6 - a - b)) for a in range(7) for b in range(7 - a)]
    assert max(errors) > 1e-6  # the exactness test above can fail


@pytest.mark.parametrize("element", [TET4, TET10])
def test_shape_functions_interpolate_and_their_gradients_are_right(element):
    N = element.shape(element.nodes)
    assert np.abs(N - np.eye(element.n_nodes)).max() < 1e-15
    rng = np.random.default_rng(0)
    xi = rng.dirichlet(np.ones(4), size=20)[:, 1:]
    assert np.abs(element.shape(xi).sum(1) - 1.0).max() < 1e-14
    grad = element.shape_gradients(xi)
    h = 1e-6
    for k in range(3):
        step = np.zeros(3)
        step[k] = h
        fd = (element.shape(xi + step) - element.shape(xi - step)) / (2 * h)
        assert np.abs(fd - grad[:, :, k]).max() < 1e-8


def test_quadratic_nodes_share_edge_midpoints():
    mesh = af.box_beam(cells=(2, 1, 1))
    nodes, tets10 = quadratic_nodes(mesh.vertices, mesh.tets)
    assert nodes.shape[0] == mesh.n_vertices + mesh.edges.shape[0]
    assert np.unique(tets10[:, 4:]).size == mesh.edges.shape[0]
    X = nodes[tets10]
    for k, (i, j) in enumerate([(0, 1), (1, 2), (0, 2), (0, 3), (1, 3), (2, 3)]):
        assert np.abs(X[:, 4 + k] - 0.5 * (X[:, i] + X[:, j])).max() < 1e-15


class Quadratic:
    """Energy, gradient and dense Hessian of a mesh raised to quadratic tets, straight from
    the element loop."""

    def __init__(self, mesh, material):
        raised = mesh.raised()
        self.nodes, self.tets = raised.vertices, raised.cells
        self.elements = element_data(raised, material.per_element(mesh.n_tets))
        n = self.nodes.shape[0]
        self.layout = DenseLayout(self.tets, np.arange(3 * n).reshape(n, 3))

    def energy(self, x):
        e_iso, e_fib, _ = kernels.assemble(x, self.elements)
        return e_iso.sum() + e_fib.sum()

    def gradient(self, x):
        return kernels.assemble(x, self.elements, want_grad=True)[2]

    def hessian(self, x, project=False):
        data = self.layout.zeros()
        kernels.assemble(x, self.elements, want_hess=True, project=project,
                         hess_map=self.layout.map, hess_data=data)
        return self.layout.matrix(data)


def curved_state(rng, q, stretches, bend=0.05):
    """Nodes moved by a homogeneous deformation plus a quadratic field, so that F varies over
    the element (bend: its size relative to the element)."""
    F = rotation(rng) @ np.diag(stretches) @ rotation(rng)
    X = q.nodes
    size = np.ptp(X, axis=0).max()
    c = X.mean(0)
    quad = bend * ((X - c) ** 2)[:, [1, 2, 0]] / size
    return X @ F.T + quad @ F.T


def fd_check(q, x, h):
    g = q.gradient(x)
    gfd = np.zeros(x.size)
    Hfd = np.zeros((x.size, x.size))
    for k in range(x.size):
        xp, xm = x.copy(), x.copy()
        xp.flat[k] += h
        xm.flat[k] -= h
        gfd[k] = (q.energy(xp) - q.energy(xm)) / (2 * h)
        Hfd[:, k] = (q.gradient(xp) - q.gradient(xm)).ravel() / (2 * h)
    H = q.hessian(x)
    rel = lambda a, b: np.linalg.norm(a - b) / np.linalg.norm(b)  # noqa: E731
    return rel(g.ravel(), gfd), rel(H, Hfd), np.abs(H - H.T).max() / np.abs(H).max()


CASES = list(itertools.product(
    [0.0, E, 100 * E],                                       # kappa
    [0.3, 0.499],                                            # nu
    [(1.1, 0.9, 1.05), (0.2, 1.0, 1.3), (3.0, 2.0, 0.5)],    # principal stretches
))


@pytest.mark.parametrize("model", af.physics.material.MODELS)
@pytest.mark.parametrize("kappa,nu,stretches", CASES)
def test_quadratic_element_matches_finite_differences(kappa, nu, stretches, model):
    rng = np.random.default_rng(hash((kappa, nu, stretches)) % 2**32)
    mesh = random_tet(rng)
    d = rng.standard_normal(3)
    q = Quadratic(mesh, af.Material(E, nu, 1000.0, d / np.linalg.norm(d), kappa, model=model))
    x = curved_state(rng, q, stretches)
    h = 1e-6 / np.linalg.norm(mesh.shape_gradients[0], axis=1).max()
    grad_err, hess_err, asym = fd_check(q, x, h)
    assert grad_err < 1e-6 and hess_err < 1e-6 and asym < 1e-12


@pytest.mark.parametrize("model", af.physics.material.MODELS)
@pytest.mark.parametrize("flatness", [1e-2, 1e-3])
def test_quadratic_element_derivatives_on_nearly_flat_elements(flatness, model):
    rng = np.random.default_rng(int(flatness * 1e4))
    mesh = random_tet(rng, flatness)
    d = rng.standard_normal(3)
    q = Quadratic(mesh, af.Material(E, 0.48, 1000.0, d / np.linalg.norm(d), E, model=model))
    x = curved_state(rng, q, (1.2, 0.8, 1.0), bend=0.01)
    h = 1e-6 / np.linalg.norm(mesh.shape_gradients[0], axis=1).max()
    grad_err, hess_err, _ = fd_check(q, x, h)
    assert grad_err < 1e-6 and hess_err < 1e-6


def collapsed_gauss(order):
    """A tensor Gauss rule on the reference tet through the Duffy map, exact far beyond degree
    5: points (p, 3), weights (p,) as fractions of the volume."""
    t, w = np.polynomial.legendre.leggauss(order)
    t, w = 0.5 * (t + 1.0), 0.5 * w
    u, v, s = (a.ravel() for a in np.meshgrid(t, t, t, indexing="ij"))
    wu, wv, ws = (a.ravel() for a in np.meshgrid(w, w, w, indexing="ij"))
    xi = np.column_stack([u, v * (1 - u), s * (1 - u) * (1 - v)])
    return xi, 6.0 * wu * wv * ws * (1 - u) ** 2 * (1 - v)


def test_quadratic_stvk_energy_equals_an_independent_integral():
    """StVK + fiber energy of a curved state is a quartic in xi: the 14-point rule gives the
    integral that an 8^3-point collapsed Gauss rule gives, psi evaluated here in numpy."""
    rng = np.random.default_rng(5)
    mesh = random_tet(rng)
    d = np.array([0.6, 0.0, 0.8])
    mat = af.Material(E, 0.45, 1000.0, d, 3 * E)
    q = Quadratic(mesh, mat)
    x = curved_state(rng, q, (1.3, 0.7, 1.1), bend=0.3)
    xi, w = collapsed_gauss(8)
    G = np.einsum("pak,kj->paj", TET10.shape_gradients(xi), mesh.inverse_jacobians[0])
    F = np.einsum("ai,paj->pij", x[q.tets[0]], G)
    C = np.einsum("pki,pkj->pij", F, F)
    Egl = 0.5 * (C - np.eye(3))
    p = mat.per_element(1)
    trE = np.trace(Egl, axis1=1, axis2=2)
    I4 = np.einsum("i,pij,j->p", d, C, d)
    psi = (0.5 * p["lam"] * trE ** 2 + p["mu"] * np.einsum("pij,pij->p", Egl, Egl)
           + p["kappa"] * (I4 - 1) ** 2)
    expected = mesh.rest_volumes[0] * (w * psi).sum()
    assert abs(q.energy(x) - expected) < 1e-12 * expected


@pytest.mark.parametrize("model", af.physics.material.MODELS)
def test_quadratic_element_under_a_homogeneous_deformation_equals_the_linear_one(model):
    rng = np.random.default_rng(9)
    mesh = af.box_beam(cells=(2, 1, 1))
    mat = af.Material(E, 0.4, 1000.0, (0.0, 0.6, 0.8), E, model=model)
    q = Quadratic(mesh, mat)
    F = rotation(rng) @ np.diag([1.2, 0.9, 1.05])
    linear = af.energy(af.Scene(mesh, mat), mesh.vertices @ F.T)
    assert abs(q.energy(q.nodes @ F.T) - linear) < 1e-12 * linear


@pytest.mark.parametrize("model", af.physics.material.MODELS)
def test_quadratic_projected_hessian_is_psd(model):
    rng = np.random.default_rng(13)
    mesh = af.box_beam(cells=(2, 1, 1))
    q = Quadratic(mesh, af.Material(E, 0.45, 1000.0, (0.0, 0.6, 0.8), E, model=model))
    x = curved_state(rng, q, (0.5, 0.9, 0.7), bend=0.1)
    lam_true = np.linalg.eigvalsh(q.hessian(x))
    lam_proj = np.linalg.eigvalsh(q.hessian(x, project=True))
    assert lam_true.min() < -1e-6 * lam_true.max()  # compressed: the true Hessian is indefinite
    assert lam_proj.min() > -1e-10 * lam_proj.max()
