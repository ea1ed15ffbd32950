"""The numba kernels and the independent numpy implementation agree."""
import numpy as np
import pytest

import anisofem as af
from anisofem.physics import reference_numpy as ref


@pytest.mark.parametrize("activated", [False, True])
def test_numba_and_numpy_agree_with_per_element_fibers(activated):
    """Per-element fibers and stiffnesses, passive or each contracting by its own activation."""
    rng = np.random.default_rng(5)
    mesh = af.box_beam(cells=(4, 2, 2))
    d = rng.standard_normal((mesh.n_tets, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    kappa = rng.uniform(0.1, 10, mesh.n_tets) * 1e5
    activation = rng.uniform(0, 0.6, mesh.n_tets) if activated else 0.0
    scene = af.Scene(mesh, af.Material(1e5, 0.45, 1000.0, d, kappa, activation=activation))
    x = mesh.vertices + 2e-3 * rng.standard_normal(mesh.vertices.shape)
    e_ref, g_ref = ref.elastic_energy_gradient(scene, x)
    split = af.metrics.energy_split(scene, x)
    assert abs(split["isotropic"] + split["fiber"] - e_ref) < 1e-12 * e_ref
    assert np.abs(af.gradient(scene, x) - g_ref).max() < 1e-10 * np.abs(g_ref).max()
    for project in (False, True):
        H = af.hessian(scene, x, project=project).toarray()
        H_ref = ref.elastic_hessian(scene, x, project=project).toarray()
        assert np.abs(H - H_ref).max() < 1e-10 * np.abs(H_ref).max()


def test_the_numpy_reference_refuses_what_it_does_not_implement():
    mesh = af.box_beam(cells=(2, 2, 2))
    scene = af.Scene(mesh, af.Material(model="neohookean"))
    with pytest.raises(ValueError, match="StVK base material only"):
        ref.elastic_energy_gradient(scene, mesh.vertices)
