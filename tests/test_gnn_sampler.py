"""The training sampler: reproducible samples, and the optional at-rest (static equilibrium)
starting states."""
import numpy as np
import pytest

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



def _stiffness_per_mass(scene, x, dx):
    """dx^T K dx / dx^T M dx in 1/s^2, K the static Hessian at x: how stiff a perturbation is."""
    k = af.hessian(scene, x) @ dx.ravel()
    return float(dx.ravel() @ k / np.sum(scene.masses[:, None] * dx ** 2))


def test_noise_modes_perturb_the_soft_modes_only_at_the_configured_size():
    rest = dict(equilibrium_probability=1.0, equilibrium_spread=0.0)
    clean = Sampler(2, SamplerConfig(**rest, **QUIET))
    white = Sampler(2, SamplerConfig(**rest))
    soft = Sampler(2, SamplerConfig(**rest, noise_modes=8))
    h = 0.01  # training meshes: about 1 cm edges, so the noise is at most about 1e-5 m
    for i in range(3):
        c, w, s = clean.sample(i), white.sample(i), soft.sample(i)
        for sample in (w, s):
            np.testing.assert_array_equal(sample.x[c.scene.fixed_mask], c.x[c.scene.fixed_mask])
        dx, dv = s.x - c.x, s.v - c.v
        assert 0 < np.sqrt(np.mean(dx[~c.scene.fixed_mask] ** 2)) < 2e-3 * h
        assert 0 < np.sqrt(np.mean(dv[~c.scene.fixed_mask] ** 2)) < 1e-1 * h
        # white noise lies mostly in the stiff volumetric modes; the soft-mode noise, in both
        # position and velocity, is at least 100 times less stiff per unit mass
        stiff = _stiffness_per_mass(c.scene, c.x, w.x - c.x)
        assert _stiffness_per_mass(c.scene, c.x, dx) < stiff / 100, i
        assert _stiffness_per_mass(c.scene, c.x, dv) < stiff / 100, i


def test_noise_options_are_validated():
    with pytest.raises(ValueError, match="noise_modes"):
        SamplerConfig(noise_modes=-1)
    with pytest.raises(ValueError, match="noise_modes"):
        SamplerConfig(noise_modes=2.5)
    with pytest.raises(ValueError, match="noise_decades"):
        SamplerConfig(noise_decades=-1.0)
    with pytest.raises(ValueError, match="white_noise_probability"):
        SamplerConfig(white_noise_probability=0.5)
    with pytest.raises(ValueError, match="white_noise_probability"):
        SamplerConfig(noise_modes=8, white_noise_probability=1.5)


def test_white_noise_probability_mixes_white_and_soft_mode_noise():
    """With noise_modes = 8 and white_noise_probability = 0.5, each sample's noise is either
    about as stiff per unit mass as white noise on the same scene or 100 times less stiff,
    and both kinds occur."""
    rest = dict(equilibrium_probability=1.0, equilibrium_spread=0.0, noise_velocity=0.0)
    clean = Sampler(4, SamplerConfig(**rest, noise_position=0.0))
    white = Sampler(4, SamplerConfig(**rest))
    mixed = Sampler(4, SamplerConfig(**rest, noise_modes=8, white_noise_probability=0.5))
    ratios = []
    for i in range(12):
        c, w, s = clean.sample(i), white.sample(i), mixed.sample(i)
        ratios.append(_stiffness_per_mass(c.scene, c.x, s.x - c.x)
                      / _stiffness_per_mass(c.scene, c.x, w.x - c.x))
    ratios = np.array(ratios)
    is_white = ratios > 0.3
    assert np.all(is_white | (ratios < 1e-2)), ratios
    assert 2 <= is_white.sum() <= 10, ratios


def test_noise_decades_draw_the_noise_size_log_uniformly():
    def relative_sizes(**options):
        """Position noise rms over its largest allowed value, noise_position h, per sample."""
        config = SamplerConfig(equilibrium_probability=1.0, noise_velocity=0.0, **options)
        noisy, clean = Sampler(5, config), Sampler(5, SamplerConfig(
            equilibrium_probability=1.0, **QUIET))
        sizes = []
        for i in range(30):
            s, c = noisy.sample(i), clean.sample(i)
            mesh = c.scene.mesh
            h = np.mean(np.linalg.norm(np.diff(mesh.vertices[mesh.edges], axis=1), axis=2))
            dx = (s.x - c.x)[~c.scene.fixed_mask]
            sizes.append(np.sqrt(np.mean(dx ** 2)) / (config.noise_position * h))
        return np.array(sizes)
    uniform, logs = relative_sizes(), relative_sizes(noise_decades=3.0)
    assert logs.max() < 1.3 and logs.min() > 1e-3 / 1.3
    assert np.median(uniform) > 0.3 and np.median(logs) < 0.1
    assert (logs < 1e-2).sum() >= 5   # a third of them expected below a hundredth


def test_axis_fibers_lie_along_the_coordinate_axes():
    """axis_fiber_probability = 1: every scene-wide fiber is x, y or z (each seen); the
    element-varying kinds stay random."""
    config = SamplerConfig(axis_fiber_probability=1.0, deformed_probability=0.0, **QUIET)
    sampler = Sampler(5, config)
    axes, varying = set(), 0
    for i in range(40):
        d = sampler.sample(i).scene.elements.fiber
        if np.allclose(d, d[0]):
            assert np.sort(np.abs(d[0])).tolist() == [0.0, 0.0, 1.0], i
            axes.add(int(np.argmax(np.abs(d[0]))))
        else:
            varying += 1
    assert axes == {0, 1, 2} and 5 <= varying <= 35
    with pytest.raises(ValueError, match="axis_fiber_probability"):
        SamplerConfig(axis_fiber_probability=1.5)
