"""The harness's Whitted integrator on Mitsuba, and why it draws its own random numbers."""

import numpy as np
from conftest import SCENES

from reference.render import render_reference
from tracer import load_scene


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
