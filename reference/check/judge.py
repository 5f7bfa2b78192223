"""Another renderer's image against the reference: is *your* ray tracer right?

``whitted check IMAGE --scene SCENE`` reads an image made by any renderer
(:mod:`reference.check.images`), renders the reference for the scene, and
judges the difference D = image - reference with two rules that each state
their false-alarm rate (alpha: the probability that a correct image fails)
and their power (what they see). The user's noise is unknown; it is taken
from one of three places (``method``):

``variance``: the image's own ``variance`` layer (EXR), the variance of each
pixel's value as the renderer estimated it.

``spp``: ``--spp N``: the noise of N samples of Mitsuba 3's ``path``
integrator on the converted scene (its ``moment`` integrator's per-sample
second moments over ``SPP_MODEL_SAMPLES`` samples, E[x^2] - E[x]^2, divided
by N). This asserts that the renderer is no noisier per sample than a path
tracer that samples one light and one lobe per sample, as most are; it bounds
a stratified estimator's noise from above, and a Whitted renderer that
follows both lobes and every light is quieter still (then the test is
conservative).

``local`` (neither given): the noise is estimated from the image itself.
Under a correct renderer D is noise with mean zero, independent from pixel
to pixel (no denoiser, no sampler correlated across pixels), whose variance
changes slowly across the image; a biased renderer adds a systematic part
that changes slowly too (a formula wrong by a few per cent over a material).
Differences of neighbouring pixels' D remove that slow part and keep the
noise: E[(D_a - D_b)^2 / 2] = (Var_a + Var_b) / 2 (Rice, "Bandwidth choice
for nonparametric regression", Ann. Statist. 12, 1984; Gasser, Sroka and
Jennen-Steinmetz, Biometrika 73, 1986). Each pixel's variance is the mean of
(D_a - D_b)^2 / 2 over the horizontal and vertical neighbour pairs in the
(2 ``LOCAL_RADIUS`` + 1)^2 window around it, leaving out the pairs that touch
the pixel itself, so that a pixel's own error does not hide itself (36 pairs
for the 5 x 5 window). What it cannot know: a pixel whose noise differs
sharply from all its neighbours' (the first pixels inside glass), for which
it errs by up to a factor 2 in variance either way; the per-pixel rule's
allowance of failing pixels absorbs that, and the figures below are measured.

Quantisation. An 8-bit value is the light rounded to a code: an error
uniform over the code's cell, standard deviation step / sqrt(12) in the
encoded domain, and step the cell's width in linear light (``step`` of
:class:`~reference.check.images.UserImage`: through the sRGB curve, about 1.1 %
of the value at 0.5 and 0.4 % near 1); it is added to every pixel's variance.
Where the image has no noise of its own, rounding is not random: a flat area
rounds every pixel the same way, and its sum moves by up to half a step a
pixel. The mean of round(x + n) - (x + n) over Gaussian noise n of standard
deviation s (in steps) is sum_k (-1)^(k+1) sin(2 pi k x) exp(-2 pi^2 k^2 s^2) / (pi k)
(the Fourier series of the rounding error; Widrow and Kollar, "Quantization
Noise", 2008, ch. 5), at most beta(s) = min(1/2, sum_k exp(-2 pi^2 k^2 s^2) /
(pi k)) steps: 1/2 without noise, 0.004 at s = 1/2, nothing beyond. A
region's sum is allowed that much on top of its noise (``quantisation
allowance``): so an 8-bit image without noise cannot show a bias below half
a step, and with noise of a step or more, it is as good as a float image.
Values an 8-bit writer clipped (saturated codes) are compared with the
reference clipped the same way, and left out of the region sums (the mean of
a clipped noisy value lies below the clipped mean).

The rules
---------
1. Per pixel (``pixels``): a pixel fails when any channel's |D| exceeds the
   threshold z_p sqrt(Var + (1e-4 max(|image|, |reference|))^2), z_p the
   two-sided Sidak level for alpha 0.01 over the pixels (5.0 at 160 x 120), as
   in ``reference.verdicts.compare``'s rule 1; the image fails when more than 0.25 % of
   its pixels fail (Mitsuba's render tests allow as many). Alpha: with known
   variance, 0.03 failing pixels are expected where 48 are allowed; with the
   local estimate, the threshold is met more often (the estimate has about 30
   degrees of freedom), still far below the allowance (measured below).
   Power: local errors beyond about 5 sigma on more than 0.25 % of the pixels.
   ``--fail A`` replaces the threshold by an absolute difference A (OpenImageIO
   idiff's meaning: a pixel fails when its largest channel difference exceeds
   A), ``--fail-percent P`` the allowance, and ``--hard-fail H`` fails the image
   when any pixel's difference exceeds H.
2. Regions (``regions``): the signed sum of D (R + G + B) over each material
   seen (the tracer's first hit at each pixel's centre), the background, 4 x 4
   tiles and the whole image, Z_g = (|sum D| - quantisation allowance) /
   sqrt(sum Var), against the Sidak level for a family-wise alpha of 1e-3 over
   the regions (about 4.0 for 20 regions), as ``reference.verdicts.compare``'s rule 4.
   This is what sees a small bias over many pixels; each region's smallest
   bias seen with 90 % power, ((z + 1.28) sqrt(sum Var) + allowance) / sum
   |reference|, is reported. The thresholds above do not change it.

The image passes when both rules pass. ``--warn``, ``--warn-percent`` and
``--hard-warn`` do the same as their ``--fail`` counterparts but only print a
warning (the exit status stays 0).

Measured (``python docs/check_figures.py``; the figures are in the README):
false alarms on correct noisy renders of other renderers over many seeds,
and the power against biases injected into them.

The reference. For a scene whose lights are all points, spots or
directional lights, the tracer's image at the scene's strata is
deterministic (``reference.renderers.mitsuba.deterministic`` shows that Mitsuba's plugins give
the same at float precision; ``--mitsuba`` checks that again and judges the
image against Mitsuba's image too). Where the tracer samples area lights, the
reference is the mean of ``compare.TRACER_SEEDS`` seeds, and its own
variance is added to the image's.

An image that fails is explained (:mod:`reference.check.suspects`): its
difference split by light path and by first-hit material, and the catalog's
formula bugs (:mod:`reference.mutants`) that the scene reaches ranked by how
much of the difference each one's image explains (``suspects``; measured by
``benchmarks/bench_suspects.py``), and a cause named only where one suspect, a
formula bug or a way of writing a right image wrongly
(:mod:`reference.check.conventions`), leaves only noise
(:func:`reference.check.suspects.name_cause`).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from statistics import NormalDist

import numpy as np

from whitted.reference.verdicts.compare import (
    FLOAT_SIGMA,
    POWER_Z,
    REGION_ALPHA,
    REGION_MIN_PIXELS,
    ZTEST_ALPHA,
    ZTEST_PASS_FRACTION,
    image_metrics,
    regions_of,
    sidak,
)

#: Window radius of the local noise estimate (a 5 x 5 window).
LOCAL_RADIUS = 2
#: Percentage of pixels allowed beyond the per-pixel threshold (compare's 99.75 %).
FAIL_PERCENT = 100 * (1 - ZTEST_PASS_FRACTION)
#: Samples per pixel of the path tracer whose per-sample variance models ``--spp N``.
SPP_MODEL_SAMPLES = 1024
METHODS = ("variance", "spp", "local")


@dataclass
class Thresholds:
    """OpenImageIO idiff's thresholds; None keeps the statistical default."""
    fail: float | None = None
    fail_percent: float | None = None
    hard_fail: float | None = None
    warn: float | None = None
    warn_percent: float | None = None
    hard_warn: float | None = None

    def warns(self) -> bool:
        return any(v is not None for v in (self.warn, self.warn_percent, self.hard_warn))


@dataclass
class Reference:
    """The reference image, its own variance, and how much light varies within each pixel."""
    image: np.ndarray                 # H x W x 3 float64, linear
    variance: np.ndarray | None       # H x W x 3, or None (deterministic)
    name: str                         # in words
    seeds: int = 1
    #: H x W x 3: the variance of one of the reference's samples in the pixel,
    #: E[x^2] - E[x]^2 over its strata (and seeds): where the pixel shows an edge, a
    #: renderer that puts its samples elsewhere in the pixel sees other values
    spread: np.ndarray | None = None
    #: H x W x 3: how far the strata centres' mean may lie from the pixel's integral
    #: (:func:`quadrature_error`); zero where light does not change within the pixel
    quadrature: np.ndarray | None = None


#: Most samples the finer render of :func:`quadrature_error` may take (a few seconds of
#: the tracer on two cores).
QUADRATURE_SAMPLES = 1 << 26


def quadrature_error(scene, image: np.ndarray, seed: int = 0) -> np.ndarray:
    """How far the mean over the scene's n x n strata centres may lie from the pixel's integral.

    The reference takes each pixel's light at the centres of n x n strata (the
    midpoint rule); a renderer whose samples land at random in the pixel
    converges to the pixel's integral instead. Where light is smooth across the
    pixel the two agree to O(1 / n^2); where an edge (a silhouette, a shadow's
    border, an edge seen in a mirror) crosses it, the midpoint rule errs by up to
    half a stratum's share of the contrast, O(1 / n), with the same sign all
    along an edge that runs with the pixel grid (a horizon). A render at m x m
    strata, m = 4 n + 1, errs by n / m as much, so R_n - R_m is (1 - n / m) of
    R_n's error, estimated as m / (m - n) |R_n - R_m|. The counts of centres on
    either side of an edge are round(n f) and round(m f) for an edge at f of the
    pixel; with m a multiple of n they can agree exactly and hide the error
    (measured: a horizon where 8 x 8 and 32 x 32 strata give the same value and
    64 x 64 another), with m = 4 n + 1 they cannot both be exact. (m = 2 n + 1
    where (4 n + 1)^2 samples would exceed :data:`QUADRATURE_SAMPLES`; none beyond.)
    A renderer that samples the strata centres, as the reference does, differs by
    none of it.
    """
    from whitted.tracer.integrator import Integrator

    n = scene.film.strata
    pixels = scene.film.width * scene.film.height
    for m in (4 * n + 1, 2 * n + 1):
        if pixels * m * m > QUADRATURE_SAMPLES:
            continue
        fine = scene.with_overrides(spp=m * m)
        r = Integrator(fine, seed=seed).render().image.astype(np.float64)
        return m / (m - n) * np.abs(np.asarray(image, dtype=np.float64) - r)
    return np.zeros_like(image, dtype=np.float64)


def tracer_reference(scene, seed: int = 0) -> Reference:
    """The tracer's image at the scene's strata: deterministic, or the mean of seeds."""
    from whitted.reference.verdicts.compare import TRACER_SEEDS, tracer_pooled
    from whitted.tracer.integrator import Integrator

    spp = scene.film.strata ** 2
    if scene.samples_lights():
        pooled = tracer_pooled(scene, first_seed=seed)
        var = pooled.variance.astype(np.float64)
        image = pooled.image.astype(np.float64)
        return Reference(image, var, f"whitted's tracer, the mean of {TRACER_SEEDS} seeds (area "
                                     "lights are sampled)", TRACER_SEEDS,
                         var * spp * TRACER_SEEDS, quadrature_error(scene, image, seed))
    r = Integrator(scene, seed=seed).render(moments=True)
    image = r.image.astype(np.float64)
    return Reference(image, None, "whitted's tracer (deterministic: every lobe, every light, "
                                  "the scene's strata)", 1, r.variance.astype(np.float64) * spp,
                     quadrature_error(scene, image, seed))


def mitsuba_reference(scene, seed: int = 0) -> Reference:
    """Mitsuba's deterministic reference (reference.renderers.mitsuba.deterministic), at
    the tracer's seeds."""
    from whitted.reference.renderers.mitsuba.render import render_reference
    from whitted.reference.verdicts.compare import TRACER_SEEDS
    from whitted.tracer.sampling import seed32

    seeds = TRACER_SEEDS if scene.samples_lights() else 1
    images = [render_reference(scene, "deterministic", seed=(seed32(seed) + k) & 0xFFFFFFFF)
              .image.astype(np.float64) for k in range(seeds)]
    mean = np.mean(images, axis=0)
    var = None
    if seeds > 1:
        var = np.var(images, axis=0, ddof=1) / seeds
    return Reference(mean, var, "Mitsuba's deterministic reference (its plugins along the "
                                "Whitted ray tree)" + (f", the mean of {seeds} seeds"
                                                       if seeds > 1 else ""), seeds)


def path_variance(scene, samples: int = SPP_MODEL_SAMPLES, seed: int = 0) -> np.ndarray:
    """H x W x 3: the per-sample variance of Mitsuba's ``path`` integrator on the scene.

    Mitsuba's ``moment`` integrator records the nested integrator's first and
    second moments; E[x^2] - E[x]^2 over ``samples`` jittered samples is the
    variance of one sample placed uniformly in the pixel.
    """
    from whitted.reference import mitsuba
    from whitted.reference.renderers.mitsuba.scene import scene_tree, to_dict
    from whitted.tracer.limits import check_render

    mi = mitsuba()
    strata = math.isqrt(samples)
    big = scene.with_overrides(spp=strata * strata)
    check_render(big, moments=True, mitsuba=True)
    tree = scene_tree(big, "path")
    tree["sensor"]["sampler"]["jitter"] = ("boolean", True)
    d = to_dict(tree, mi)
    d["integrator"] = {"type": "moment", "nested": d["integrator"]}
    ms = mi.load_dict(d)
    out = np.asarray(mi.render(ms, seed=seed, spp=strata * strata), dtype=np.float64)
    m1, m2 = out[..., 3:6], out[..., 6:9]
    return np.maximum(m2 - m1 * m1, 0)


# ---------------------------------------------------------------- noise


def local_variance(d: np.ndarray, valid: np.ndarray | None = None,
                   radius: int = LOCAL_RADIUS) -> np.ndarray:
    """Each pixel's noise variance from its neighbours' differences (the module docstring).

    ``d`` is H x W (one channel of the difference image); ``valid`` (H x W)
    marks the pixels that may be used. The result is the mean of
    (d_a - d_b)^2 / 2 over the neighbour pairs inside the pixel's window that
    do not touch the pixel; where a window holds no such pair, the mean over
    the whole image.
    """
    d = np.asarray(d, dtype=np.float64)
    h, w = d.shape
    ok = np.ones((h, w), dtype=bool) if valid is None else valid
    d = np.where(ok, d, 0.0)
    # Pair values placed at their first pixel, (y, x) for (y, x)-(y, x + 1) and (y, x)-(y + 1, x).
    hv = np.zeros((h, w))
    hn = np.zeros((h, w))
    vv = np.zeros((h, w))
    vn = np.zeros((h, w))
    if w > 1:
        m = ok[:, 1:] & ok[:, :-1]
        hv[:, :-1] = np.where(m, (d[:, 1:] - d[:, :-1]) ** 2 / 2, 0)
        hn[:, :-1] = m
    if h > 1:
        m = ok[1:, :] & ok[:-1, :]
        vv[:-1, :] = np.where(m, (d[1:, :] - d[:-1, :]) ** 2 / 2, 0)
        vn[:-1, :] = m
    r = radius
    # A horizontal pair at (y, x) lies in the window of (Y, X) when |y - Y| <= r and
    # X - r <= x <= X + r - 1: the box sum shifted by half a pair; likewise vertical.
    hs = _shifted_box(hv, r, axis=1)
    hc = _shifted_box(hn, r, axis=1)
    vs = _shifted_box(vv, r, axis=0)
    vc = _shifted_box(vn, r, axis=0)
    total = hs + vs
    count = hc + vc
    # Leave out the (up to four) pairs that touch the pixel itself.
    own = hv.copy()
    own_n = hn.copy()
    own[:, 1:] += hv[:, :-1]
    own_n[:, 1:] += hn[:, :-1]
    own += vv
    own_n += vn
    own[1:, :] += vv[:-1, :]
    own_n[1:, :] += vn[:-1, :]
    total -= own
    count -= own_n
    everywhere = (hv.sum() + vv.sum()) / max(hn.sum() + vn.sum(), 1)
    with np.errstate(invalid="ignore", divide="ignore"):
        out = np.where(count > 0.5, total / np.maximum(count, 1), everywhere)
    return np.maximum(out, 0)


def _shifted_box(a: np.ndarray, r: int, axis: int) -> np.ndarray:
    """Window sums of pair values stored at a pair's first pixel (see local_variance).

    Along ``axis`` the window of pixel X holds pairs starting at X - r .. X + r - 1;
    across it, X - r .. X + r.
    """
    a = np.asarray(a, dtype=np.float64)
    h, w = a.shape
    # Shifted copies added up, not a summed-area table: differences of running sums lose
    # every small value after one huge one (a firefly of 1e7 leaves its squares' 1e14
    # in every later sum, and windows far away came out as 0 or negative).
    dy = range(-r, r + 1) if axis == 1 else range(-r, r)
    dx = range(-r, r) if axis == 1 else range(-r, r + 1)
    out = np.zeros((h, w))
    for oy in dy:
        for ox in dx:
            ys0, ys1 = max(0, -oy), min(h, h - oy)
            xs0, xs1 = max(0, -ox), min(w, w - ox)
            if ys0 < ys1 and xs0 < xs1:
                out[ys0:ys1, xs0:xs1] += a[ys0 + oy:ys1 + oy, xs0 + ox:xs1 + ox]
    return out


#: Factors a tried by :func:`footprint_factor`: 0 and 2^-24 .. 1 (one sample), in steps of
#: 2^(1/4).
FOOTPRINT_FACTORS = np.concatenate([[0.0], 2.0 ** np.arange(-24, 0.01, 0.25)])


def footprint_factor(diff: np.ndarray, var: np.ndarray, spread: np.ndarray,
                     use: np.ndarray) -> float:
    """The factor a of the noise a * spread that sampling other points of a pixel adds.

    A renderer that puts its N samples elsewhere in the pixel than the
    reference's strata centres (jittered, random, one at the centre) sees other
    values wherever light varies within the pixel: an edge, a shadow's border, a
    silhouette seen in glass. That noise is confined to thin lines, so the
    local estimate, which averages a 5 x 5 window, sees a sixth of it or less;
    its variance is a * spread, with spread the variance of one sample over the
    pixel (:attr:`Reference.spread`) and a = 1 / N for independent uniform
    samples, less for stratified ones. a is fitted by maximum likelihood over
    every pixel-channel, D ~ Normal(0, var + a spread), on a grid of powers of
    2^(1/4) (a bias confined to a few pixels cannot move it far).
    """
    m = use & (spread > 0) & np.isfinite(diff)
    if not m.any():
        return 0.0
    d2, v, sp = diff[m] ** 2, np.maximum(var[m], 1e-300), spread[m]
    best, best_nll = 0.0, math.inf
    for a in FOOTPRINT_FACTORS:
        t = v + a * sp
        nll = float(np.sum(np.log(t) + d2 / t))
        if nll < best_nll:
            best, best_nll = float(a), nll
    return best


def rounding_bias_bound(s: np.ndarray, terms: int = 8) -> np.ndarray:
    """beta(s): the most rounding can shift a mean, in steps, under Gaussian noise of s steps.

    min(1/2, sum_k exp(-2 pi^2 k^2 s^2) / (pi k)) (module docstring).
    """
    s = np.asarray(s, dtype=np.float64)
    k = np.arange(1, terms + 1).reshape((-1,) + (1,) * s.ndim)
    series = (np.exp(-2 * math.pi ** 2 * k ** 2 * s ** 2) / (math.pi * k)).sum(axis=0)
    return np.minimum(0.5, series)


# ---------------------------------------------------------------- the verdict


@dataclass
class PixelRule:
    threshold: str                   # "statistical (z sigma)" or "absolute A"
    z: float | None                  # the Sidak level, where statistical
    failing: int
    fraction: float
    limit: float                     # allowed fraction
    max_abs: float
    hard: float | None
    passed: bool
    nonfinite: int = 0


@dataclass
class CheckResult:
    """One image judged against one reference."""
    passed: bool
    warned: bool
    method: str
    reference: str
    size: tuple[int, int]
    pixels: dict
    regions: dict
    metrics: dict
    notes: list = field(default_factory=list)
    warning: dict | None = None
    #: H x W x 3 arrays (not in JSON): the difference, its variance, the per-pixel failures
    arrays: dict = field(default_factory=dict, repr=False)

    def to_json(self) -> dict:
        d = {k: v for k, v in asdict(self).items() if k != "arrays"}
        d["size"] = list(self.size)
        return d


def _pixel_rule(diff, var, quad, nonfinite, fail, percent, hard, z_p, judged=None):
    """Failing pixels under a threshold (statistical when ``fail`` is None); ``judged``
    (H x W) the pixels counted, all where None."""
    a = np.abs(diff)
    if fail is None:
        over = a > z_p * np.sqrt(var) + quad
        threshold = f"statistical ({z_p:.1f} sigma of each pixel's noise)"
    else:
        over = a > fail
        threshold = f"absolute {fail:g}"
    failing_px = over.any(axis=-1) | nonfinite
    n = failing_px.size
    if judged is not None:
        failing_px &= judged
        n = max(int(judged.sum()), 1)
    count = int(failing_px.sum())
    limit = (FAIL_PERCENT if percent is None else percent) / 100
    finite_a = np.where(np.isfinite(a), a, 0)
    max_abs = math.inf if nonfinite.any() else float(finite_a.max(initial=0))
    ok = count <= limit * n and (hard is None or max_abs <= hard)
    return PixelRule(threshold, None if fail is not None else z_p, count, count / n, limit,
                     max_abs, hard, bool(ok), int(nonfinite.sum())), failing_px


def judge_image(user, ref: Reference, material_ids: np.ndarray | None = None,
                material_names: list[str] | None = None, model_variance: np.ndarray | None = None,
                thresholds: Thresholds | None = None,
                ignore: np.ndarray | None = None, metrics: bool = True) -> CheckResult:
    """Judge a :class:`~reference.check.images.UserImage` against a :class:`Reference`.

    ``model_variance`` is the variance of the image's pixels under ``--spp N``
    (:func:`path_variance` / N); the image's own variance layer takes
    precedence, and without either the noise is estimated locally. ``ignore``
    (H x W) leaves pixels out of both rules (a hypothesis of
    :mod:`reference.check.conventions` that cannot predict them).
    """
    th = thresholds or Thresholds()
    u = np.asarray(user.image, dtype=np.float64)
    r = np.asarray(ref.image, dtype=np.float64)
    notes = list(user.notes)
    if user.clip is not None:
        r = np.minimum(r, user.clip)
    nonfinite = ~np.isfinite(u).all(axis=-1)
    diff = np.where(np.isfinite(u), u - r, 0.0)
    h, w, _ = u.shape
    q2 = np.zeros_like(u) if user.step is None else (user.step / math.sqrt(12)) ** 2
    floor = (FLOAT_SIGMA * np.maximum(np.abs(r), np.where(np.isfinite(u), np.abs(u), 0))) ** 2
    ref_var = np.zeros_like(u) if ref.variance is None else ref.variance
    valid = ~nonfinite
    if ignore is not None:
        valid = valid & ~ignore
        diff = np.where(ignore[..., None], 0.0, diff)
        nonfinite = nonfinite & ~ignore
    if user.variance is not None:
        method = "variance"
        noise = user.variance + ref_var
        sum_var = None
    elif model_variance is not None:
        method = "spp"
        noise = model_variance + ref_var
        sum_var = None
    else:
        method = "local"
        est = np.stack([local_variance(diff[..., c], valid) for c in range(3)], axis=-1)
        noise = np.maximum(est - q2, 0)      # the estimate holds the dithered rounding too
        sum_var = local_variance(diff.sum(-1), valid)
        spread = np.zeros_like(u) if ref.spread is None else ref.spread
        spread = np.where(spread > floor, spread, 0.0)   # below float precision: no edge
        a = footprint_factor(diff, noise + q2 + floor, spread, valid[..., None] & ~(
            user.saturated if user.saturated is not None else np.zeros_like(u, dtype=bool)))
        if a > 0:
            noise = noise + a * spread
            sum_var = sum_var + a * np.sqrt(spread).sum(-1) ** 2
            notes.append(f"where light varies within a pixel (edges), the noise of sampling it "
                         f"elsewhere is fitted as {a:.3g} x the reference's spread "
                         f"(1 / {1 / a:.3g} samples)")
    var = noise + q2 + floor
    # Channels whose writer clipped them, or that a noisy value may have reached the clip at.
    excluded = np.zeros_like(u, dtype=bool)
    if user.clip is not None:
        sat = user.saturated if user.saturated is not None else u >= user.clip
        excluded = sat | (r + 3 * np.sqrt(noise + q2) >= user.clip)
    pixels = h * w
    alpha_pixel = sidak(ZTEST_ALPHA, pixels)
    z_p = NormalDist().inv_cdf(1 - alpha_pixel / 2)
    quad = np.zeros_like(u) if ref.quadrature is None else ref.quadrature
    pix, failing_px = _pixel_rule(diff, var, quad, nonfinite, th.fail, th.fail_percent,
                                  th.hard_fail, z_p, valid if ignore is not None else None)
    if pix.nonfinite:
        notes.append(f"{pix.nonfinite:,} pixels are NaN or infinite: they fail")
    warning = None
    if th.warns():
        wr, _ = _pixel_rule(diff, var, quad, nonfinite, th.warn,
                            th.warn_percent if th.warn_percent is not None else 0.0,
                            th.hard_warn, z_p)
        warning = asdict(wr)

    # Regions: signed sums of R + G + B.
    use_px = valid & ~excluded.any(axis=-1)
    d_sum = diff.sum(-1)
    if sum_var is None:
        v_sum = np.sqrt(noise + q2).sum(-1) ** 2      # Var(R+G+B) <= (sd_R + sd_G + sd_B)^2
    else:
        v_sum = np.maximum(sum_var, q2.sum(-1))
    v_sum = v_sum + floor.sum(-1)
    if user.step is not None:
        s_steps = np.sqrt(noise) / np.where(user.step > 0, user.step, 1)
        allowance = (rounding_bias_bound(s_steps) * user.step).sum(-1)
    else:
        allowance = np.zeros((h, w))
    allowance = allowance + quad.sum(-1)
    if material_ids is None:
        region_masks = {"image": np.ones((h, w), dtype=bool)}
    else:
        region_masks = regions_of(material_ids, material_names or [])
    level_px = np.abs(r).sum(-1)
    tested = []
    for name, mask in region_masks.items():
        m = mask & use_px
        n_g = int(m.sum())
        s = float(v_sum[m].sum())
        if n_g < REGION_MIN_PIXELS or s <= 0:
            continue
        total = float(d_sum[m].sum())
        allow = float(allowance[m].sum())
        level = float(level_px[m].sum())
        z = max(abs(total) - allow, 0.0) / math.sqrt(s)
        tested.append({"name": name, "pixels": n_g, "z": math.copysign(z, total),
                       "sum_diff": total, "sigma": math.sqrt(s), "allowance": allow,
                       "level": level,
                       "bias": total / level if level > 0 else None})
    alpha_region = sidak(REGION_ALPHA, len(tested))
    z_r = NormalDist().inv_cdf(1 - alpha_region / 2)
    for g in tested:
        g["detectable_bias"] = (((z_r + POWER_Z) * g["sigma"] + g["allowance"]) / g["level"]
                                if g["level"] > 0 else None)
    worst = max(tested, key=lambda g: abs(g["z"]), default=None)
    max_z = abs(worst["z"]) if worst else 0.0
    regions = {"max_abs_z": max_z, "limit": z_r, "alpha": REGION_ALPHA,
               "worst": worst["name"] if worst else None, "passed": bool(max_z < z_r),
               "excluded_pixels": int((~use_px).sum()), "regions": tested}
    if excluded.any():
        notes.append(f"{int(excluded.any(-1).sum()):,} pixels saturated (clipped by an 8-bit "
                     "writer) are left out of the region sums")
    finite_u = np.where(np.isfinite(u), u, r)
    metrics = asdict(image_metrics(finite_u.astype(np.float32), r.astype(np.float32))) \
        if metrics else {}
    passed = pix.passed and regions["passed"]
    warned = warning is not None and not warning["passed"]
    return CheckResult(bool(passed), bool(warned), method, ref.name, (w, h), asdict(pix),
                       regions, metrics, notes, warning,
                       {"diff": diff, "var": var, "failing": failing_px, "reference": r,
                        "image": finite_u, "sum_var": v_sum, "valid": use_px})


def describe_method(result: CheckResult, spp: int | None = None) -> str:
    return {"variance": "the image's own variance layer",
            "spp": f"--spp {spp}: Mitsuba's path tracer's per-sample variance / {spp}",
            "local": "estimated from neighbouring pixels (no variance layer, no --spp)"}[
        result.method]


def format_check(result: CheckResult, title: str, spp: int | None = None) -> str:
    """The short table the command prints."""
    p, g = result.pixels, result.regions
    lines = [title, f"  reference: {result.reference}",
             f"  noise: {describe_method(result, spp)}",
             f"  {'check':<30}{'value':>12}  {'limit':>12}  result"]
    lines.append(f"  {'pixels beyond threshold':<30}{100 * p['fraction']:>10.3f} %  "
                 f"<= {100 * p['limit']:>7.2f} %  {'pass' if p['passed'] else 'FAIL'}")
    lines.append(f"    threshold {p['threshold']}; {p['failing']:,} of "
                 f"{result.size[0] * result.size[1]:,} pixels beyond it"
                 + (f"; hard fail above {p['hard']:g}, largest difference {p['max_abs']:.3g}"
                    if p["hard"] is not None else ""))
    lines.append(f"  {'regions: largest |Z|':<30}{g['max_abs_z']:>12.2f}  <  {g['limit']:>9.2f}  "
                 f"{'pass' if g['passed'] else 'FAIL'}")
    if g["regions"]:
        image = next((x for x in g["regions"] if x["name"] == "image"), None)
        seen = ""
        if image is not None and image["detectable_bias"] is not None:
            seen = (f"; a bias of {100 * image['detectable_bias']:.2g} % over the whole image "
                    "is seen with 90 % power")
        lines.append(f"    {len(g['regions'])} regions tested (largest |Z| in {g['worst']})"
                     + seen)
    m = result.metrics
    lines.append(f"  RMSE {m['rmse']:.3e}   mean rel. {m['mean_rel']:.2e}   median rel. "
                 f"{m['median_rel']:.2e}   image means differ by {100 * m['mean_rel_diff']:.3f} %")
    if result.warning is not None:
        wr = result.warning
        lines.append(f"  warning threshold {wr['threshold']}: {wr['failing']:,} pixels beyond "
                     f"it ({100 * wr['fraction']:.3f} %, allowed {100 * wr['limit']:.2f} %): "
                     + ("WARN" if not wr["passed"] else "ok"))
    for n in result.notes:
        lines.append(f"  note: {n}")
    return "\n".join(lines)


# ---------------------------------------------------------------- one image, start to end


@dataclass
class CheckRun:
    """Everything ``whitted check`` computed for one image."""
    image_path: str
    scene: str
    storage: str
    passed: bool
    warned: bool
    spp: int | None
    result: CheckResult
    #: the verdict against Mitsuba's reference (``--mitsuba``), and the reference's own
    #: agreement with Mitsuba (compare's exact-strata verdict)
    mitsuba: CheckResult | None = None
    reference_vs_mitsuba: dict | None = None
    #: light paths and materials, for an image that fails
    decomposition: dict | None = None
    #: the catalog's formula bugs ranked by how much of the difference each explains
    #: (:class:`reference.check.suspects.SuspectRanking`), for an image that fails
    suspects: dict | None = None
    files: dict = field(default_factory=dict)
    seconds: float = 0.0

    def to_json(self) -> dict:
        return {"image": self.image_path, "scene": self.scene, "storage": self.storage,
                "pass": self.passed, "warn": self.warned, "spp": self.spp,
                "check": self.result.to_json(),
                "mitsuba": None if self.mitsuba is None else self.mitsuba.to_json(),
                "reference_vs_mitsuba": self.reference_vs_mitsuba,
                "decomposition": self.decomposition, "suspects": self.suspects,
                "files": self.files,
                "seconds": self.seconds}


def check_image(user, scene, spp: int | None = None, thresholds: Thresholds | None = None,
                mitsuba: bool = False, seed: int = 0, reference: Reference | None = None,
                decompose: bool = True, suspects: bool = True, log=None) -> CheckRun:
    """Judge a read image (:class:`~reference.check.images.UserImage`) against the scene's
    reference.

    ``reference`` may be given (a suite's stored image); otherwise the tracer
    renders it. ``spp`` selects the ``--spp`` noise model, ``mitsuba`` adds
    Mitsuba's deterministic reference as a second reference. An image that
    fails gets its difference split by light path and material (``decompose``)
    and the catalog's formula bugs ranked by how much of it each explains
    (``suspects``; :func:`reference.check.suspects.rank_catalog`).
    """
    import time

    from whitted.tracer.integrator import material_ids

    say = log or (lambda *_: None)
    start = time.perf_counter()
    if reference is None:
        say("rendering the reference")
        reference = tracer_reference(scene, seed)
    ids = material_ids(scene)
    names = list(scene.materials)
    model = None
    if spp is not None and user.variance is None:
        say(f"rendering the --spp noise model ({SPP_MODEL_SAMPLES} samples of Mitsuba's path)")
        model = path_variance(scene, seed=seed) / spp
    result = judge_image(user, reference, ids, names, model, thresholds)
    run = CheckRun(user.path, scene.name, user.storage, result.passed, result.warned, spp,
                   result)
    if mitsuba:
        from whitted.reference.verdicts.compare import image_metrics, judge

        say("rendering Mitsuba's deterministic reference")
        mref = mitsuba_reference(scene, seed)
        mref.spread = reference.spread
        m = image_metrics(reference.image.astype(np.float32), mref.image.astype(np.float32),
                          with_flip=False)
        verdict, _ = judge("exact-strata", m, reference.image, mref.image, scene=scene)
        run.reference_vs_mitsuba = {"test": verdict.test, "passed": verdict.passed,
                                    "checks": verdict.checks}
        run.mitsuba = judge_image(user, mref, ids, names, model, thresholds)
        run.passed = run.passed and run.mitsuba.passed and verdict.passed
        run.warned = run.warned or run.mitsuba.warned
    if decompose and not result.passed:
        say("splitting the difference by light path and material")
        run.decomposition = decomposition(scene, result, ids, names, seed)
    if suspects and not result.passed:
        from whitted.reference.check.suspects import name_cause, rank_catalog

        say("ranking the catalog's formula bugs by how much of the difference each explains")
        a = result.arrays
        t0 = time.perf_counter()
        ranking = rank_catalog(scene, a["diff"], a["var"], a["valid"], seed, log=log)
        say("judging the conventions and the bugs: which leaves only noise")
        run.suspects = ranking.to_json() | name_cause(
            user, reference, result, ids, names, ranking,
            lambda: fine_image(scene, reference, seed), judge_image=judge_image,
            reference_type=Reference)
        run.suspects["seconds"] = time.perf_counter() - t0
    run.seconds = time.perf_counter() - start
    return run


def fine_image(scene, reference: Reference, seed: int = 0) -> np.ndarray:
    """The tracer's image at twice the film's size (half-pixel shifts: conventions.py), cached
    with the bugs' images; at one seed where lights are sampled."""
    from whitted.reference.check.suspects import mutated_image

    w, h = scene.film.width, scene.film.height
    return mutated_image(scene.with_overrides(size=(2 * w, 2 * h)), None, seed)[0].astype(
        np.float64)


def rank_suspects(user_image: np.ndarray, scene, candidates: list,
                  reference: np.ndarray | None = None, variance: np.ndarray | None = None,
                  use: np.ndarray | None = None) -> list:
    """Rank formula bugs by how well each one's image explains ``user_image``.

    ``reference`` defaults to the tracer's image of the scene, ``variance``
    (the weights' inverse) to :func:`judge_image`'s noise
    estimate for the user's image. For each candidate, D = image - reference
    is fitted by k (M - reference), M the candidate's render; candidates are
    ranked by the share of D they explain (best first): ``candidates`` are
    :class:`reference.check.suspects.Suspect`, the result its ``SuspectFit``.
    Here and not in :mod:`reference.check.suspects`, which the judge imports: it
    judges the image first.
    """
    u = np.asarray(user_image, dtype=np.float64)
    if reference is None or variance is None:
        from whitted.reference.check.images import UserImage

        ref = tracer_reference(scene)
        if reference is None:
            reference = ref.image
        else:
            ref.image = np.asarray(reference, dtype=np.float64)
        if variance is None:
            result = judge_image(UserImage("<image>", "array", "float32", u), ref)
            variance, use = result.arrays["var"], result.arrays["valid"]
    from whitted.reference.check.suspects import rank_difference

    r = np.asarray(reference, dtype=np.float64)
    return rank_difference(u - r, variance, use, candidates,
                           [c.render(scene) for c in candidates], r)


def decomposition(scene, result: CheckResult, ids: np.ndarray, names: list[str],
                  seed: int = 0) -> dict:
    """The failing image's difference by light path and by first-hit material."""
    from whitted.reference.check.suspects import light_path_fit, light_path_images, material_split

    a = result.arrays
    parts = light_path_images(scene, seed)
    paths = light_path_fit(a["diff"], a["var"], parts, a["valid"])
    materials = material_split(a["diff"], a["var"], a["reference"], ids, names, a["valid"])
    return {"light_paths": [asdict(p) for p in paths],
            "materials": [asdict(m) for m in materials]}


def format_run(run: CheckRun, title: str) -> str:
    out = [format_check(run.result, title, run.spp)]
    if run.mitsuba is not None:
        rv = run.reference_vs_mitsuba
        out.append(f"the reference against Mitsuba's ({rv['test']}): "
                   f"{'pass' if rv['passed'] else 'FAIL'}")
        out.append(format_check(run.mitsuba, "the image against Mitsuba's reference:", run.spp))
    if run.decomposition:
        from whitted.reference.check.suspects import MaterialPart, PathFit, format_decomposition

        d = run.decomposition
        out.append(format_decomposition([PathFit(**p) for p in d["light_paths"]],
                                        [MaterialPart(**m) for m in d["materials"]]))
    if run.suspects is not None:
        from whitted.reference.check.suspects import format_cause

        sp = run.suspects
        bugs = sum(f["kind"] == "formula bug" for f in sp["ranked"])
        out.append(format_cause(sp) +
                   f"\n  ({sp['candidates']} bugs of the catalog reach the scene, "
                   f"{bugs} change its image; {len(sp['ranked']) - bugs} conventions tried; "
                   f"{sp['seconds']:.1f} s)")
    verdict = "PASS" if run.passed else "FAIL"
    if run.passed and run.warned:
        verdict = "PASS with a WARNING"
    out.append(verdict)
    return "\n".join(out)


# ---------------------------------------------------------------- files


def side_by_side(image: np.ndarray, reference: np.ndarray, failing: np.ndarray, path,
                 names: tuple[str, str] = ("your image", "reference")) -> None:
    """A PNG: the image, the reference, and the pixels beyond the threshold over it in grey."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from whitted.tracer.imageio import to_srgb8

    a, b = to_srgb8(image), to_srgb8(reference)
    grey = (0.3 * b.mean(-1, keepdims=True) + 60).astype(np.uint8).repeat(3, -1)
    marked = np.where(failing[..., None], np.array([255, 40, 40], dtype=np.uint8), grey)
    h, w = failing.shape
    fig_w = max(6.0, min(15.0, 3 * w / 50 + 1))
    fig, axes = plt.subplots(1, 3, figsize=(fig_w, fig_w / 3 * h / w + 0.6), dpi=100)
    titles = (names[0], names[1], f"{int(failing.sum()):,} pixels beyond the threshold")
    for ax, img, t in zip(axes, (a, b, marked), titles, strict=True):
        ax.imshow(img, interpolation="nearest")
        ax.set_title(t, fontsize=8)
        ax.set_xticks([])
        ax.set_yticks([])
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


#: What ``whitted check`` writes into its output folder.
OUTPUT_NAMES = ("diff.png", "side_by_side.png", "reference.exr", "check.json", "check.html")
#: written too where the image fails and a fitted output curve is shown
OPTIONAL_OUTPUT_NAMES = ("curve.png",)


def refuse_in_the_way(folder, names) -> None:
    """Refuse, before any work, an output folder where a folder stands in an output's place.

    Outputs are moved into place by renaming, which replaces a file or a
    symbolic link but not a folder: found only then, it would leave half the
    outputs moved.
    """
    import os
    from pathlib import Path

    from whitted.tracer.errors import UserError

    for n in names:
        p = Path(folder) / n
        if os.path.isdir(p) and not os.path.islink(p):
            raise UserError(f"{p}: is a folder, where an output file goes")


def write_outputs(run: CheckRun, outdir, title: str, final=None) -> dict:
    """diff.png, side_by_side.png, reference.exr, check.json and check.html in ``outdir``.

    ``final`` is the folder the files will be moved to (``outdir`` where not
    given), as recorded in ``check.json``. An error of the operating system
    (a full disk) is one line naming ``final``; the caller removes what was
    written (``whitted check`` writes into a :class:`tracer.imageio.StagedFolder`).
    """
    from pathlib import Path

    from whitted.reference.verdicts.compare import heat_map, pixel_relative_difference, write_json
    from whitted.tracer.errors import UserError
    from whitted.tracer.imageio import write_exr

    out = Path(outdir)
    run.files = {k: str(Path(final or out) / k) for k in OUTPUT_NAMES}
    try:
        out.mkdir(parents=True, exist_ok=True)
        a = run.result.arrays
        rel = pixel_relative_difference(a["image"], a["reference"])
        heat_map(rel, out / "diff.png", f"{run.scene}: {Path(run.image_path).name} against "
                                        "the reference", label="|image - reference| / reference")
        side_by_side(a["image"], a["reference"], a["failing"], out / "side_by_side.png")
        write_exr(out / "reference.exr", a["reference"])
        curve = None
        if run.suspects is not None and run.suspects.get("curve"):
            write_curve(run, out / "curve.png")
            run.files["curve.png"] = str(Path(final or out) / "curve.png")
            curve = (out / "curve.png").read_bytes()
        write_json(out / "check.json", run.to_json())
        (out / "check.html").write_text(check_page(run, title, (out / "diff.png").read_bytes(),
                                                   curve))
    except OSError as e:
        raise UserError(f"{final or out}: cannot write: {e.strerror or e}") from None
    except UserError as e:   # tracer.imageio's, naming the staging folder
        raise UserError(str(e).replace(str(out), str(final or out))) from None
    return run.files


def write_curve(run: CheckRun, path) -> None:
    """curve.png: the image's values against the reference's, the fitted monotone curve and
    the named curve (:func:`reference.check.conventions.plot_curve`)."""
    from whitted.reference.check import conventions as cv

    c = run.suspects["curve"]
    enc = cv.FileEncoding(c["encoding"], c["maxval"], c["clip"])
    fit = cv.MonotoneFit([np.asarray(x) for x in c["x"]], [np.asarray(y) for y in c["y"]],
                         c["pieces"])
    named = None
    first = run.suspects["ranked"][0] if run.suspects["ranked"] else None
    if run.suspects.get("named") and first and first["kind"] == "convention" and \
            first["id"] != cv.MONOTONE.id and cv.get(first["id"]).write is not None:
        conv = cv.get(first["id"])
        named = cv.Prediction(conv, np.zeros(0), None, None, None, params=first["params"])
    a = run.result.arrays
    cv.plot_curve(fit, enc, path, named, (a["reference"], a["image"]))


def _verdict_html(ok: bool, warn: bool = False) -> str:
    if ok and warn:
        return '<span class="warn">PASS with a WARNING</span>'
    return '<span class="pass">PASS</span>' if ok else '<span class="fail">FAIL</span>'


PAGE_CSS = """
body { font: 14px/1.45 system-ui, sans-serif; margin: 24px auto; max-width: 1200px;
       color: #1d1d1f; padding: 0 16px; }
.pass { color: #137333; font-weight: 600; } .fail { color: #c5221f; font-weight: 600; }
.warn { color: #8a5a00; font-weight: 600; }
table { border-collapse: collapse; margin: 8px 0; font-size: 13px; }
td, th { border: 1px solid #ddd; padding: 3px 8px; text-align: left; vertical-align: top; }
th { background: #f4f4f6; } .meta { color: #555; font-size: 12px; }
h2 { margin-top: 32px; border-bottom: 1px solid #ddd; }
img.map { max-height: 300px; }
"""


def result_rows(result: CheckResult) -> str:
    """Table rows of the two rules (HTML)."""
    import html

    p, g = result.pixels, result.regions
    worst = next((x for x in g["regions"] if x["name"] == g["worst"]), None)
    detail = ""
    if worst is not None and worst.get("bias") is not None:
        detail = f" (in {html.escape(worst['name'])}: bias {100 * worst['bias']:+.3f} %)"
    return (f"<tr><td>pixels beyond the threshold ({html.escape(p['threshold'])})</td>"
            f"<td>{100 * p['fraction']:.3f} % ({p['failing']:,} pixels) &le; "
            f"{100 * p['limit']:.2f} %</td><td>{_verdict_html(p['passed'])}</td></tr>"
            f"<tr><td>regions: largest |Z| of the signed sums</td><td>{g['max_abs_z']:.2f} &lt; "
            f"{g['limit']:.2f}{detail}</td><td>{_verdict_html(g['passed'])}</td></tr>")


def check_page(run: CheckRun, title: str, heat_png: bytes, curve_png: bytes | None = None
               ) -> str:
    """One self-contained HTML page: the verdict, the tables, and the tev-like viewer."""
    import base64
    import html

    from whitted.reference.report.viewer import assets, viewer

    esc = html.escape
    r = run.result
    a = r.arrays
    parts = ["<!doctype html><html lang='en'><head><meta charset='utf-8'>",
             f"<title>whitted check: {esc(run.scene)}</title><style>{PAGE_CSS}</style>",
             assets(), "</head><body>",
             f"<h1>whitted check: {_verdict_html(run.passed, run.warned)}</h1>",
             f"<p>{esc(title)}</p>",
             f"<p class='meta'>image: {esc(run.image_path)} ({esc(run.storage)}); reference: "
             f"{esc(r.reference)}; noise: {esc(describe_method(r, run.spp))}</p>",
             "<table><tr><th>check</th><th>value vs. limit</th><th>result</th></tr>",
             result_rows(r), "</table>"]
    for n in r.notes:
        parts.append(f"<p class='meta'>note: {esc(n)}</p>")
    if run.mitsuba is not None:
        rv = run.reference_vs_mitsuba
        parts.append(f"<h2>Against Mitsuba's reference: {_verdict_html(run.mitsuba.passed)}</h2>"
                     f"<p>The tracer's reference against Mitsuba's ({esc(rv['test'])}): "
                     f"{_verdict_html(rv['passed'])}</p><table><tr><th>check</th>"
                     "<th>value vs. limit</th><th>result</th></tr>"
                     f"{result_rows(run.mitsuba)}</table>")
    if run.decomposition:
        d = run.decomposition
        rows = "".join(f"<tr><td><code>{esc(p['path'])}</code> ({esc(p['words'])})</td>"
                       f"<td>{100 * p['light_share']:.0f} %</td>"
                       f"<td>{100 * p['share']:.0f} %</td>"
                       f"<td>{100 * p['relative_error']:+.2f} % &plusmn; "
                       f"{100 * p['standard_error']:.2f} %</td></tr>" for p in d["light_paths"])
        mats = "".join(f"<tr><td>{esc(m['name'])}</td><td>{m['pixels']:,}</td>"
                       f"<td>{100 * m['share']:.0f} %</td><td>"
                       + ("" if m["bias"] is None else f"{100 * m['bias']:+.2f} %")
                       + "</td></tr>" for m in d["materials"])
        parts.append("<h2>Where the difference sits</h2><table><tr><th>light path</th>"
                     "<th>share of the light</th><th>share of the difference</th><th>fitted "
                     f"relative error</th></tr>{rows}</table><table><tr><th>first hit</th>"
                     "<th>pixels</th>"
                     f"<th>share of the difference</th><th>bias</th></tr>{mats}</table>")
    if run.suspects is not None:
        sp = run.suspects
        parts.append(f"<h2>Cause</h2><p><b>{esc(sp.get('cause', ''))}</b></p>")
        if curve_png is not None:
            import base64 as b64m

            parts.append("<p class='meta'>Your values against the reference's, per channel, "
                         "the monotone curve fitted through them"
                         + (" (it explains the difference down to the noise)"
                            if sp["curve"].get("at_noise") else
                            " (it does not explain the difference: the light transport "
                            "differs)")
                         + ":</p><p><img alt='fitted curve' src='data:image/png;base64,"
                         + b64m.b64encode(curve_png).decode("ascii") + "'></p>")
        rows = "".join(f"<tr><td>{i}</td><td><code>{esc(f['id'])}</code>"
                       + (f" (not told apart from {esc(', '.join(f['ties']))})"
                          if f["ties"] else "")
                       + (f" (same pattern, other strength: {esc(', '.join(f['alike']))})"
                          if f["alike"] else "")
                       + f"</td><td>{esc(f['kind'])}</td>"
                       f"<td>{esc(f['formula'])}</td><td>{esc(f['correct'])}</td>"
                       f"<td>{esc(f['topic'])}" + (f"<br>{esc(f['source'])}" if f["source"]
                                                     else "") + "</td>"
                       f"<td>{100 * f['explains']:.0f} %</td>"
                       f"<td>{'yes' if f['at_noise'] else 'no'}</td>"
                       f"<td>{f['scale']:.2f}</td></tr>" for i, f in enumerate(sp["top"], 1))
        parts.append("<h2>Suspects</h2><p class='meta'>The ways of writing a right image "
                     "wrongly (conventions) and the catalog's formula bugs "
                     f"(whitted mutants --list) that reach the scene ({sp['candidates']}), "
                     "each judged by what it leaves: first the one whose residual is at the "
                     "noise with the smallest score (none: no cause is named), then by the "
                     "share of the whole difference it explains.</p>"
                     "<table><tr><th>rank</th><th>suspect</th><th>kind</th><th>formula</th>"
                     "<th>right</th><th>topic / source</th><th>explains</th><th>at the "
                     f"noise</th><th>strength</th></tr>{rows}</table>")
    parts.append("<h2>The images</h2>")
    parts.append(viewer([("your image", a["image"]), ("reference", a["reference"])],
                        "the difference view outlines the pixels beyond the threshold in cyan",
                        marks=a["failing"]))
    b64 = base64.b64encode(heat_png).decode("ascii")
    parts.append(f"<p><img class='map' alt='relative difference' "
                 f"src='data:image/png;base64,{b64}'></p>")
    parts.append("</body></html>\n")
    return "\n".join(parts)
