"""Mesh generators, topology helpers and meshio round trips."""
import meshio
import numpy as np
import pytest
from conftest import mirror_partner

import anisofem as af
from anisofem.physics import mesh as mesh_module


@pytest.mark.parametrize("make,volume", [
    (lambda: af.box_beam((0.1, 0.02, 0.03), (6, 2, 4)), 0.1 * 0.02 * 0.03),
    (lambda: af.box_beam(cells=(3, 2, 2)), 0.1 * 0.02 * 0.02),
    (lambda: af.box_beam((0.1, 0.02, 0.03), (5, 3, 2), tets_per_cell=6), 0.1 * 0.02 * 0.03),
    (lambda: af.t_shape(), 0.02 * (0.1 * 0.02 + 0.02 * 0.06)),
    (lambda: af.y_shape(), 0.02 * (0.1 * 0.02 + 0.02 * 0.06)),  # a shear keeps the volume
])
def test_generators_fill_their_shape(make, volume):
    mesh = make()
    assert (mesh.rest_volumes > 0).all()
    assert abs(mesh.rest_volumes.sum() - volume) < 1e-12 * volume


def test_cylinder_volume_converges_to_pi_r2_l():
    errs = []
    for n, rings in [(2, 1), (4, 2), (8, 4)]:
        mesh = af.cylinder_beam(0.1, 0.01, 4, n, rings)
        errs.append(abs(mesh.rest_volumes.sum() / (np.pi * 0.01 ** 2 * 0.1) - 1))
    assert errs[0] > errs[1] > errs[2] and errs[2] < 0.01


@pytest.mark.parametrize("cells,tets", [((3, 2, 2), 60), ((6, 2, 2), 120)])
def test_training_sizes(cells, tets):
    assert af.box_beam(cells=cells).n_tets == tets
    assert af.cylinder_beam(cells_along=cells[0] // 3, section_cells=2, rings=1).n_tets == \
        60 * cells[0] // 3


@pytest.mark.parametrize("make,axes", [
    (lambda: af.box_beam(cells=(4, 2, 4)), (1, 2)),
    (lambda: af.box_beam(cells=(3, 4, 2), tets_per_cell=6), (1, 2)),
    (lambda: af.cylinder_beam(section_cells=4, rings=1), (1, 2)),
    (lambda: af.t_shape(), (0, 1)),
])
def test_alternating_split_is_mirror_symmetric(make, axes):
    mesh = make()
    tets = {tuple(sorted(t)) for t in mesh.tets.tolist()}
    for axis in axes:
        j = mirror_partner(mesh.vertices, axis)
        assert {tuple(sorted(t)) for t in j[mesh.tets].tolist()} == tets


@pytest.mark.parametrize("tets_per_cell", [5, 6])
def test_box_splits_are_conforming(tets_per_cell):
    """Every face inside the box is shared by exactly two tets, every face on its boundary lies
    on one of the box's six planes."""
    mesh = af.box_beam((0.1, 0.02, 0.02), (3, 3, 2), tets_per_cell=tets_per_cell)
    assert mesh.n_tets == tets_per_cell * 18
    faces = np.sort(mesh.tets[:, [[1, 2, 3], [0, 2, 3], [0, 1, 3], [0, 1, 2]]].reshape(-1, 3), 1)
    _, count = np.unique(faces, axis=0, return_counts=True)
    assert count.max() == 2
    lo, hi = mesh.vertices.min(0), mesh.vertices.max(0)
    X = mesh.vertices[mesh.boundary_faces]
    on_plane = (np.isclose(X, lo).all(axis=1) | np.isclose(X, hi).all(axis=1)).any(axis=1)
    assert on_plane.all()
    with pytest.raises(ValueError, match="tets_per_cell"):
        af.box_beam(tets_per_cell=4)


def test_coloring_separates_blocks_sharing_a_vertex(monkeypatch):
    monkeypatch.setattr(mesh_module, "ASSEMBLY_BLOCK", 7)  # many blocks on a small mesh
    mesh = af.box_beam(cells=(6, 3, 3))
    starts, ptr = mesh.coloring
    assert sorted(starts.tolist()) == list(range(0, mesh.n_tets, 7))
    assert len(ptr) - 1 >= 2
    for c in range(len(ptr) - 1):
        verts = np.concatenate([mesh.tets[s:s + 7].ravel() for s in starts[ptr[c]:ptr[c + 1]]])
        blocks = np.concatenate([np.full(mesh.tets[s:s + 7].size, s)
                                 for s in starts[ptr[c]:ptr[c + 1]]])
        # a vertex may repeat within a block, never across two blocks of one color
        pairs = np.unique(np.stack([verts, blocks]), axis=1)
        assert np.unique(pairs[0]).size == pairs.shape[1]


def test_boundary_faces_point_outward_and_close_the_surface():
    mesh = af.cylinder_beam(section_cells=2, rings=1)
    F = mesh.boundary_faces
    X = mesh.vertices
    n = np.cross(X[F[:, 1]] - X[F[:, 0]], X[F[:, 2]] - X[F[:, 0]]) / 2
    assert np.abs(n.sum(axis=0)).max() < 1e-15  # closed surface: area vectors cancel
    # divergence theorem: volume = 1/3 sum (centroid . area vector)
    vol = np.einsum("ij,ij->", X[F].mean(axis=1), n) / 3
    assert abs(vol - mesh.rest_volumes.sum()) < 1e-12 * vol


def test_edges_are_unique_and_complete():
    mesh = af.box_beam(cells=(2, 2, 2))
    e = mesh.edges
    assert (e[:, 0] < e[:, 1]).all() and len(np.unique(e, axis=0)) == len(e)
    for t in mesh.tets[:5]:
        for a in range(4):
            for b in range(a + 1, 4):
                assert any((e == sorted((t[a], t[b]))).all(1))


@pytest.mark.parametrize("ext", ["msh", "vtu", "xdmf"])
def test_write_and_read_round_trip(tmp_path, ext, beam):
    scene = af.Scene(beam, af.Material.paper((0, 1, 0), 1e5), fixed=[0, 1, 2],
                     gravity=(0, 0, -9.81))
    x = beam.vertices + 1e-3 * np.random.default_rng(0).standard_normal(beam.vertices.shape)
    path = tmp_path / f"out.{ext}"
    af.write_mesh(path, beam, x, scene)
    raw = meshio.read(path)
    assert np.allclose(raw.point_data["displacement"], x - beam.vertices, atol=1e-15)
    assert np.allclose(raw.cell_data["energy"][0], af.element_energy(scene, x))
    assert np.allclose(raw.cell_data["fiber_direction"][0], [0, 1, 0])
    back = af.read_mesh(path)
    assert np.array_equal(back.tets, beam.tets) and np.allclose(back.vertices, beam.vertices)
    assert [p.name for p in tmp_path.iterdir()] == [f"out.{ext}"]  # no temporary left over


def test_read_mesh_rejects_a_file_without_tets(tmp_path):
    path = tmp_path / "tri.vtu"
    meshio.write(path, meshio.Mesh(np.eye(3), [("triangle", np.array([[0, 1, 2]]))]))
    with pytest.raises(ValueError, match="no tetra"):
        af.read_mesh(path)
