"""The verdicts' false-alarm rates and powers, measured on seeds.

Each rule of :mod:`reference.verdicts.compare` states how often it fails a correct
tracer (alpha) and what it sees (power). Here a correct tracer is judged
against the one-lobe reference on independent seeds (the reference's passes,
and the tracer's own seeds where it samples area lights), and known errors
are injected into its image:

* false alarms: every trial passes every rule (the rules' alphas, 1e-3 for the
  regions and far less for the per-pixel rule, make a failure in the
  ``SEEDS`` x 2 trials here a 1 % event), and the region statistic is
  standard normal: the mean of Z^2 over disjoint tiles of all trials lies in
  its chi-square interval (which a variance 1024 times too large, or the
  missed paths of zero-variance pixels left out of it, would leave);
* the zero-variance rule is what keeps the correct tracer from failing on the
  scene with a light inside glass (without it, the per-pixel rule fails);
* power: a 1 % bias over the glass (a region of random pixels) fails the
  region rule in every trial, as its stated detectable bias (< 1 %) predicts; a 30 % error on 1 %
  of the pixels fails the per-pixel rule; both powers vanish when the
  variance is inflated 1024 times, so these tests fail on such a toothless
  variance;
* the float-precision verdict: float32 rounding passes, a 5e-4 bias over 30 %
  of the pixels fails its mean check, a 2e-3 error on 0.3 % of them its
  0.1 % check.

The quick run uses small images (64 x 48, 80 x 60) and 4 seeds; ``-m slow``
repeats it with 24 seeds at 96 x 72 on four scenes.
"""

import math

import numpy as np
import pytest
from conftest import SCENES

from whitted.reference.verdicts.compare import (
    EXACT_LIMITS,
    REGION_ALPHA,
    image_metrics,
    judge,
    region_test,
    statistical_comparison,
    z_test,
)
from whitted.tracer import load_scene

SEEDS = 4
SLOW_SEEDS = 24
SIZE = (64, 48)


def _trials(name, seeds, size=SIZE, spp=64):
    scene = load_scene(SCENES / f"{name}.toml").with_overrides(size=size, spp=spp)
    return [statistical_comparison(scene, seed=1000 * (k + 1), tracer_seed=16 * (k + 1))
            for k in range(seeds)]


@pytest.fixture(scope="module")
def glass():
    """glass_sphere: the tracer deterministic, the reference picks lobes."""
    return _trials("glass_sphere", SEEDS)


@pytest.fixture(scope="module")
def lit_glass():
    """emitter_in_glass: a light inside glass, area lights sampled on both sides."""
    return _trials("emitter_in_glass", SEEDS, size=(80, 60))


def _tile_z(trials, noise_scale=1.0):
    zs = []
    for t in trials:
        rt = region_test(t.tracer_image, t.ref.image, t.noise.scaled(noise_scale))
        zs += [g["z"] for g in rt.regions if g["name"].startswith("tile")]
    return np.array(zs)


def _chi2_interval(n: int, z: float = 3.29) -> tuple[float, float]:
    """Where the mean of n squared standard normals lies, two-sided 1e-3 (Wilson-Hilferty)."""
    a = 2 / (9 * n)
    return (1 - a - z * math.sqrt(a)) ** 3, (1 - a + z * math.sqrt(a)) ** 3


def _false_alarms(trials):
    return {k: sum(not t.verdict.checks[k]["pass"] for t in trials)
            for k in trials[0].verdict.checks}


def test_a_correct_tracer_passes_every_rule_on_independent_seeds(glass, lit_glass):
    for trials in (glass, lit_glass):
        fails = _false_alarms(trials)
        assert not any(fails.values()), fails


def test_region_statistic_is_standard_normal_for_a_correct_tracer(glass, lit_glass):
    z = _tile_z(glass + lit_glass)
    lo, hi = _chi2_interval(len(z))
    assert len(z) >= 40
    assert lo < np.mean(z * z) < hi, (np.mean(z * z), lo, hi)
    assert abs(np.mean(z)) < 3.29 / math.sqrt(len(z))
    # A variance 1024 times too large makes every Z ~32 times too small: caught here.
    z_big = _tile_z(glass + lit_glass, 1024)
    assert not lo < np.mean(z_big * z_big) < hi


def test_zero_variance_rule_keeps_a_correct_tracer_from_failing(lit_glass):
    # Inside the glass some pixels are lit only through rare Fresnel paths that the
    # reference's 1024 samples never take: zero variance, and a correct tracer's
    # small value there fails the plain z-test. With the rule, those pixels pass.
    for t in lit_glass:
        nz = t.noise
        plain = z_test(t.tracer_image, t.ref.image, nz.ref_var, nz.tracer_var)
        ruled = z_test(t.tracer_image, t.ref.image, nz.ref_var, nz.tracer_var,
                       random_fraction=nz.random_fraction, samples=nz.samples)
        assert not plain.passed
        assert ruled.passed and ruled.zero_variance > 0
        assert ruled.zero_variance_passed == ruled.zero_variance


def _biased(trial, region: str, bias: float, noise_scale: float = 1.0) -> tuple[dict, float]:
    """(the verdict's checks, the region's detectable bias), ``bias`` added over ``region``."""
    mask = trial.noise.regions[region]
    img = trial.tracer_image.copy()
    img[mask] *= 1 + bias
    noise = trial.noise.scaled(noise_scale)
    verdict, _ = judge("z-test", image_metrics(img, trial.ref.image, with_flip=False), img,
                       trial.ref.image, noise)
    rt = region_test(img, trial.ref.image, noise)
    detectable = next(g["detectable_bias"] for g in rt.regions if g["name"] == region)
    return verdict.checks, detectable


# The glass: where the reference's noise, not float rounding, sets the limit (on
# surfaces that no random choice reaches, rule 1's float32 floor catches any bias).
REGION = "material glass"


def test_a_one_percent_bias_over_a_region_fails_the_verdict(glass, lit_glass):
    for t in glass + lit_glass:
        checks, detectable = _biased(t, REGION, 0.01)
        assert detectable < 0.01      # the stated power: >= 90 % for a 1 % bias
        assert not checks["region_max_z"]["pass"]
        assert checks["z_fraction_passed"]["pass"]   # too small for the per-pixel rule


def test_a_variance_1024_times_too_large_loses_that_power(glass, lit_glass):
    # The power check above fails for a toothless variance: the same 1 % bias passes.
    for t in glass + lit_glass:
        checks, detectable = _biased(t, REGION, 0.01, noise_scale=1024)
        assert detectable > 0.01 and all(c["pass"] for c in checks.values())


def _local_error(trial, noise_scale=1.0) -> bool:
    """Does the per-pixel rule (alone) catch +30 % on about 1 % of the pixels (glass)?"""
    glass = np.argwhere(trial.noise.regions["material glass"] &
                        (trial.ref.image.sum(-1) > 0.1 * trial.ref.image.sum(-1).mean()))
    pick = glass[:: max(1, len(glass) // (trial.tracer_image.size // 300))]
    img = trial.tracer_image.copy()
    img[pick[:, 0], pick[:, 1]] *= 1.3
    nz = trial.noise.scaled(noise_scale)
    z = z_test(img, trial.ref.image, nz.ref_var, nz.tracer_var,
               random_fraction=nz.random_fraction, samples=nz.samples)
    return not z.passed


def test_per_pixel_rule_sees_a_large_local_error_unless_its_variance_is_inflated(glass):
    for t in glass:
        assert _local_error(t)
        assert not _local_error(t, noise_scale=1024)


def test_float_precision_verdict_passes_rounding_and_fails_small_biases():
    # A deterministic pair of images: the tracer's render, and the same with float32
    # rounding noise (a few ulps per pixel), a 5e-4 bias over 30 % of the pixels, or a
    # 2e-3 error on 0.3 % of them.
    from whitted.tracer.integrator import Integrator

    scene = load_scene(SCENES / "three_lights.toml").with_overrides(size=(96, 64), spp=4)
    ref = Integrator(scene).render().image
    rng = np.random.default_rng(0)

    def verdict(img):
        return judge("exact-strata", image_metrics(img, ref, with_flip=False), img, ref)[0]

    ulps = (ref * (1 + rng.normal(0, 4 * 2.0 ** -24, ref.shape))).astype(np.float32)
    assert verdict(ulps).passed
    band = ulps.copy()
    rows = slice(int(0.7 * ref.shape[0]), None)      # the lowest 30 % of the rows: the floor
    band[rows] *= 1 + 5e-4
    assert ref[rows].sum() > 0.25 * ref.sum()         # the mean moves by > 1.25e-4
    v = verdict(band)
    assert not v.passed and not v.checks["mean_rel_diff"]["pass"]
    assert v.checks["median_rel"]["pass"] and v.checks["frac_over_01pct"]["pass"]
    spots = ulps.copy()
    lit = np.argwhere(ref.sum(-1) > 0.5 * ref.sum(-1).mean())
    pick = lit[rng.choice(len(lit), int(0.003 * ref.shape[0] * ref.shape[1]), replace=False)]
    spots[pick[:, 0], pick[:, 1]] *= 1 + 2e-3
    v = verdict(spots)
    assert not v.passed and not v.checks["frac_over_01pct"]["pass"]
    assert EXACT_LIMITS["frac_over_01pct"] == 1e-3


@pytest.mark.slow
@pytest.mark.parametrize("name", ["glass_sphere", "emitter_in_glass", "area_lights",
                                  "whitted_mix"])
def test_false_alarms_and_power_on_many_seeds(name):
    # The long version: SLOW_SEEDS trials at 96 x 72. Every trial passes; the tiles' Z
    # are standard normal; a 1 % bias over the whole image is caught in every trial.
    trials = _trials(name, SLOW_SEEDS, size=(96, 72))
    fails = _false_alarms(trials)
    # At alpha 1e-3 per trial, 2 or more failures in 24 trials has probability 3e-4.
    assert sum(fails.values()) <= 1, fails
    z = _tile_z(trials)
    lo, hi = _chi2_interval(len(z))
    assert lo < np.mean(z * z) < hi, (np.mean(z * z), lo, hi)
    for t in trials:
        assert not _biased(t, "image", 0.01)[0]["region_max_z"]["pass"]
    assert REGION_ALPHA == 1e-3


def test_block_rule_counts_correlated_channels_at_their_true_noise():
    # One path carries all three channels: for grey noise, the channel sum's standard
    # deviation is 3 sigma, not sqrt(3) sigma. Blocks of pure noise must then exceed 3
    # standard deviations as rarely as a normal does (0.27 %), not 8 % of the time.
    from whitted.reference.verdicts.compare import BLOCK_SIGMAS, block_metrics

    rng = np.random.default_rng(3)
    h, w, sigma = 256, 256, 0.004
    ref = np.full((h, w, 3), 0.01, dtype=np.float32)
    noise = rng.normal(0, sigma, (h, w, 1)).repeat(3, axis=-1)
    test = (ref + noise).astype(np.float32)
    var = np.full((h, w, 3), sigma ** 2)
    frac = block_metrics(test, ref, var)["block_frac_over_5pct"]
    assert BLOCK_SIGMAS == 3.0
    assert frac < 0.01, frac
