"""Curved quadratic tets (isoparametric 10-node tets, midside nodes off their edges' middles,
as Gmsh places them on curved surfaces): their volumes, Lame's thick sphere under internal
pressure, derivatives, and a folded tet named. Meshes: tests/data
(scripts/make_curved_meshes.py)."""
import os

import numpy as np
import pytest

import anisofem as af
from anisofem.physics.potential import Potential
from test_contact import central_differences

DATA = os.path.join(os.path.dirname(os.path.abspath(__file__)), "data")
INNER, OUTER = 0.01, 0.02
E, NU, P = 1e5, 0.3, 10.0


@pytest.fixture(scope="module")
def shells():
    """(the Gmsh octant at second order: curved; the linear one raised: straight-sided)."""
    curved = af.read_mesh(os.path.join(DATA, "shell_octant_2.msh"))
    straight = af.read_mesh(os.path.join(DATA, "shell_octant_1.msh")).raised()
    return curved, straight


def lame(r):
    """Lame's radial displacement (m) at radius r of the thick sphere under internal P."""
    return (P * INNER ** 3 / (E * (OUTER ** 3 - INNER ** 3))
            * ((1 - 2 * NU) * r + (1 + NU) * OUTER ** 3 / (2 * r ** 2)))


def octant_scene(mesh):
    """The octant on rollers on its three cut planes, pressure P on its inner wall."""
    X = mesh.vertices
    fixed = np.abs(X) < 1e-9
    wall = mesh.faces_where(lambda c: np.abs(np.linalg.norm(c, axis=-1) - INNER) < 0.2 * INNER)
    return af.Scene(mesh, af.Material(E, NU, 1000.0), fixed=fixed,
                    pressure=af.Pressure(wall, P))


def test_gmsh_second_order_tets_are_curved_and_their_volume_is_the_shells(shells):
    """The octant's volume pi/6 (b^3 - a^3): within 0.05% summed over the curved tets, where
    the straight-sided ones (chords) miss it by more than 0.4%."""
    curved, straight = shells
    assert curved.curved and not straight.curved
    exact = np.pi / 6 * (OUTER ** 3 - INNER ** 3)
    assert abs(curved.rest_volumes.sum() / exact - 1) < 5e-4
    assert abs(straight.rest_volumes.sum() / exact - 1) > 4e-3
    assert np.allclose(curved.point_weights.sum(axis=1), curved.rest_volumes)


def test_the_thick_sphere_follows_lame_on_curved_tets(shells):
    """Internal pressure: the inner and outer walls' mean radial displacement within 0.2% of
    Lame's on the curved tets; on the same mesh with straight sides, more than 1% off."""
    errors = {}
    for name, mesh in zip(("curved", "straight"), shells):
        result = af.solve(octant_scene(mesh))
        assert result.converged
        X = mesh.vertices
        R = np.linalg.norm(X, axis=1)
        radial = np.einsum("ij,ij->i", result.x - X, X / R[:, None])
        errors[name] = [abs(radial[np.abs(R - r) < 1e-3 * r].mean() / lame(r) - 1)
                        for r in (INNER, OUTER)]
        print(f"{name}: {mesh.n_tets} tets, inner and outer walls "
              f"{100 * errors[name][0]:.2f}% and {100 * errors[name][1]:.2f}% off Lame's")
    assert max(errors["curved"]) < 2e-3, errors
    assert min(errors["straight"]) > 1e-2, errors


def test_curved_tets_derivatives_match_central_differences(shells):
    """The potential's gradient and Hessian on the curved octant, pressure on, at a deformed
    state: within 1e-6 of central differences."""
    scene = octant_scene(shells[0])
    rng = np.random.default_rng(6)
    x = scene.with_fixed(scene.mesh.vertices + rng.normal(scale=2e-4,
                                                           size=scene.mesh.vertices.shape))
    pot = Potential(scene)
    layout = scene.full_layout
    _, g, data = pot.hessian_data(x, layout)
    H = layout.matrix(data)
    for p in rng.normal(size=(2,) + x.shape):
        p /= np.linalg.norm(p)
        slope, change = central_differences(pot, x, p, 1e-7)
        assert slope == pytest.approx(float((g * p).sum()), rel=1e-6)
        Hp = (H @ p.ravel()).reshape(-1, 3)
        assert np.abs(change - Hp).max() <= 1e-6 * np.abs(Hp).max()


def test_a_curved_tet_folded_by_its_midside_node_is_named():
    """A midside node pulled past the opposite face folds its tet: refused, the tet named."""
    mesh = af.box_beam(size=(0.01, 0.01, 0.01), cells=(1, 1, 1)).raised()
    X = mesh.vertices.copy()
    cells = mesh.cells
    mid = cells[0, 4]                    # the midside node of tet 0's edge (0, 1)
    a, b = X[cells[0, 0]], X[cells[0, 1]]
    X[mid] = (a + b) / 2 + 2.0 * (X[cells[0, 2:4]].mean(axis=0) - (a + b) / 2)
    with pytest.raises(ValueError, match=r"tets: curved tet \d+ is (inverted|flat) at its "
                                         r"(quadrature point|corner) \d+"):
        af.TetMesh(X, cells)


def test_a_reduced_model_of_curved_tets_has_their_energy():
    """A beam bent by a smooth map (its quadratic tets curved): the reduced model's energy
    polynomial reads their quadrature, its energy at q the FEM's at x0 + U q to 1e-10."""
    from anisofem.reduced import ReducedModel
    beam = af.box_beam(size=(0.1, 0.02, 0.02), cells=(5, 1, 1)).raised()
    X = beam.vertices.copy()
    X[:, 2] += 0.01 * np.sin(np.pi * X[:, 0] / 0.1)
    mesh = af.TetMesh(X, beam.cells)
    assert mesh.curved
    scene = af.Scene(mesh, af.Material(1e5, 0.45, 1000.0, np.array([1.0, 0, 0]), 1e5),
                     fixed=X[:, 0] <= 1e-9, gravity=(0, 0, -9.81))
    model = ReducedModel(scene, modes=6, validate=False)
    rng = np.random.default_rng(7)
    for _ in range(3):
        q = rng.normal(scale=0.02, size=model.r)
        fem = Potential(scene).energy(model.positions(q)) + float(
            (scene.external_force * model.positions(q)).sum())
        assert model.energy(q) == pytest.approx(fem, rel=1e-10, abs=1e-12)
