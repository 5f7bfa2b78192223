"""The harness's Whitted integrator on Mitsuba, and why it draws its own random numbers."""

import numpy as np
from conftest import SCENES

from whitted.reference.renderers.mitsuba.render import render_reference
from whitted.tracer import load_scene


def test_centred_strata_quantise_one_dimensional_choices(mi):
    # Mitsuba's stratified sampler with jitter = false gives the 64 samples of a pixel
    # the 1D values (p + 1/2) / 64 in every dimension. A lobe of probability
    # R = 0.0083 is then taken by exactly one sample in 64 (1.56 %), not by 0.83 % on
    # average, in every pass and with every seed: the bias the reference integrator
    # avoids by drawing lobe choices from its own stream.
    for seed in (0, 1, 2):
        sampler = mi.load_dict({"type": "stratified", "sample_count": 64, "jitter": False})
        sampler.set_samples_per_wavefront(64)  # as Mitsuba's render loop does: one pixel
        sampler.seed(seed, 64)
        u = np.sort(np.asarray(sampler.next_1d()))
        assert np.allclose(u, (np.arange(64) + 0.5) / 64)
        assert np.mean(u < 0.0083) == 1 / 64


def test_reference_passes_with_different_seeds_are_independent():
    scene = load_scene(SCENES / "glass_sphere.toml").with_overrides(size=(40, 30), spp=16)
    a = render_reference(scene, seed=0).image
    b = render_reference(scene, seed=1).image
    c = render_reference(scene, seed=0).image
    assert np.array_equal(a, c)          # a seed reproduces its image
    assert not np.array_equal(a, b)      # another seed draws other lobes
    # Outside the glass nothing is random: the same pixels there, up to the order in
    # which the film sums the samples (float32 rounding, ~1e-7 relative).
    same = np.isclose(a, b, rtol=1e-5, atol=1e-7).all(axis=-1)
    assert same.mean() > 0.5


def test_reference_moments_give_the_variance_of_the_pixel_mean():
    scene = load_scene(SCENES / "glass_sphere.toml").with_overrides(size=(40, 30), spp=16)
    r = render_reference(scene, moments=True, passes=2)
    assert r.variance.shape == r.image.shape and (r.variance >= 0).all()
    assert r.variance.max() > 0 and r.passes == 2


def test_random_aov_marks_the_pixels_where_the_reference_draws_lobes():
    # Through the glass a sample's lobe is drawn at random; on the floor and the panels,
    # lit by a point and a directional light, nothing is.
    from whitted.tracer.integrator import material_ids

    scene = load_scene(SCENES / "glass_sphere.toml").with_overrides(size=(40, 30), spp=16)
    r = render_reference(scene, moments=True, passes=2)
    ids = material_ids(scene)
    glass = ids == list(scene.materials).index("glass")
    assert r.random_fraction.shape == ids.shape
    assert np.all(r.random_fraction[glass] > 0)
    far = ~glass
    far[1:] &= ~glass[:-1]
    far[:-1] &= ~glass[1:]
    far[:, 1:] &= ~glass[:, :-1]
    far[:, :-1] &= ~glass[:, 1:]  # pixels whose neighbours show no glass either
    assert np.all(r.random_fraction[far & (ids >= 0)] == 0)


def test_pass_variance_is_the_spread_of_independent_passes():
    # Var(pooled mean) = s^2 / P from P passes; it does not count the variation of
    # radiance across a pixel's strata, which the per-sample moment does.
    scene = load_scene(SCENES / "glass_sphere.toml").with_overrides(size=(40, 30), spp=16)
    r = render_reference(scene, moments=True, passes=4)
    passes = [render_reference(scene, seed=k).image.sum(-1).astype(np.float64)
              for k in range(4)]
    expected = np.var(passes, axis=0, ddof=1) / 4
    assert np.allclose(r.pass_variance, expected, rtol=1e-3, atol=1e-12)
    moment = np.sqrt(r.variance.astype(np.float64)).sum(-1) ** 2
    assert np.median(moment[r.pass_variance > 0] / r.pass_variance[r.pass_variance > 0]) > 1
