"""Issue 28: compare's rules raise no false alarm on a correct tracer, and keep their power.

Each case is a pair of small synthetic images built like the false alarm seen on
real scenes (docs/verdicts.md, "Calibration"): the rules before the calibration
failed it, the rules now pass it, and a planted error of the kind the rule is for
still fails. The rules' derivations are in docs/verdicts.md.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from whitted.reference.verdicts.compare import (
    EXACT_LIMITS,
    block_metrics,
    image_metrics,
    judge,
    largest_bilinear_texture,
    median_limit,
    student_t_quantile,
    student_t_tail,
    z_test,
)


def _exact(t, r):
    return judge("exact-strata", image_metrics(t, r, with_flip=False), t, r)[0]


def _cornell_edge(h=128, w=128, flipped=35):
    """A wall (0.6) above a floor (0.2) meeting on a pixel row that runs through sample
    positions: on ``flipped`` pixels of that row the tracer puts one row of 4 of the 16
    samples on the other surface (0.4 / 4 = 0.1 apart)."""
    r = np.full((h, w, 3), 0.2, np.float32)
    r[: h // 2] = 0.6
    r[h // 2] = 0.4                     # the edge row: half wall, half floor
    t = r.copy()
    t[h // 2, 10:10 + flipped] += 0.1
    return t, r


def test_edge_ties_are_not_differences():
    t, r = _cornell_edge()
    old_value = image_metrics(t, r, with_flip=False).frac_over_01pct
    assert old_value > EXACT_LIMITS["frac_over_01pct"]      # the old rule's false alarm
    v = _exact(t, r)
    assert v.passed, v.checks
    assert v.checks["frac_over_01pct"]["edge_ties"] == 35


def test_the_same_difference_away_from_edges_fails():
    t, r = _cornell_edge()
    t2 = r.copy()
    t2[100, 10:45] += 0.1               # the floor, flat: no edge explains it
    assert not _exact(t2, r).passed


def test_edge_ties_beyond_one_line_across_the_image_fail():
    h = w = 64
    r = np.full((h, w, 3), 0.2, np.float32)
    r[::2] = 0.6                        # stripes: every pixel on an edge
    t = r + 0.05                        # a 10 % error everywhere, within each 3x3 range
    v = _exact(t.astype(np.float32), r)
    assert v.checks["frac_over_01pct"]["edge_ties"] > h + w - 1
    assert not v.checks["frac_over_01pct"]["pass"]


def test_image_mean_leaves_out_the_pixels_the_pixel_rule_allows():
    r = np.full((48, 48, 3), 0.5, np.float32)
    t = r.copy()
    t[3, 7] += 0.25
    t[40, 20] += 0.25                   # 2 of 2304 pixels (0.087 %): allowed by rule 2
    m = image_metrics(t, r, with_flip=False)
    assert m.frac_over_01pct < EXACT_LIMITS["frac_over_01pct"]
    assert m.mean_rel_diff > EXACT_LIMITS["mean_rel_diff"]  # the old rule's false alarm
    v = _exact(t, r)
    assert v.passed, v.checks


def test_image_mean_still_sees_a_small_bias_over_many_pixels():
    r = np.full((48, 48, 3), 0.5, np.float32)
    t = r.copy()
    t[: 15] *= 1 + 5e-4                 # 5e-4 over 30 % of the pixels: 1.5e-4 on the mean
    v = _exact(t.astype(np.float32), r)
    assert not v.checks["mean_rel_diff"]["pass"]


def test_student_t_tail_matches_tables():
    # t_15: P(|T| > 2.131) = 0.05, P(|T| > 2.947) = 0.01; t_63 near the normal
    assert abs(float(student_t_tail(np.array([2.131]), 15)[0]) - 0.05) < 2e-4
    assert abs(float(student_t_tail(np.array([2.947]), 15)[0]) - 0.01) < 1e-4
    assert abs(student_t_quantile(0.05, float("inf")) - 1.95996) < 1e-4
    assert 7.0 < student_t_quantile(3.27e-6, 15) < 7.3


def _skewed_pixels(bias_pixels=0, bias=0.0, seed=0):
    """Per pixel-channel estimates like the envmap scenes' at 16 spp: 0.4 % of them
    |z| = 5.5 off (the tracer's mean of 16 seeds missed a rare bright sample and its
    variance estimate with it), the rest normal; sigma 1 % of the value."""
    rng = np.random.default_rng(seed)
    r = np.full((48, 64, 3), 0.5)
    sd = 0.005
    var = np.full(r.shape, sd * sd / 5)        # the reference's: 1024 samples
    # the tracer's, 256 samples, four times the reference's (as measured)
    t = r + rng.normal(0, sd, r.shape)
    flat = t.reshape(-1)
    idx = rng.choice(flat.size, int(0.004 * flat.size), replace=False)
    flat[idx] = 0.5 - 5.5 * sd
    if bias_pixels:
        t[:bias_pixels // 64 or 1, :min(bias_pixels, 64)] *= 1 + bias
    return t, r, var, 4 * var


def test_pixel_rule_allows_skewed_tails_at_16_spp():
    t, r, var, tvar = _skewed_pixels()
    old = z_test(t, r, var, tvar)
    assert not old.passed                       # the old rule's false alarm
    new = z_test(t, r, var, tvar, ref_replicates=64, test_replicates=16)
    assert new.passed, new.fraction_passed


def test_pixel_rule_still_sees_local_errors():
    # +30 % on 1 % of the pixels (30 sigma): caught with the t-like correction too
    t, r, var, tvar = _skewed_pixels(bias_pixels=31, bias=0.3)
    new = z_test(t, r, var, tvar, ref_replicates=64, test_replicates=16)
    assert not new.passed


def test_block_median_judges_what_noise_cannot_explain():
    rng = np.random.default_rng(1)
    r = np.full((48, 64, 3), 0.02)
    sd = 0.004                                  # 20 % per pixel: 5 % per 4x4 block
    var = np.full(r.shape, sd * sd)
    t = r + rng.normal(0, sd, r.shape)
    old = block_metrics(t, r)                   # without the noise: the old median
    assert old["block_median_rel"] > 0.01       # the old rule's false alarm
    assert block_metrics(t, r, var)["block_median_rel"] < 0.01
    # a 30 % bias everywhere (well beyond the noise) still fails
    assert block_metrics(t * 1.3, r, var)["block_median_rel"] > 0.01


# --- exact-strata's median on scenes with a large bilinear bitmap (docs/verdicts.md,
# "The median"): mitsuba-data's test_spot_direct projects a 1920 x 1080 binary pattern.

SPOT = (Path(__file__).resolve().parents[2] / "data" / "real_scenes" / "mitsuba-data" /
        "tests" / "scenes" / "spot_light" / "test_spot_direct.xml")


def test_median_limit_grows_with_the_largest_bilinear_bitmap():
    from whitted.tracer.scene import load_any

    scene = load_any(SPOT)
    assert largest_bilinear_texture(scene) == 1920
    assert median_limit(scene) == pytest.approx(4 * 2.0 ** -24 * 1920)   # 4.6e-4
    assert median_limit(None) == EXACT_LIMITS["median_rel"]
    # nearest filtering moves no value by a fraction of a texel: the float32 limit
    (i, spot), = [(i, x) for i, x in enumerate(scene.lights) if hasattr(x, "texture")
                  and x.texture is not None]
    nearest = replace(spot, texture=replace(spot.texture, filter_type="nearest"))
    lights = list(scene.lights)
    lights[i] = nearest
    assert median_limit(replace(scene, lights=tuple(lights))) == EXACT_LIMITS["median_rel"]


def test_a_large_projected_pattern_passes_and_a_wrong_spot_uv_still_fails():
    """The tracer as written passes test_spot_direct (median 7.7e-5: above the float32
    limit of 1e-5 that failed it, below 4 u R); the spot's uv centred at 0 still fails."""
    from whitted.reference.verdicts.compare import compare_scene
    from whitted.tracer import faults
    from whitted.tracer.scene import load_any

    scene = load_any(SPOT).with_overrides(size=(64, 48), spp=16)
    result, _, _ = compare_scene(scene, second_opinion=False)
    median = result.checks["median_rel"]["value"]
    assert result.passed and EXACT_LIMITS["median_rel"] < median < median_limit(scene)
    from whitted.reference import mutants  # noqa: F401  (declares the catalog's ids)

    with faults.active("spot-uv-centred-at-zero"):
        bad, _, _ = compare_scene(scene, second_opinion=False)
    assert not bad.passed and bad.checks["median_rel"]["value"] > 100 * median_limit(scene)
