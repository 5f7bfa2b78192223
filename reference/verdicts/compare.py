"""Compare the tracer's image with Mitsuba's: metrics, verdicts, a heat map.

:func:`compare_scene` renders a scene with the tracer and with one of three
Mitsuba references (``reference``): ``deterministic`` (the default; Mitsuba's
plugins along the whole Whitted ray tree, nothing random), ``onelobe`` (the
``whitted`` integrator: one lobe and light sample per sample, from its own
stream) or ``direct`` (Mitsuba's stock integrator). :func:`judge` then gives
the verdict of one of three tests (:func:`choose_test`):

* ``exact-strata``: float precision (median, pixels beyond 1e-3 with edge ties
  counted apart, the image mean over the pixels within 1e-3);
* ``tessellated``: looser limits (median, pixels beyond 5 %, the mean over all
  pixels), for a paraboloid that Mitsuba sees as a mesh;
* ``z-test``: the statistical verdict for a reference that samples, rules 1
  (each pixel-channel, Student's t), 2 (zero variance), 3 (4 x 4 blocks) and 4
  (signed sums over regions);

and, on scenes whose lights the tracer samples, a second opinion by the z-test
against the one-lobe reference.

Every rule, its limits, their derivation, its false-alarm rate and power, and
the figures measured on it are in docs/verdicts.md, one section a test: "The
references", "Which test judges a scene", "exact-strata" ("The median",
"Pixels beyond 1e-3, edge ties apart", "The image mean"), "tessellated",
"z-test" ("What the two sides give", "Rule 1" to "Rule 4", "Measured on the
built-in scenes"), "The second opinion", and "Calibration on real scenes:
false alarms" (benchmarks/false_alarms.py). The docstrings below state each
rule in a line and name its section.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field
from pathlib import Path
from statistics import NormalDist

import numpy as np

#: Relative floor on the compared values' standard deviation (float32 agreement).
FLOAT_SIGMA = 1e-4

#: exact-strata's limits (docs/verdicts.md, "exact-strata").
EXACT_LIMITS = {"median_rel": 1e-5, "frac_over_01pct": 1e-3, "mean_rel_diff": 1e-4}
#: Unit roundoff of float32 (2^-24), and the roundings between a ray's direction and the
#: texture coordinate it gives (a direction within ~1 u per component, then a division, a
#: product and a sum): :func:`median_limit`.
FLOAT32_U = 2.0 ** -24
TEXTURE_ROUNDINGS = 4
#: tessellated's limits, for a paraboloid Mitsuba sees as a mesh with chords within 1e-4
#: (docs/verdicts.md, "tessellated").
TESSELLATED_LIMITS = {"median_rel": 1e-3, "frac_over_5pct": 0.02, "mean_rel_diff": 5e-3}
ZTEST_ALPHA = 0.01
ZTEST_PASS_FRACTION = 0.9975
BLOCK = 4
BLOCK_LIMITS = {"block_median_rel": 0.01, "block_frac_over_5pct": 0.02}
#: Family-wise false-alarm rate of the region test, per scene.
REGION_ALPHA = 1e-3
#: Regions with fewer random pixels than this are not tested on their own.
REGION_MIN_PIXELS = 16
#: Tiles per image side for the region test.
REGION_TILES = 4
#: z quantile of 90 % power on top of the critical value (one-sided).
POWER_Z = NormalDist().inv_cdf(0.9)

REFERENCES = ("deterministic", "onelobe", "direct")
#: Names of the Mitsuba integrator a reference uses (``--integrator`` named these).
INTEGRATOR_OF = {"deterministic": "deterministic", "onelobe": "whitted", "direct": "direct"}


def reference_name(name: str) -> str:
    """A reference's name; the integrator name ``whitted`` means ``onelobe``."""
    name = {"whitted": "onelobe"}.get(name, name)
    if name not in REFERENCES:
        raise ValueError(f"unknown reference {name!r} (expected one of {', '.join(REFERENCES)})")
    return name


def pixel_relative_difference(test: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """Per-pixel relative difference sum_c |t - r| / max(sum_c |r|, floor).

    The floor, 1e-3 of the mean of sum_c |r| over the image, keeps nearly black
    pixels from dividing by zero; where both images are black the difference is 0.
    """
    num = np.abs(test.astype(np.float64) - ref).sum(-1)
    den = np.abs(ref.astype(np.float64)).sum(-1)
    floor = 1e-3 * max(float(den.mean()), 1e-30)
    return num / np.maximum(den, floor)


def block_pixels(image: np.ndarray, k: int = BLOCK) -> int:
    """Pixels in one block of :func:`block_mean`: k x k, or the whole image when it is
    narrower or lower than one block."""
    h, w = image.shape[:2]
    return h * w if h < k or w < k else k * k


def block_mean(image: np.ndarray, k: int = BLOCK) -> np.ndarray:
    """Mean over k x k pixel blocks (the image cropped to a multiple of k); an image
    smaller than one block in either direction is one block."""
    if image.shape[0] < k or image.shape[1] < k:
        return image.astype(np.float64).reshape(1, 1, -1, image.shape[-1]).mean(axis=2)
    h, w = (image.shape[0] // k) * k, (image.shape[1] // k) * k
    a = image[:h, :w].astype(np.float64)
    return a.reshape(h // k, k, w // k, k, -1).mean(axis=(1, 3))


def flip_error(test: np.ndarray, ref: np.ndarray) -> float | None:
    """Mean HDR-FLIP error (Andersson et al., "FLIP", 2020/2021) or None if unavailable."""
    try:
        import flip_evaluator as flip
    except ImportError:
        return None
    t = np.ascontiguousarray(np.maximum(np.nan_to_num(test), 0), dtype=np.float32)
    r = np.ascontiguousarray(np.maximum(np.nan_to_num(ref), 0), dtype=np.float32)
    if not np.any(r) and not np.any(t):
        return 0.0
    _, mean, _ = flip.evaluate(r, t, "HDR", applyMagma=False)
    return float(mean)


@dataclass
class Metrics:
    rmse: float
    mean_rel: float
    median_rel: float
    max_rel: float
    frac_over_5pct: float
    mean_tracer: float
    mean_mitsuba: float
    mean_rel_diff: float
    flip: float | None = None
    #: 99.9th percentile of the per-pixel relative difference
    p999_rel: float = 0.0
    #: fraction of pixels whose relative difference exceeds 1e-3
    frac_over_01pct: float = 0.0


def image_metrics(test: np.ndarray, ref: np.ndarray, with_flip: bool = True) -> Metrics:
    rel = pixel_relative_difference(test, ref)
    mt, mr = float(test.mean()), float(ref.mean())
    return Metrics(
        rmse=float(np.sqrt(np.mean((test.astype(np.float64) - ref) ** 2))),
        mean_rel=float(rel.mean()), median_rel=float(np.median(rel)), max_rel=float(rel.max()),
        frac_over_5pct=float((rel > 0.05).mean()), mean_tracer=mt, mean_mitsuba=mr,
        mean_rel_diff=abs(mt - mr) / mr if mr != 0 else (0.0 if mt == 0 else math.inf),
        flip=flip_error(test, ref) if with_flip else None,
        p999_rel=float(np.quantile(rel, 0.999)), frac_over_01pct=float((rel > 1e-3).mean()))


# ---------------------------------------------------------------- the statistical verdict


@dataclass
class Noise:
    """What the statistical verdict knows about the randomness of the two images.

    ``ref_var`` and ``tracer_var`` (H x W x 3) come from per-sample second
    moments: upper bounds for stratified means (rule 1). ``ref_pass_var`` and
    ``tracer_pass_var`` (H x W) are unbiased variances of the channel sum from
    the spread of independent passes or seeds (rule 4). ``random_fraction``
    (H x W) is the fraction of the reference's samples that drew a random
    number that could change them; ``samples`` the reference's samples per
    pixel. ``regions`` maps a name to an H x W mask.
    """
    ref_var: np.ndarray
    samples: int
    ref_pass_var: np.ndarray | None = None
    random_fraction: np.ndarray | None = None
    tracer_var: np.ndarray | None = None
    tracer_pass_var: np.ndarray | None = None
    regions: dict[str, np.ndarray] | None = None
    #: independent replicates behind each side's mean: the reference's passes and the
    #: tracer's seeds (None: unknown, the normal limit; rule 1's degrees of freedom)
    ref_passes: int | None = None
    tracer_seeds: int | None = None

    def scaled(self, k: float) -> Noise:
        """The same noise with every variance multiplied by k (a power check's foil)."""
        def mul(a):
            return None if a is None else a * k
        return Noise(self.ref_var * k, self.samples, mul(self.ref_pass_var),
                     self.random_fraction, mul(self.tracer_var), mul(self.tracer_pass_var),
                     self.regions, getattr(self, "ref_passes", None),
                     getattr(self, "tracer_seeds", None))


@dataclass
class ZTest:
    alpha_pixel: float
    fraction_passed: float
    min_p: float
    passed: bool
    p_values: np.ndarray = field(repr=False, default=None)
    #: pixel-channels judged by the zero-variance rule, and how many of them passed
    zero_variance: int = 0
    zero_variance_passed: int = 0


def sidak(alpha: float, tests: int) -> float:
    """The per-test level that keeps the family-wise false-alarm rate at ``alpha``."""
    return 1 - (1 - alpha) ** (1 / max(tests, 1))


def zero_variance_bound(ref: np.ndarray, random_fraction: np.ndarray, samples: int,
                        alpha_pixel: float) -> np.ndarray:
    """H x W x 3: how far a correct pixel may lie from a reference with zero variance (rule 2).

    q B, q = -ln(alpha_pixel) / N_random and B the channel's brightest reference
    value; 0 where the reference made no random choice (docs/verdicts.md,
    "Rule 2: zero variance").
    """
    n = np.asarray(random_fraction, dtype=np.float64) * samples
    with np.errstate(divide="ignore"):
        q = np.where(n > 0, np.minimum(1.0, -math.log(alpha_pixel) / np.maximum(n, 1e-300)),
                     0.0)
    b = np.abs(ref.astype(np.float64)).reshape(-1, ref.shape[-1]).max(axis=0)
    return q[..., None] * b


def _betainc(a: np.ndarray, b: float, x: np.ndarray) -> np.ndarray:
    """Regularised incomplete beta I_x(a, b), elementwise (Lentz's continued fraction,
    Numerical Recipes 6.4), for :func:`student_t_tail`."""
    a = np.asarray(a, dtype=np.float64)
    x = np.clip(np.asarray(x, dtype=np.float64), 0.0, 1.0)
    lbeta = (np.vectorize(math.lgamma)(a) + math.lgamma(b) - np.vectorize(math.lgamma)(a + b))
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        front = np.exp(a * np.log(np.maximum(x, 1e-300)) + b * np.log1p(-np.minimum(x, 1 - 1e-16))
                       - lbeta) / a
        tiny = 1e-300
        f = np.ones_like(x)
        c = np.ones_like(x)
        d = 1.0 - (a + b) * x / (a + 1.0)
        d = 1.0 / np.where(np.abs(d) < tiny, tiny, d)
        f = d.copy()
        for m in range(1, 300):
            for num in (m * (b - m) * x / ((a + 2 * m - 1) * (a + 2 * m)),
                        -(a + m) * (a + b + m) * x / ((a + 2 * m) * (a + 2 * m + 1))):
                d = 1.0 + num * d
                d = 1.0 / np.where(np.abs(d) < tiny, tiny, d)
                c = 1.0 + num / np.where(np.abs(c) < tiny, tiny, c)
                f = f * c * d
            if np.all(np.abs(c * d - 1.0) < 1e-12):
                break
        return np.where(x <= 0, 0.0, np.where(x >= 1, 1.0, front * f))


def student_t_tail(z: np.ndarray, dof) -> np.ndarray:
    """Two-sided tail P(|T| >= z) of Student's t with ``dof`` degrees of freedom
    (elementwise; an infinite dof is the normal's erfc(z / sqrt 2))."""
    z = np.abs(np.asarray(z, dtype=np.float64))
    dof = np.broadcast_to(np.asarray(dof, dtype=np.float64), z.shape)
    normal = np.vectorize(math.erfc, otypes=[np.float64])(z / math.sqrt(2))
    finite = np.isfinite(dof)
    if not finite.any():
        return normal
    nu = np.where(finite, dof, 1.0)
    # P(|T| >= z) = I_{nu / (nu + z^2)}(nu / 2, 1 / 2); the continued fraction converges
    # fast for x < (a + 1) / (a + b + 2), else use the symmetry I_x(a, b) = 1 - I_{1-x}(b, a)
    x = nu / (nu + z * z)
    return np.where(finite, _betainc(nu / 2, 0.5, x), normal)


def student_t_quantile(p: float, dof: float) -> float:
    """z with P(|T| >= z) = p for Student's t with ``dof`` degrees of freedom (bisection)."""
    if not math.isfinite(dof):
        return NormalDist().inv_cdf(1 - p / 2)
    lo, hi = 0.0, 1e4
    for _ in range(200):
        mid = (lo + hi) / 2
        lo, hi = (mid, hi) if float(student_t_tail(np.array([mid]), dof)[0]) > p else (lo, mid)
    return hi


def welch_dof(ref_var: np.ndarray, ref_replicates: int | None, test_var, test_replicates):
    """Rule 1's degrees of freedom per pixel-channel (Welch-Satterthwaite).

    nu = (V_r + V_t)^2 / (V_r^2 / nu_r + V_t^2 / nu_t), nu_side = replicates - 1
    (passes, seeds), a side with unknown replicates infinite (docs/verdicts.md,
    "Rule 1: each pixel-channel").
    """
    vr = np.asarray(ref_var, dtype=np.float64)
    vt = np.zeros_like(vr) if test_var is None else np.asarray(test_var, dtype=np.float64)
    nu_r = math.inf if not ref_replicates or ref_replicates < 2 else ref_replicates - 1
    nu_t = math.inf if not test_replicates or test_replicates < 2 else test_replicates - 1
    den = vr ** 2 / nu_r + vt ** 2 / nu_t
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(den > 0, (vr + vt) ** 2 / np.where(den > 0, den, 1.0), np.inf)


def z_test(test: np.ndarray, ref: np.ndarray, ref_var: np.ndarray,
           test_var: np.ndarray | None = None, alpha: float = ZTEST_ALPHA,
           pass_fraction: float = ZTEST_PASS_FRACTION,
           random_fraction: np.ndarray | None = None, samples: int | None = None,
           ref_replicates: int | None = None, test_replicates: int | None = None) -> ZTest:
    """Per-pixel, per-channel two-sided test with the Sidak correction (rules 1 and 2).

    With ``random_fraction`` and ``samples`` (the reference's samples per pixel),
    pixel-channels where the reference made random choices but estimated zero
    variance are judged by the zero-variance rule instead. With
    ``ref_replicates`` / ``test_replicates`` (passes, seeds) the statistic is
    referred to Student's t with Welch's degrees of freedom (:func:`welch_dof`);
    without them, to the normal. docs/verdicts.md, "Rule 1: each pixel-channel"
    and "Rule 2: zero variance".
    """
    t = test.astype(np.float64)
    r = ref.astype(np.float64)
    floor = (FLOAT_SIGMA * np.maximum(np.abs(r), np.abs(t))) ** 2
    tvar = 0 if test_var is None else test_var.astype(np.float64)
    var = np.maximum(ref_var.astype(np.float64) + tvar + floor, 1e-300)
    z = np.abs(t - r) / np.sqrt(var)
    if ref_replicates or test_replicates:
        dof = welch_dof(ref_var, ref_replicates, test_var, test_replicates)
        p = student_t_tail(z, dof)
    else:
        p = np.vectorize(math.erfc, otypes=[np.float64])(z / math.sqrt(2))
    pixels = test.shape[0] * test.shape[1]
    alpha_pixel = sidak(alpha, pixels)
    zero = zero_ok = 0
    if random_fraction is not None and samples:
        bound = zero_variance_bound(r, random_fraction, samples, alpha_pixel)
        rule = np.isfinite(bound) & (bound > 0) & \
            (ref_var.astype(np.float64) <= (FLOAT_SIGMA * np.abs(r)) ** 2)
        nu_t = (test_replicates - 1 if test_replicates and test_replicates > 1 else math.inf)
        z_crit = student_t_quantile(alpha_pixel, nu_t)
        ok = np.abs(t - r) <= bound + z_crit * np.sqrt(tvar + floor)
        p = np.where(rule, np.where(ok, 1.0, 0.0), p)
        zero, zero_ok = int(rule.sum()), int((rule & ok).sum())
    frac = float((p > alpha_pixel).mean())
    return ZTest(alpha_pixel, frac, float(p.min()), frac >= pass_fraction, p, zero, zero_ok)


def _channel_sum_variance(per_channel: np.ndarray | None) -> np.ndarray | None:
    """Var(R + G + B) <= (sd_R + sd_G + sd_B)^2 (Cauchy-Schwarz), from per-channel variances."""
    if per_channel is None:
        return None
    return np.sqrt(np.maximum(per_channel.astype(np.float64), 0)).sum(-1) ** 2


#: A block "differs" only when its difference is also this many standard deviations of
#: the two estimates' noise (rule 3, block_metrics).
BLOCK_SIGMAS = 3.0


def block_metrics(test: np.ndarray, ref: np.ndarray, var: np.ndarray | None = None) -> dict:
    """Rule 3: median relative difference of 4x4 blocks, and the fraction beyond 5 %.

    With ``var`` (the per-pixel, per-channel variance of test - ref) both look
    only at what exceeds BLOCK_SIGMAS standard deviations of the block's noise
    (docs/verdicts.md, "Rule 3: 4 x 4 blocks").
    """
    bt, br = block_mean(test), block_mean(ref)
    rel = pixel_relative_difference(bt, br)
    beyond = rel > 0.05
    median_rel = rel
    if var is not None:
        v = _channel_sum_variance(var)[..., None]
        sigma_block = np.sqrt(block_mean(v)[..., 0] / block_pixels(v))  # Var of a mean
        diff = np.abs(bt.astype(np.float64) - br).sum(-1)
        beyond &= diff > BLOCK_SIGMAS * sigma_block
        # the median takes the relative difference beyond BLOCK_SIGMAS of the noise, so
        # that dim blocks' noise is not measured as a difference (issue 28)
        excess = np.maximum(diff - BLOCK_SIGMAS * sigma_block, 0.0)
        median_rel = np.where(diff > 0, rel * excess / np.where(diff > 0, diff, 1.0), 0.0)
    return {"block_median_rel": float(np.median(median_rel)),
            "block_frac_over_5pct": float(beyond.mean())}


def regions_of(material_ids: np.ndarray, material_names: list[str],
               tiles: int = REGION_TILES) -> dict[str, np.ndarray]:
    """The regions of rule 4: the whole image, each material seen, tiles x tiles tiles.

    ``material_ids`` is :func:`tracer.integrator.material_ids`'s buffer: a
    material's index, ``len(material_names)`` for an emitter without one, -1
    for the background.
    """
    h, w = material_ids.shape
    out = {"image": np.ones((h, w), dtype=bool)}
    for m in np.unique(material_ids):
        if m < 0:
            name = "background"
        elif m < len(material_names):
            name = f"material {material_names[m]}"
        else:
            name = "emitters"
        out[name] = material_ids == m
    ys = np.linspace(0, h, tiles + 1).round().astype(int)
    xs = np.linspace(0, w, tiles + 1).round().astype(int)
    for i in range(tiles):
        for j in range(tiles):
            mask = np.zeros((h, w), dtype=bool)
            mask[ys[i]:ys[i + 1], xs[j]:xs[j + 1]] = True
            out[f"tile {i},{j}"] = mask
    return out


@dataclass
class RegionTest:
    alpha_region: float
    z_crit: float
    max_abs_z: float
    passed: bool
    #: per tested region: name, random pixels, Z, smallest relative bias seen with 90 % power
    regions: list[dict]


def region_test(test: np.ndarray, ref: np.ndarray, noise: Noise,
                alpha: float = REGION_ALPHA) -> RegionTest:
    """Rule 4: signed sums of the differences over regions against their noise, every |Z|
    below the Sidak level of ``alpha`` (docs/verdicts.md, "Rule 4: regions")."""
    d = (test.astype(np.float64) - ref).sum(-1)
    v_ref = noise.ref_pass_var
    if v_ref is None:
        v_ref = _channel_sum_variance(noise.ref_var)
    v_ref = np.asarray(v_ref, dtype=np.float64)
    v_tr = noise.tracer_pass_var
    if v_tr is None:
        v_tr = _channel_sum_variance(noise.tracer_var)
    v_tr = np.zeros_like(v_ref) if v_tr is None else np.asarray(v_tr, dtype=np.float64)
    # only pixels whose value varies beyond rule 1's float32 floor on either side; the
    # others are rules 1 and 2's (docs/verdicts.md, "Rule 4: regions")
    floor = (FLOAT_SIGMA * np.abs(ref.astype(np.float64)).sum(-1)) ** 2
    random = (v_ref > floor) | (v_tr > floor)
    var = v_ref + v_tr + floor
    tested = []
    for name, mask in (noise.regions or {"image": np.ones(d.shape, dtype=bool)}).items():
        m = mask & random
        n_g = int(m.sum())
        s = float(var[m].sum())
        if n_g < REGION_MIN_PIXELS or s <= 0:
            continue
        level = abs(float(ref[m].astype(np.float64).sum()))
        tested.append({"name": name, "pixels": n_g, "z": float(d[m].sum() / math.sqrt(s)),
                       "sigma": math.sqrt(s), "level": level})
    alpha_region = sidak(alpha, len(tested))
    z_crit = NormalDist().inv_cdf(1 - alpha_region / 2)
    for g in tested:
        g["detectable_bias"] = ((z_crit + POWER_Z) * g["sigma"] / g["level"]
                                if g["level"] > 0 else math.inf)
    worst = max((abs(g["z"]) for g in tested), default=0.0)
    return RegionTest(alpha_region, z_crit, worst, worst < z_crit, tested)


#: Smallest 3 x 3 contrast, relative to the pixel, that counts as an edge (exact_checks;
#: docs/verdicts.md, "Pixels beyond 1e-3, edge ties apart").
EDGE_CONTRAST = 0.1


def local_range(ref: np.ndarray) -> np.ndarray:
    """H x W: sum over channels of (max - min) of ``ref`` over each pixel's 3 x 3
    neighbourhood (clipped at the image's border)."""
    r = ref.astype(np.float64)
    p = np.pad(r, ((1, 1), (1, 1), (0, 0)), mode="edge")
    h, w = r.shape[:2]
    win = np.stack([p[i:i + h, j:j + w] for i in range(3) for j in range(3)])
    return (win.max(axis=0) - win.min(axis=0)).sum(-1)


def exact_checks(test: np.ndarray, ref: np.ndarray) -> dict:
    """exact-strata's pixel and mean checks, edge ties counted apart (issue 28).

    * ``frac_over_01pct``: the fraction of pixels beyond 1e-3 that are not edge
      ties (3 x 3 contrast R_p >= EDGE_CONTRAST of the pixel, difference <= R_p); when
      there are more than W + H - 1 ties, every pixel beyond 1e-3 counts.
    * ``mean_rel_diff``: |sum (t - r)| over the pixels within 1e-3, over sum |r| of
      the whole image.

    docs/verdicts.md, "Pixels beyond 1e-3, edge ties apart" and "The image mean".
    """
    rel = pixel_relative_difference(test, ref)
    beyond = rel > 1e-3
    d = np.abs(test.astype(np.float64) - ref).sum(-1)
    rng_ = local_range(ref)
    level = np.abs(ref.astype(np.float64)).sum(-1)
    # an edge is a discontinuity, and a tie moves the pixel by at most its contrast
    tie = beyond & (rng_ >= EDGE_CONTRAST * level) & (d <= rng_)
    h, w = rel.shape
    cap = w + h - 1
    n_tie = int(tie.sum())
    counted = beyond & ~tie if n_tie <= cap else beyond
    inside = ~beyond
    diff = (test.astype(np.float64) - ref)[inside].sum()
    total = float(np.abs(ref.astype(np.float64)).sum())
    mean = abs(float(diff)) / total if total > 0 else (0.0 if diff == 0 else math.inf)
    return {"frac_over_01pct": float(counted.mean()), "edge_ties": n_tie,
            "edge_tie_cap": cap, "mean_rel_diff": mean,
            "pixels_left_out": int(beyond.sum())}


@dataclass
class Verdict:
    test: str                       # "exact-strata", "tessellated" or "z-test"
    passed: bool
    checks: dict[str, dict]          # name -> {"value", "limit", "pass"}
    reason: str


def choose_test(scene, reference: str = "deterministic") -> str:
    """``exact-strata`` or ``tessellated`` where neither side samples, else ``z-test``.

    The deterministic reference never samples; the others do wherever the scene
    has mirrors, glass or area lights (docs/verdicts.md, "Which test judges a scene").
    """
    if reference_name(reference) != "deterministic" and (
            scene.has_specular() or scene.samples_lights()):
        return "z-test"
    return "tessellated" if scene.has_tessellated() else "exact-strata"


def largest_bilinear_texture(scene) -> int:
    """The largest side, in texels, of a bitmap the scene looks up with bilinear filtering
    (a material's or a spot's texture, an environment map); 0 without one."""
    import dataclasses

    seen, best = {}, 0

    def walk(x, depth=0):
        nonlocal best
        if x is None or depth > 6 or id(x) in seen:
            return
        # keep x alive while the walk runs: an id is unique only among live objects, and a
        # value made on the way (a property's) could free its id for a texture met later
        seen[id(x)] = x
        texels = getattr(x, "texels", None)
        if isinstance(texels, np.ndarray) and texels.ndim >= 2:
            if getattr(x, "filter_type", "bilinear") == "bilinear":
                best = max(best, int(max(texels.shape[:2])))
            return
        if dataclasses.is_dataclass(x) and not isinstance(x, type):
            for f in dataclasses.fields(x):
                walk(getattr(x, f.name, None), depth + 1)
        elif isinstance(x, (tuple, list)):
            for y in x:
                walk(y, depth + 1)
        elif isinstance(x, dict):
            for y in x.values():
                walk(y, depth + 1)

    walk(list(scene.materials.values()))
    walk(list(scene.lights))
    return best


def median_limit(scene=None) -> float:
    """exact-strata's limit on the median relative difference for ``scene``.

    1e-5 (float32 agreement: docs/verdicts.md, "The median"), raised where a large
    bitmap is filtered bilinearly: a float32 texture coordinate is only determined to
    about TEXTURE_ROUNDINGS x u of its range, that is 4 u R texels for a map R texels
    across, and a bilinear lookup between texels that differ by the full range moves by
    that fraction of it. Two renderers that agree in every formula then differ per
    sample by up to 4 u R of the value (measured on mitsuba-data's test_spot_direct: a
    1920-texel binary pattern projected by a spot, camera rays within 1.5e-8 rad of
    the exact ones on both sides, spot values at the same points within 8.6e-8 of each
    other, and a median of 7.7e-5 between the images: under 4 u R = 4.6e-4)."""
    r = largest_bilinear_texture(scene) if scene is not None else 0
    return max(EXACT_LIMITS["median_rel"], TEXTURE_ROUNDINGS * FLOAT32_U * r)


def judge(test_name: str, metrics: Metrics, tracer_img, ref_img,
          noise: Noise | None = None, scene=None) -> tuple[Verdict, ZTest | None]:
    """The verdict of ``test_name`` on the two images, every check passing (docs/verdicts.md,
    one section a test). ``noise``: the z-test's. ``scene``: the scene judged, whose
    bitmaps set exact-strata's median limit (:func:`median_limit`)."""
    checks: dict[str, dict] = {}

    def check(name, value, limit):
        checks[name] = {"value": value, "limit": limit, "pass": bool(value < limit)}

    z = None
    if test_name == "exact-strata":
        e = exact_checks(tracer_img, ref_img)
        check("median_rel", metrics.median_rel, median_limit(scene))
        check("frac_over_01pct", e["frac_over_01pct"], EXACT_LIMITS["frac_over_01pct"])
        checks["frac_over_01pct"].update(edge_ties=e["edge_ties"], edge_tie_cap=e["edge_tie_cap"],
                                         all_beyond=metrics.frac_over_01pct)
        check("mean_rel_diff", e["mean_rel_diff"], EXACT_LIMITS["mean_rel_diff"])
        checks["mean_rel_diff"].update(all_pixels=metrics.mean_rel_diff,
                                       pixels_left_out=e["pixels_left_out"])
    if test_name == "tessellated":
        for k, limit in TESSELLATED_LIMITS.items():
            check(k, getattr(metrics, k), limit)
    if test_name in ("exact-strata", "tessellated"):
        reason = ("same ray tree at the same strata on both sides, nothing random: float32 "
                  "agreement except samples on edges")
        if test_name == "tessellated":
            reason += ("; Mitsuba sees the paraboloid as a fine mesh (chords within 1e-4 of "
                       "its size), so shading may differ by ~1e-3 where it is seen")
    else:
        if noise is None:
            raise ValueError("the z-test needs the reference's variance")
        z = z_test(tracer_img, ref_img, noise.ref_var, noise.tracer_var,
                   random_fraction=noise.random_fraction, samples=noise.samples,
                   ref_replicates=getattr(noise, "ref_passes", None),
                   test_replicates=getattr(noise, "tracer_seeds", None))
        checks["z_fraction_passed"] = {"value": z.fraction_passed, "limit": ZTEST_PASS_FRACTION,
                                       "pass": z.passed, "alpha_pixel": z.alpha_pixel,
                                       "zero_variance": z.zero_variance,
                                       "zero_variance_passed": z.zero_variance_passed}
        var = noise.ref_var.astype(np.float64)
        if noise.tracer_var is not None:
            var = var + noise.tracer_var
        for k, v in block_metrics(tracer_img, ref_img, var).items():
            check(k, v, BLOCK_LIMITS[k])
        rt = region_test(tracer_img, ref_img, noise)
        checks["region_max_z"] = {"value": rt.max_abs_z, "limit": rt.z_crit, "pass": rt.passed,
                                  "alpha": REGION_ALPHA, "regions": rt.regions}
        reason = ("Mitsuba samples one lobe / light point per sample: per-pixel z-test "
                  "(Sidak alpha 0.01, >= 99.75 % pass; zero-variance pixels within q B), "
                  "4x4-block relative differences, and signed sums over materials, tiles "
                  f"and the image within the Sidak level of alpha {REGION_ALPHA:g}")
    passed = all(c["pass"] for c in checks.values())
    return Verdict(test_name, passed, checks, reason), z


# ---------------------------------------------------------------- pictures


def heat_map(rel: np.ndarray, path: str | Path, title: str = "", lo: float = 1e-8,
             hi: float = 1.0, label: str = "|tracer - Mitsuba| / Mitsuba") -> None:
    """False-colour map of per-pixel relative difference on a log scale, with a scale bar.

    Drawn with Pillow from matplotlib's ``inferno`` colour table and its DejaVu Sans
    font: the same picture as a matplotlib figure (image, title, scale bar with its
    decades, the label beside it) in 15 ms instead of 0.3 s, and a report draws about
    30 of them.
    """
    from PIL import Image, ImageDraw

    h, w = rel.shape
    # each pixel a k x k block: the image about 600 pixels wide and at least 240 tall
    k = 1 if w >= 600 else int(np.clip(max(round(600 / w), math.ceil(240 / h)), 2, 32))
    lut = _inferno_lut()
    level = (np.log10(np.clip(np.nan_to_num(rel, nan=hi), lo, hi)) - math.log10(lo)) / (
        math.log10(hi) - math.log10(lo))
    rgb = lut[np.clip((level * 255).round().astype(np.int64), 0, 255)]
    img = Image.fromarray(np.repeat(np.repeat(rgb, k, axis=0), k, axis=1), "RGB")
    small, large = _font(11), _font(13)
    top = 26 if title else 8
    iw, ih = img.size
    bar_x, bar_w = 8 + iw + 12, 16
    width = max(bar_x + bar_w + 72, round(large.getlength(title)) + 16 if title else 0)
    canvas = Image.new("RGB", (width, top + ih + 10), "white")
    canvas.paste(img, (8, top))
    draw = ImageDraw.Draw(canvas)
    draw.rectangle((7, top - 1, 8 + iw, top + ih), outline="black")
    if title:
        wide = large.getlength(title) > iw
        draw.text((width / 2 if wide else 8 + iw / 2, top / 2), title, fill="black",
                  font=large, anchor="mm")
    ramp = lut[np.linspace(255, 0, ih).round().astype(np.int64)]
    canvas.paste(Image.fromarray(np.repeat(ramp[:, None, :], bar_w, axis=1), "RGB"),
                 (bar_x, top))
    draw.rectangle((bar_x - 1, top - 1, bar_x + bar_w, top + ih), outline="black")
    decades = range(round(math.log10(lo)), round(math.log10(hi)) + 1)
    for e in decades:
        y = top + ih - 1 - (e - math.log10(lo)) / (math.log10(hi) - math.log10(lo)) * (ih - 1)
        draw.line((bar_x + bar_w, y, bar_x + bar_w + 3, y), fill="black")
        draw.text((bar_x + bar_w + 5, y), f"1e{e}", fill="black", font=small, anchor="lm")
    side = Image.new("RGB", (ih, 16), "white")
    ImageDraw.Draw(side).text((ih / 2, 8), label, fill="black", font=small, anchor="mm")
    canvas.paste(side.rotate(90, expand=True), (bar_x + bar_w + 48, top))
    canvas.save(path, compress_level=1)


def _inferno_lut() -> np.ndarray:
    """matplotlib's ``inferno`` colour table, 256 x 3 uint8."""
    from matplotlib import colormaps

    return (colormaps["inferno"](np.linspace(0, 1, 256))[:, :3] * 255).round().astype(np.uint8)


def _font(size: int):
    """DejaVu Sans, the font matplotlib ships, at ``size`` pixels (Pillow's own if absent)."""
    from PIL import ImageFont

    try:
        import matplotlib

        return ImageFont.truetype(str(Path(matplotlib.get_data_path()) / "fonts" / "ttf"
                                      / "DejaVuSans.ttf"), size)
    except OSError:
        return ImageFont.load_default(size)


# ---------------------------------------------------------------- one scene, both sides


@dataclass
class Comparison:
    scene: str
    test: str
    passed: bool
    metrics: dict
    checks: dict
    reason: str
    seconds: dict
    spp: int
    size: tuple[int, int]
    integrator: str
    backend: str
    max_depth: int = 0
    description: str = ""
    tracer_only: list = field(default_factory=list)
    #: metrics of the full tracer render (tracer-only parts included) against Mitsuba
    expected_deviation: dict | None = None
    files: dict = field(default_factory=dict)
    #: "deterministic", "onelobe" or "direct" (see the module docstring)
    reference: str = "deterministic"
    #: the one-lobe reference's verdict beside the deterministic one (area-lit scenes):
    #: {"reference", "test", "passed", "checks", "metrics", "reason", "seconds"}
    second_opinion: dict | None = None
    #: the full render (declared tracer-only parts included) judged against the
    #: deterministic reference with the harness's own model of those parts, where it has
    #: one (Schlick's dielectric): {"reference", "models", "test", "passed", "checks",
    #: "metrics"}
    tracer_only_model: dict | None = None

    def to_json(self) -> dict:
        d = asdict(self)
        d["size"] = list(self.size)
        return d


#: Samples per pixel the reference pools for the z-test, over ceil(N / spp) passes
#: at the same strata (see reference.renderers.mitsuba.render.render_reference).
ZTEST_SAMPLES = 1024


def ztest_passes(spp: int) -> int:
    return -(-ZTEST_SAMPLES // spp)


#: Tracer renders (seeds) pooled where the tracer samples lights (area lights).
TRACER_SEEDS = 16


@dataclass
class PooledTracer:
    """The mean of several tracer renders (seeds) and the noise of that mean."""
    image: np.ndarray            # H x W x 3
    variance: np.ndarray         # H x W x 3, from per-sample second moments
    pass_variance: np.ndarray    # H x W, channel sum, from the spread of the seeds' means
    seeds: int


def tracer_pooled(scene, seeds: int = TRACER_SEEDS, first_seed: int = 0) -> PooledTracer:
    """Mean of ``seeds`` tracer renders and the variance of that mean.

    Where the tracer samples area lights the z-test judges its expectation: the
    mean of renders with seeds first_seed, first_seed + 1, ..., with the pooled
    per-sample variance (rule 1) and the spread of the seeds' means (rule 4)
    (docs/verdicts.md, "What the two sides give").
    """
    from whitted.reference.shared import reused

    return reused(lambda: _tracer_pooled(scene, seeds, first_seed), scene, "tracer pooled",
                  seeds, first_seed)


def _tracer_pooled(scene, seeds: int, first_seed: int) -> PooledTracer:
    from whitted.tracer.integrator import Integrator
    from whitted.tracer.sampling import seed32

    m1 = m2 = 0.0
    s1 = s2 = 0.0
    spp = scene.film.strata ** 2
    renders = Integrator(scene).render_seeds(
        [(seed32(first_seed) + k) & 0xFFFFFFFF for k in range(seeds)], moments=True)
    for r in renders:
        mean = r.image.astype(np.float64)
        m1 = m1 + mean / seeds
        m2 = m2 + (r.variance.astype(np.float64) * spp + mean ** 2) / seeds
        c = mean.sum(-1)
        s1, s2 = s1 + c, s2 + c * c
    var = np.maximum(m2 - m1 ** 2, 0) / (spp * seeds)
    spread = np.maximum(s2 - s1 * s1 / seeds, 0) / (seeds - 1) / seeds if seeds > 1 else None
    return PooledTracer(m1.astype(np.float32), var.astype(np.float32), spread, seeds)


def shared_tracer_image(scene, seed: int = 0) -> np.ndarray:
    """The tracer's image of ``scene``; inside :func:`reference.shared.shared`, rendered
    once while no bug is switched on."""
    from whitted.reference.shared import reused
    from whitted.tracer.integrator import Integrator

    return reused(lambda: Integrator(scene, seed=seed).render().image, scene, "tracer image",
                  seed)


def at_strata_centres(scene):
    """The scene with a box filter and samples at the strata centres (no jitter).

    The references evaluate the tracer's own samples, the strata centres, and take
    each pixel's mean: a gaussian filter or jitter changes only where samples lie
    and how they are weighted, the same on both sides
    (tests/reference/renderers/mitsuba/test_import.py judges
    the filter and the jitter against Mitsuba's own), so compare judges the
    radiance at the centres.
    """
    from dataclasses import replace

    f = scene.film
    if f.filter == "box" and not f.jitter:
        return scene
    return replace(scene, film=replace(f, filter="box", jitter=False))


def comparable(scene):
    """The scene with its declared tracer-only parts replaced by what Mitsuba models.

    Each material says what that means for its kind
    (:meth:`~tracer.materials.base.MaterialModel.comparable`): Schlick's
    approximation becomes the exact Fresnel equations, a Phong material's
    ambient term becomes zero. Parts that are not declared stay as they are,
    so an undeclared tracer-only part fails the comparison rather than being
    hidden.
    """
    from dataclasses import replace

    if not scene.tracer_only:
        return scene
    mats = {k: m.comparable(scene.tracer_only) for k, m in scene.materials.items()}
    return replace(scene, materials=mats)


@dataclass
class StatisticalResult:
    """A sampling reference judged by the z-test: the verdict and what it was computed from."""
    verdict: Verdict
    metrics: Metrics
    tracer_image: np.ndarray
    ref: object                  # reference.renderers.mitsuba.render.ReferenceResult
    noise: Noise
    tracer_seeds: int


def statistical_comparison(scene, tracer_image: np.ndarray | None = None,
                           reference: str = "onelobe", passes: int | None = None,
                           seed: int = 0, tracer_seed: int = 0) -> StatisticalResult:
    """Judge ``scene`` against a sampling reference by the z-test (rules 1-4).

    ``tracer_image`` is the tracer's render (rendered here if None); where the
    tracer samples area lights it is replaced by the mean of
    :data:`TRACER_SEEDS` seeds from ``tracer_seed`` on. ``seed`` is the
    reference's first pass seed.
    """
    from whitted.reference.renderers.mitsuba.render import render_reference
    from whitted.tracer.integrator import Integrator

    if tracer_image is None and not scene.samples_lights():
        tracer_image = Integrator(scene).render().image

    integrator = INTEGRATOR_OF[reference_name(reference)]
    if integrator != "whitted":
        raise ValueError(f"the z-test needs moments, which the {integrator!r} integrator "
                         "does not give; compare with --reference onelobe")
    spp = scene.film.strata ** 2
    if passes is None:
        passes = ztest_passes(spp)
    ref = render_reference(scene, integrator, seed=seed, moments=True, passes=passes)
    return statistical_verdict(scene, ref, tracer_image, tracer_seed)


def statistical_verdict(scene, ref, tracer_image: np.ndarray | None = None,
                        tracer_seed: int = 0, regions: dict | None = None,
                        with_flip: bool = True) -> StatisticalResult:
    """Judge the tracer against a sampling reference already rendered (``ref``, with moments).

    The second half of :func:`statistical_comparison`, for callers that judge
    several tracer images against one reference (``reference/mutants.py``).
    ``regions`` (rule 4's regions) are computed from the scene when None.
    ``with_flip``: also the FLIP metric, which is reported, never judged.
    """
    from whitted.tracer.integrator import Integrator, material_ids

    if tracer_image is None and not scene.samples_lights():
        tracer_image = Integrator(scene).render().image
    spp = scene.film.strata ** 2
    tracer_var = tracer_pass_var = None
    seeds = 1
    if scene.samples_lights():
        pooled = tracer_pooled(scene, first_seed=tracer_seed)
        tracer_image, tracer_var, tracer_pass_var = (pooled.image, pooled.variance,
                                                     pooled.pass_variance)
        seeds = pooled.seeds
    if regions is None:
        regions = regions_of(material_ids(scene), list(scene.materials))
    noise = Noise(ref.variance, spp * ref.passes, ref.pass_variance, ref.random_fraction,
                  tracer_var, tracer_pass_var, regions, ref.passes,
                  seeds if scene.samples_lights() else None)
    metrics = image_metrics(tracer_image, ref.image, with_flip=with_flip)
    verdict, _ = judge("z-test", metrics, tracer_image, ref.image, noise)
    if seeds > 1:
        verdict.reason += (f"; the tracer samples area lights, so its image is the mean of "
                           f"{seeds} seeds")
    return StatisticalResult(verdict, metrics, tracer_image, ref, noise, seeds)


#: The second opinion renders at most this many pixels, the scene scaled down
#: (docs/verdicts.md, "The second opinion").
SECOND_OPINION_PIXELS = 160 * 120


def second_opinion_scene(scene):
    """The scene at most :data:`SECOND_OPINION_PIXELS` pixels large, aspect kept."""
    w, h = scene.film.width, scene.film.height
    if w * h <= SECOND_OPINION_PIXELS:
        return scene
    k = math.sqrt(SECOND_OPINION_PIXELS / (w * h))
    return scene.with_overrides(size=(max(1, int(w * k)), max(1, int(h * k))))


def compare_scene(scene, outdir: str | Path | None = None, reference: str = "deterministic",
                  progress=None, passes: int | None = None, second_opinion: bool | None = None,
                  seed: int = 0) -> tuple[Comparison, np.ndarray, np.ndarray]:
    """Render ``scene`` with the tracer and with Mitsuba, compare, and write the outputs.

    ``reference`` is ``deterministic`` (default), ``onelobe`` (``whitted``, the
    name of its integrator, is accepted) or ``direct``; see the module
    docstring. ``second_opinion`` (default: on scenes with area lights, when the
    reference is deterministic) also judges the one-lobe reference by the
    z-test; the scene then passes only if both verdicts pass.

    Returns the comparison and both images. With ``outdir`` the folder gets
    ``tracer.exr``, ``mitsuba.exr``, ``diff.png`` and ``metrics.json`` (and
    ``mitsuba_onelobe.exr`` with a second opinion). A scene that declares
    tracer-only parts is judged with those parts replaced by Mitsuba's
    equivalent (:func:`comparable`); the full render's difference from
    Mitsuba is reported as the expected deviation (``deviation.png``), and
    ``tracer.exr`` is the full render. ``seed`` seeds both sides' random numbers
    (the tracer's area-light samples, which the deterministic reference reads too,
    and the one-lobe reference's lobe and light choices).
    """
    from whitted.reference.renderers.mitsuba.deterministic import shares_light_samples
    from whitted.reference.renderers.mitsuba.render import render_reference
    from whitted.tracer import backend
    from whitted.tracer.imageio import write_exr
    from whitted.tracer.integrator import Integrator
    from whitted.tracer.scene import TRACER_ONLY

    reference = reference_name(reference)
    scene = at_strata_centres(scene)
    full_scene = scene
    scene = comparable(scene)
    fallback = ""
    if reference == "deterministic" and not shares_light_samples(scene):
        # An emitting shape without a sample map: its light cannot be sampled at the
        # tracer's points, so only a sampling reference can judge the scene.
        reference, second_opinion = "onelobe", False
        fallback = ("; an emitter of this scene has no shared light samples "
                    "(reference.renderers.mitsuba.deterministic.SAMPLE_MAPS), so the one-lobe "
                    "reference judges it")
    integrator = INTEGRATOR_OF[reference]
    test_name = choose_test(scene, reference)
    integ = Integrator(scene, seed=seed)
    # The warm-up compiles the kernels, so that both sides are timed warm. Its image is the
    # clean render the formula-bug sweep reuses (shared_tracer_image).
    shared_tracer_image(scene, seed)
    tr = integ.render(progress)
    # The median of three warm renders, as Mitsuba's time is the median of warm passes.
    tr.seconds = float(np.median([tr.seconds] + [integ.render().seconds for _ in range(2)]))
    tracer_image = tr.image
    if test_name == "z-test":
        st = statistical_comparison(scene, tr.image, reference, passes, seed=seed,
                                    tracer_seed=seed)
        ref, metrics, verdict, tracer_image = st.ref, st.metrics, st.verdict, st.tracer_image
    else:
        # The deterministic reference reads the tracer's light samples of the seed the
        # tracer rendered with.
        ref = render_reference(scene, integrator, seed=seed)
        metrics = image_metrics(tr.image, ref.image)
        verdict, _ = judge(test_name, metrics, tr.image, ref.image, scene=scene)
    reason = verdict.reason + fallback
    if reference == "deterministic":
        reason = ("deterministic reference (both lobes of every delta BSDF, the tracer's "
                  "light samples): " + reason)
    full_image, deviation, model = tracer_image, None, None
    if scene is not full_scene:
        full_image = shared_tracer_image(full_scene, seed)
        deviation = asdict(image_metrics(full_image, ref.image))
        reason += ("; tracer-only parts (" + ", ".join(full_scene.tracer_only) +
                   ") replaced by Mitsuba's equivalent for the check, their effect shown as "
                   "the expected deviation")
        model = tracer_only_model_check(full_scene, full_image, seed)
        if model is not None:
            reason += ("; the full render against the harness's own model of "
                       f"{', '.join(model['models'])}: {'pass' if model['passed'] else 'FAIL'}")
    used = full_scene.tracer_only_used()
    for part in TRACER_ONLY:
        if part in used and part not in full_scene.tracer_only:
            reason += (f"; this scene uses {part}, which Mitsuba does not model: declare "
                       f"[compare] tracer_only = [\"{part}\"] to check the rest")
    second = None
    passed = verdict.passed and (model is None or model["passed"])
    if second_opinion is None:
        second_opinion = reference == "deterministic" and scene.samples_lights()
    onelobe_image = None
    if second_opinion and reference == "deterministic":
        small = second_opinion_scene(scene)
        st = statistical_comparison(small, tr.image if small is scene else None, "onelobe",
                                    passes, seed=seed, tracer_seed=seed)
        onelobe_image = st.ref.image
        second = {"reference": "onelobe", "integrator": "whitted", "test": st.verdict.test,
                  "size": [small.film.width, small.film.height],
                  "passed": st.verdict.passed, "checks": st.verdict.checks,
                  "metrics": asdict(st.metrics), "reason": st.verdict.reason,
                  "reference_passes": st.ref.passes, "tracer_seeds": st.tracer_seeds,
                  "seconds": {"mitsuba": st.ref.seconds, "mitsuba_all_passes":
                              st.ref.seconds_total}}
        passed = passed and st.verdict.passed
        reason += ("; second opinion: the one-lobe reference (Mitsuba's own sampling) by "
                   f"the z-test: {'pass' if st.verdict.passed else 'FAIL'}")
    result = Comparison(
        scene=scene.name, test=verdict.test, passed=passed, metrics=asdict(metrics),
        checks=verdict.checks, reason=reason,
        seconds={"tracer": tr.seconds, "mitsuba": ref.seconds,
                 "ratio_mitsuba_over_tracer": ref.seconds / tr.seconds if tr.seconds else None,
                 "mitsuba_all_passes": ref.seconds_total, "reference_passes": ref.passes},
        spp=tr.spp, size=(scene.film.width, scene.film.height), integrator=integrator,
        backend=backend.name(), max_depth=scene.film.max_depth,
        description=full_scene.description, tracer_only=list(full_scene.tracer_only),
        expected_deviation=deviation, reference=reference, second_opinion=second,
        tracer_only_model=model)
    if outdir is not None:
        from whitted.tracer.errors import UserError

        for side, img in (("the tracer's", full_image), ("Mitsuba's", ref.image)):
            if not np.isfinite(img).all():
                raise UserError(f"{side} render overflowed float32 (light too strong: scale "
                                "intensities and radiances down); nothing was written")
        out = Path(outdir)
        out.mkdir(parents=True, exist_ok=True)
        write_exr(out / "tracer.exr", full_image)
        write_exr(out / "mitsuba.exr", ref.image)
        title = (f"{scene.name}: median {metrics.median_rel:.1e}, "
                 f">0.1%: {100 * metrics.frac_over_01pct:.2f}% of pixels")
        heat_map(pixel_relative_difference(tracer_image, ref.image), out / "diff.png", title)
        names = ["tracer.exr", "mitsuba.exr", "diff.png", "metrics.json"]
        if onelobe_image is not None:  # the second opinion's size, see second_opinion_scene
            write_exr(out / "mitsuba_onelobe.exr", onelobe_image)
            names.append("mitsuba_onelobe.exr")
        if deviation is not None:
            heat_map(pixel_relative_difference(full_image, ref.image), out / "deviation.png",
                     f"{scene.name}: expected deviation ({', '.join(full_scene.tracer_only)})")
            names.append("deviation.png")
        result.files = {k: str(out / k) for k in names}
        write_json(out / "metrics.json", result.to_json())
    return result, full_image, ref.image


def tracer_only_model_check(full_scene, full_image: np.ndarray, seed: int = 0) -> dict | None:
    """The full render judged against the harness's model of its declared tracer-only parts.

    Mitsuba has no counterpart of a tracer-only part, so :func:`compare_scene`
    judges the rest of the scene with the part replaced (:func:`comparable`).
    Where the harness has a model of its own of the part, written on Mitsuba's
    API from the formulas (Schlick's dielectric, ``whitted_schlick`` in
    ``reference/materials/dielectric.py``), the full render is judged against
    the deterministic reference with that model too, by the same float-precision
    test, so that a wrong Schlick fails. None where no declared part has a model.
    """
    from whitted.reference.materials import has_tracer_only_models, tracer_only_model
    from whitted.reference.renderers.mitsuba.render import deterministic_image

    if not has_tracer_only_models(full_scene):
        return None
    ref_image = deterministic_image(full_scene, seed, models=True)
    metrics = image_metrics(full_image, ref_image)
    verdict, _ = judge(choose_test(full_scene), metrics, full_image, ref_image,
                       scene=full_scene)
    models = sorted({tracer_only_model(m)["type"] for m in full_scene.used_materials()
                     if m.tracer_only_used() & set(full_scene.tracer_only) and
                     tracer_only_model(m) is not None})
    return {"reference": "deterministic", "models": models, "test": verdict.test,
            "passed": verdict.passed, "checks": verdict.checks, "metrics": asdict(metrics)}


def _finite(v):
    """The value with every NaN or infinite float replaced by None (JSON's null)."""
    if isinstance(v, float):
        return v if math.isfinite(v) else None
    if isinstance(v, dict):
        return {k: _finite(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_finite(x) for x in v]
    return v


def write_json(path: str | Path, data) -> None:
    """Write strict JSON (RFC 8259 has no NaN or Infinity): undefined numbers become null."""
    Path(path).write_text(json.dumps(_finite(data), indent=2, allow_nan=False) + "\n")
