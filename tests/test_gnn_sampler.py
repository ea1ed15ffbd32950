"""The training sampler: reproducible samples, and the optional at-rest (static equilibrium)
starting states."""
import numpy as np

import anisofem as af
from anisognn.sampler import Sampler, SamplerConfig

QUIET = dict(noise_position=0.0, noise_velocity=0.0)


def test_a_sample_depends_on_seed_and_index_only():
    a, b = Sampler(3), Sampler(3)
    later = b.sample(7)                       # drawn out of order on purpose
    first = b.sample(2)
    np.testing.assert_array_equal(a.sample(2).x, first.x)
    np.testing.assert_array_equal(a.sample(7).v, later.v)
    assert not np.array_equal(Sampler(4).sample(2).x, first.x)


def test_equilibrium_samples_start_at_rest_in_the_static_equilibrium_of_their_loads():
    sampler = Sampler(0, SamplerConfig(equilibrium_probability=1.0, equilibrium_spread=0.0,
                                       **QUIET))
    for i in range(4):
        s = sampler.sample(i)
        free = ~s.scene.fixed_mask
        load = np.abs(s.scene.external_force[free]).max()
        residual = np.abs(af.gradient(s.scene, s.x)[free]).max()
        assert residual < 1e-6 * load, (i, residual, load)
        assert np.abs(s.x - s.scene.mesh.vertices).max() > 1e-5   # deflected, not the rest mesh
        np.testing.assert_array_equal(s.v, 0.0)


def test_equilibrium_spread_scales_the_load_of_the_equilibrium():
    def residual(spread):
        s = Sampler(1, SamplerConfig(equilibrium_probability=1.0, equilibrium_spread=spread,
                                     **QUIET)).sample(5)
        return np.abs(af.gradient(s.scene, s.x)[~s.scene.fixed_mask]).max()
    # the same draws but a load factor in [0.5, 1.5]: out of balance with the scene's own load
    assert residual(0.0) < 1e-6 * residual(0.5)
