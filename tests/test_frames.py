"""Vertex rotations and the multigrid hierarchy carried by them (anisofem.solvers.frames)."""
import numpy as np
import pytest
import scipy.sparse.linalg as spla

import anisofem as af
from anisofem.solvers import multigrid
from anisofem.solvers.frames import VertexFrames
from anisofem.physics.potential import Potential


def rotation(axis, angle):
    """(3, 3) the rotation by angle (rad) about axis (3,)."""
    k = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K


def test_a_rigid_rotation_is_every_vertex_rotation():
    mesh = af.box_beam(cells=(6, 2, 3))
    frames = VertexFrames(mesh, np.arange(3 * mesh.n_vertices))
    Q = rotation([1, -2, 0.5], 2.4)
    R = frames.rotations(mesh.vertices @ Q.T + [0.3, -1.0, 2.0])
    assert np.abs(R - Q).max() < 1e-12


def test_rotations_are_proper_even_for_a_mirrored_or_collapsed_star():
    mesh = af.box_beam(cells=(4, 2, 2))
    frames = VertexFrames(mesh, np.arange(3 * mesh.n_vertices))
    mirrored = mesh.vertices * [-1, 1, 1]
    collapsed = np.zeros_like(mesh.vertices)
    for x in (mirrored, collapsed):
        R = frames.rotations(x)
        assert np.abs(R @ R.transpose(0, 2, 1) - np.eye(3)).max() < 1e-12
        assert np.abs(np.linalg.det(R) - 1).max() < 1e-12
    assert np.array_equal(frames.rotations(collapsed), np.tile(np.eye(3), (mesh.n_vertices, 1, 1)))


def test_a_partly_held_vertex_keeps_the_identity():
    mesh = af.box_beam(cells=(4, 2, 2))
    free = np.arange(3 * mesh.n_vertices)
    free = free[free != 2]  # vertex 0 held along z only: a roller
    frames = VertexFrames(mesh, free)
    Q = rotation([0, 0, 1], 0.7)
    calls = []
    carried = frames.carry(lambda r: calls.append(r) or r, np.tile(np.eye(3), (mesh.n_vertices,
                                                                               1, 1)),
                           mesh.vertices @ Q.T)
    r = np.random.default_rng(0).normal(size=free.size)
    out = carried(r)
    # vertex 0's two free components pass through unrotated, the rest turn by Q^T then back
    assert np.allclose(calls[0][:2], r[:2]) and np.allclose(out, r)
    assert np.allclose(calls[0][2:5], Q.T @ r[2:5])


@pytest.fixture(scope="module")
def bent():
    """The 1,600-tet default cantilever at rest under its weight (sagging by about 29% of its
    length), and its Hessian there."""
    scene = af.default_scene(af.box_beam(cells=(20, 4, 4)))
    x = af.solve(scene, method="newton").x
    layout = scene.layout("csr")
    H = layout.matrix(Potential(scene).hessian_data(x, layout, project=False,
                                                    want_grad=False)[2])
    return scene, x, H


def cg_iterations(H, precondition):
    b = H @ np.random.default_rng(1).normal(size=H.shape[0])
    count = []
    spla.cg(H, b, rtol=1e-8, maxiter=2000, callback=count.append,
            M=spla.LinearOperator(H.shape, matvec=precondition, dtype=float))
    return len(count)


def test_the_hierarchy_built_at_rest_serves_a_bent_state_once_carried(bent):
    """CG to 1e-8 on the bent cantilever's Hessian: the hierarchy of the rest Hessian carried
    by the vertex rotations needs about as many iterations as one built there, and far fewer
    than itself unrotated (measured: 34, 29 and 132)."""
    scene, x, H = bent
    sag = -(x - scene.mesh.vertices)[:, 2].min()
    assert sag > 0.2 * 0.1
    layout, free, rest = scene.layout("csr"), scene.free_dofs, scene.initial_positions()
    potential = Potential(scene)

    def hierarchy(y):
        data = potential.hessian_data(y, layout, project=True, want_grad=False)[2]
        return multigrid.preconditioner(layout.matrix(data),
                                        multigrid.rigid_body_modes(y, free))
    at_rest = hierarchy(rest)
    frames = VertexFrames(scene.mesh, free)
    carried = frames.carry(at_rest, frames.rotations(rest), x)
    its = {name: cg_iterations(H, p) for name, p in
           (("stale", at_rest), ("carried", carried), ("fresh", hierarchy(x)))}
    print(its)
    assert its["carried"] <= 1.5 * its["fresh"]
    assert its["carried"] <= 0.6 * its["stale"]


def test_multigrid_newton_keeps_one_hierarchy_through_the_bending(bent):
    """The static solve from rest by multigrid CG builds its hierarchy once and lands on exact
    Newton's answer."""
    scene, x, _ = bent
    result = af.solve(scene, method="cg", preconditioner="amg")
    assert result.converged and result.factorizations == 1
    assert np.abs(result.x - x).max() < 1e-9 * np.abs(x - scene.mesh.vertices).max()
