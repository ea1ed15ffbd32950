"""Quadratic (10-node) tet meshes: validation, raising a linear mesh, lumped masses and
consistent loads, patch tests against exact linear-elastic fields, inversion at quadrature
points, files, and the static answer."""
import meshio
import numpy as np
import pytest

import anisofem as af
from anisofem.studies import convergence
from anisofem.physics.inversion import volume_change
from test_derivatives import random_tet

E = 1e5


@pytest.fixture(scope="module")
def beam():
    return af.box_beam(cells=(4, 2, 2), size=(0.1, 0.02, 0.02), order=2)


def test_raised_mesh_shares_midside_nodes_at_edge_midpoints(beam):
    linear = af.box_beam(cells=(4, 2, 2), size=(0.1, 0.02, 0.02))
    assert beam.order == 2 and beam.cells.shape == (linear.n_tets, 10)
    assert np.array_equal(beam.tets, linear.tets)
    assert beam.n_vertices == linear.n_vertices + linear.edges.shape[0]
    mids = beam.edge_nodes(linear.edges)
    X = beam.vertices
    assert np.abs(X[mids] - X[linear.edges].mean(axis=1)).max() < 1e-15
    with pytest.raises(ValueError, match="not an edge"):
        beam.edge_nodes([[0, beam.n_vertices - 1]])


def test_inverted_quadratic_tets_are_reordered_with_their_midside_nodes(beam):
    cells = beam.cells.copy()
    cells[0, [2, 3]] = cells[0, [3, 2]]
    cells[0, 4:] = cells[0, [4, 8, 7, 6, 5, 9]]   # the same tet labelled the other way round
    fixed = af.TetMesh(beam.vertices, cells)
    assert np.array_equal(fixed.cells, beam.cells)
    with pytest.raises(ValueError, match="inverted"):
        af.TetMesh(beam.vertices, cells, fix_orientation=False)


def test_bad_quadratic_meshes_are_refused(beam):
    X = beam.vertices.copy()
    X[beam.cells[0, 5]] += 1e-4       # a midside node off its edge's middle: a curved tet
    assert af.TetMesh(X, beam.cells).curved and not beam.curved
    cells = beam.cells.copy()
    # a second node at the middle of tet 0's first edge, used by tet 0 only
    X = np.vstack([beam.vertices, beam.vertices[cells[0, 4]]])
    cells[0, 4] = X.shape[0] - 1
    with pytest.raises(ValueError, match="has two midside nodes"):
        af.TetMesh(X, cells)
    with pytest.raises(ValueError, match=r"\(m, 4\) linear or \(m, 10\) quadratic"):
        af.TetMesh(beam.vertices, beam.cells[:, :5])
    with pytest.raises(ValueError, match="order"):
        af.box_beam(order=3)


def test_hrz_masses_are_positive_and_loads_consistent(beam):
    rho, b = 1200.0, np.array([1.0, -2.0, 3.0])
    scene = af.Scene(beam, af.Material(E, 0.3, rho), body_force=b)
    volume = beam.rest_volumes.sum()
    assert scene.masses.min() > 0
    assert abs(scene.masses.sum() - rho * volume) < 1e-12 * rho * volume
    corners = np.unique(beam.tets)
    assert np.allclose(scene.masses[corners].sum(), rho * volume / 9)  # 4 x 1/36 of each tet
    assert np.allclose(scene.external_force.sum(0), b * volume, rtol=1e-12)
    # a single tet: the consistent load is -V/20 at its corners and V/5 at its midside nodes
    one = random_tet(np.random.default_rng(0)).raised()
    f = af.Scene(one, af.Material(), body_force=(0, 0, 1.0)).external_force[:, 2]
    V = one.rest_volumes[0]
    assert np.allclose(f[:4], -V / 20) and np.allclose(f[4:], V / 5)


def test_traction_goes_to_midside_nodes(beam):
    faces = beam.faces_where(lambda c: c[:, 0] > 0.1 - 1e-9)
    scene = af.Scene(beam, af.Material(), traction=(0, 0, -50.0), traction_faces=faces)
    area = 0.02 * 0.02
    assert np.allclose(scene.external_force.sum(0), [0, 0, -50.0 * area], rtol=1e-12)
    assert np.abs(scene.external_force[np.unique(faces)]).max() == 0.0


def elasticity(lam, mu, kappa, d):
    """The small-strain stiffness C (3, 3, 3, 3) of StVK plus the fiber term at rest."""
    I = np.eye(3)
    return (lam * np.einsum("ij,kl->ijkl", I, I) + mu * (np.einsum("ik,jl->ijkl", I, I)
                                                          + np.einsum("il,jk->ijkl", I, I))
            + 8 * kappa * np.einsum("i,j,k,l->ijkl", d, d, d, d))


@pytest.mark.parametrize("order", [1, 2])
def test_patch_test_reproduces_a_field_of_the_element_order_exactly(order):
    """Linear elasticity (the Hessian at rest) with every boundary node prescribed: linear tets
    reproduce a linear field, quadratic tets a quadratic one under the constant body force
    that makes it exact; the interior nodes come out right to round-off."""
    rng = np.random.default_rng(order)
    mesh = af.box_beam(cells=(3, 3, 3), size=(0.03, 0.03, 0.03), order=order)
    d = np.array([0.6, 0.0, 0.8])
    material = af.Material(E, 0.45, 1000.0, d, 2 * E)
    lam, mu = material.per_element(1)["lam"][0], material.per_element(1)["mu"][0]
    C = elasticity(lam, mu, 2 * E, d)
    X = mesh.vertices
    G = rng.standard_normal((3, 3)) * 1e-3
    A = rng.standard_normal((3, 3, 3)) * 1e-2 if order == 2 else np.zeros((3, 3, 3))
    A = 0.5 * (A + A.transpose(0, 2, 1))             # u_i = G_ij X_j + A_ijk X_j X_k / 2
    u = X @ G.T + 0.5 * np.einsum("ijk,nj,nk->ni", A, X, X)
    grad_strain = 0.5 * (A + A.transpose(1, 0, 2))   # d eps_ij / d X_k
    b = -np.einsum("ijkl,klj->i", C, grad_strain)    # -div sigma, constant
    boundary = np.zeros(mesh.n_vertices, bool)
    boundary[np.unique(mesh.boundary_faces)] = True
    if order == 2:
        faces = mesh.boundary_faces
        boundary[mesh.edge_nodes(faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2))] = True
    scene = af.Scene(mesh, material, fixed=np.flatnonzero(boundary), body_force=b)
    K = af.hessian(scene, X).toarray()
    free = np.repeat(~boundary, 3)
    f = scene.external_force.ravel()
    u_full = u.ravel()
    solved = np.linalg.solve(K[np.ix_(free, free)], f[free] - K[np.ix_(free, ~free)] @
                             u_full[~free])
    assert (~boundary).sum() > 0
    assert np.abs(solved - u_full[free]).max() <= 1e-9 * np.abs(u).max()


def test_inversion_is_seen_at_quadrature_points():
    mesh = af.TetMesh(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1.0]]),
                      [[0, 1, 2, 3]]).raised()
    x = mesh.vertices.copy()
    assert abs(volume_change(mesh, x)[0]) < 1e-12
    x[mesh.edge_nodes([[1, 2]])] = [[0.1, 0.1, 0.0]]   # pulled across towards vertex 0
    assert (np.linalg.det(np.stack([x[1] - x[0], x[2] - x[0], x[3] - x[0]], 1)) > 0)
    assert volume_change(mesh, x)[0] <= -1.0             # the corners alone would miss it
    assert af.inversion.inversion(mesh, x).inverted == 1


def test_quadratic_files_round_trip_and_mixed_orders_are_refused(beam, tmp_path):
    for ext in (".vtu", ".msh"):
        path = tmp_path / f"beam{ext}"
        af.write_mesh(path, beam)
        back = af.read_mesh(path)
        assert back.order == 2 and np.array_equal(back.cells, beam.cells)
    linear = af.box_beam(cells=(1, 1, 1))
    mixed = meshio.Mesh(beam.vertices, [("tetra", linear.tets), ("tetra10", beam.cells)])
    mixed.write(tmp_path / "mixed.vtu")
    with pytest.raises(ValueError, match="mixes linear"):
        af.read_mesh(tmp_path / "mixed.vtu")
    cubic = meshio.Mesh(np.zeros((20, 3)), [("tetra20", np.arange(20)[None])])
    cubic.write(tmp_path / "cubic.msh", file_format="gmsh22")
    with pytest.raises(ValueError, match="tetra20"):
        af.read_mesh(tmp_path / "cubic.msh")


def test_quadratic_cantilever_sags_nearer_the_continuum():
    """The 200-tet cantilever of the paper's material: quadratic tets on the same cells sag 60% more
    than linear ones (linear tets lock in bending at nu = 0.48)."""
    sags = []
    for order in (1, 2):
        mesh = af.box_beam(cells=(10, 2, 2), order=order)
        scene = af.default_scene(mesh)
        result = af.solve(scene)
        assert result.converged
        sags.append(-af.metrics.tip_displacement(mesh, result.x)[2])
    assert sags[1] > 1.5 * sags[0]


def test_the_network_and_its_runtime_refuse_quadratic_tets(beam):
    pytest.importorskip("torch")
    from anisognn.graph import from_scene
    from export.runtime import OnnxSimulator
    from export import model_path
    scene = af.default_scene(beam)
    with pytest.raises(ValueError, match="quadratic tets"):
        from_scene(scene)
    with pytest.raises(ValueError, match="quadratic"):
        OnnxSimulator(model_path("directional"), beam.vertices, beam.cells)
    result = af.trade(scene, steps=10, progress=False)
    assert any("quadratic" in note for note in result["notes"])
    assert {r["kind"] for r in result["rungs"]} == {"fem", "reduced"}


def test_red_refinement_splits_each_tet_into_eight_of_the_same_body():
    mesh = af.box_beam(cells=(3, 2, 2))
    fine = mesh.refined()
    assert fine.n_tets == 8 * mesh.n_tets
    assert np.array_equal(fine.vertices[:mesh.n_vertices], mesh.vertices)
    assert abs(fine.rest_volumes.sum() - mesh.rest_volumes.sum()) < 1e-15
    assert fine.rest_volumes.min() > 0 and np.isclose(fine.rest_volumes.sum() / fine.n_tets,
                                                      mesh.rest_volumes.sum() / mesh.n_tets / 8)
    assert fine.boundary_faces.shape[0] == 4 * mesh.boundary_faces.shape[0]
    with pytest.raises(ValueError, match="refine the linear mesh"):
        mesh.raised().refined()


def test_neo_hookean_quadratic_tets_solve_and_step_at_ten_g():
    mesh = af.box_beam(cells=(6, 2, 2), order=2)
    scene = af.Scene(mesh, af.Material(E, 0.48, 1000.0, (1, 0, 0), E, model="neohookean"),
                     fixed=af.metrics.end_vertices(mesh, 0, "min"), gravity=(0, 0, -98.1))
    result = af.solve(scene)
    assert result.converged and result.inversion.physical
    rollout = af.simulate(scene, 5)
    assert rollout.completed and rollout.converged


@pytest.mark.parametrize("ks", [(1, 2, 4), (3, 4, 6)])
def test_richardson_recovers_limit_and_order(ks):
    limit, p = convergence.richardson(ks, [0.028 - 0.004 * k ** -1.7 for k in ks])
    assert abs(limit - 0.028) < 1e-14 and abs(p - 1.7) < 1e-9
    with pytest.raises(ValueError, match="monotonically"):
        convergence.richardson(ks, [1.0, 2.0, 1.5])
    with pytest.raises(ValueError, match="asymptotic"):  # differences that grow
        convergence.richardson(ks, [1.0, 2.0, 3.5])


def test_convergence_command_measures_each_sequence(monkeypatch, tmp_path):
    """A small run (cells 4 x 1 x 1 refined 1, 2, 3 times): every sequence sags more when
    refined, quadratic tets sag more than linear ones on the same cells, the limit lies above
    every sag, and the cheapest rows are within the asked error of it."""
    monkeypatch.setattr(convergence, "BASE_CELLS", (4, 1, 1))
    monkeypatch.setattr(convergence, "TIMED_STEPS", 1)
    report = convergence.run(out=tmp_path / "c.json", refinements=(1, 2, 3))
    rows = report["rows"]
    assert len(rows) == 12 and len(report["sequences"]) == 4
    assert report["sequences"]["order 2, 6 tets per cell"]["observed_order"] > 0
    for order in (1, 2):
        for split in (5, 6):
            sags = [r["sag"] for r in rows if (r["order"], r["tets_per_cell"]) == (order, split)]
            assert sags == sorted(sags)
    linear = {(r["tets_per_cell"], r["refinement"]): r["sag"] for r in rows if r["order"] == 1}
    assert all(r["sag"] > linear[r["tets_per_cell"], r["refinement"]] for r in rows
               if r["order"] == 2)
    assert all(0 < r["error"] < 1 and r["ms_per_step"] > 0 for r in rows)
    for order, best in report["cheapest"].items():
        within = [r for r in rows if r["order"] == int(order) and r["error"] <= 0.02]
        assert (best is None) == (not within)
        if best:
            assert best["ms_per_step"] == min(r["ms_per_step"] for r in within)
    with pytest.raises(ValueError, match="reference sequence"):
        convergence.run(out=tmp_path / "d.json", refinements=(1, 2, 3), max_unknowns=1000)
