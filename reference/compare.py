"""Compare the tracer's image with Mitsuba's: metrics, a per-pixel z-test, a heat map.

Two tests decide agreement, chosen by what the scene contains:

``exact-strata`` (scenes lit only by point, spot and directional lights, with
no mirrors or glass). Both sides put their samples at the same strata centres
and neither draws a random number, so the images should agree to float32
precision, except in the few pixels where one sample lands on an edge and
the two renderers' rounding puts it on different sides. Required, from the
vertical-slice issue: the median per-pixel relative difference below 1e-4
(float32 carries 2^-24 = 6e-8 relative error per operation; a shading
computation of a few hundred operations stays well within 1e-4), fewer than
0.5 % of pixels beyond 5 % (one of 64 samples changing sides moves a pixel by
1/64 = 1.6 % of the contrast across the edge, so only edge pixels can exceed 5 %,
and edges cover well under 0.5 % of an image at the built-in resolutions), and
the image means within 0.1 % (the edge pixels average out).

``z-test`` (scenes with mirrors, glass or area lights). Mitsuba picks one
lobe at a dielectric and samples area lights at random, so its image has
variance. The reference pools ``ZTEST_SAMPLES`` = 1024 samples per pixel,
ceil(1024 / spp) renders at the same strata with different seeds: a single
64-sample pass misses Fresnel paths rarer than about 1/64 and then reports
zero variance for the very pixels they light (measured on the built-in
glass scenes: 99.82 % of pixels pass with one pass, 99.97 % with 16, and the
differences shrink as 1/sqrt(passes)). As Mitsuba's own render tests do,
each pixel and channel is tested with z = |tracer - mitsuba| / sqrt(Var),
where Var is the variance of the reference's pixel mean, estimated from its
per-sample second moment (E[x^2] - E[x]^2) / N over its N pooled samples,
plus, where the tracer samples area lights, the variance of its image, which
is then the mean of 16 seeds (see :func:`tracer_pooled`), plus a float32
floor (sigma = 1e-4 |value|, the same precision argument as above, so that
pixels without any randomness are compared to float precision). Two-sided
p-values are compared with the Sidak-corrected level
alpha_pixel = 1 - (1 - 0.01)^(1 / pixels); the test passes when at least
99.75 % of the pixel-channels pass. Because the estimated per-sample variance
includes the variation of radiance across a pixel, it bounds the variance of
stratified means from above, so this test is conservative; the block test
below guards against differences it would miss: after averaging 4x4 blocks on
both sides, the median block relative difference must be below 1 % and fewer
than 2 % of blocks may differ by more than 5 % (and by more than three
standard deviations of the two images' noise, so that nearly black blocks,
where a 1024-sample reference still has several per cent of relative noise,
do not count as differences of the renderers).
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

#: Relative floor on the compared values' standard deviation (float32 agreement).
FLOAT_SIGMA = 1e-4

EXACT_LIMITS = {"median_rel": 1e-4, "frac_over_5pct": 0.005, "mean_rel_diff": 1e-3}
#: Deterministic scenes with a shape Mitsuba lacks (a paraboloid), which the conversion
#: tessellates so that its chords stay within 1e-4 of the shape's size: positions then
#: differ by up to 1e-4 relative and interpolated normals by about (pi / N)^2 / 8 for N
#: segments, so shading differs by up to ~1e-3 relative where the shape is seen, and
#: samples within 1e-4 of its silhouette may land on either side.
TESSELLATED_LIMITS = {"median_rel": 1e-3, "frac_over_5pct": 0.02, "mean_rel_diff": 5e-3}
ZTEST_ALPHA = 0.01
ZTEST_PASS_FRACTION = 0.9975
BLOCK = 4
BLOCK_LIMITS = {"block_median_rel": 0.01, "block_frac_over_5pct": 0.02}


def pixel_relative_difference(test: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """Per-pixel relative difference sum_c |t - r| / max(sum_c |r|, floor).

    The floor, 1e-3 of the mean of sum_c |r| over the image, keeps nearly black
    pixels from dividing by zero; where both images are black the difference is 0.
    """
    num = np.abs(test.astype(np.float64) - ref).sum(-1)
    den = np.abs(ref.astype(np.float64)).sum(-1)
    floor = 1e-3 * max(float(den.mean()), 1e-30)
    return num / np.maximum(den, floor)


def block_mean(image: np.ndarray, k: int = BLOCK) -> np.ndarray:
    """Mean over k x k pixel blocks (the image cropped to a multiple of k)."""
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


def image_metrics(test: np.ndarray, ref: np.ndarray, with_flip: bool = True) -> Metrics:
    rel = pixel_relative_difference(test, ref)
    mt, mr = float(test.mean()), float(ref.mean())
    return Metrics(
        rmse=float(np.sqrt(np.mean((test.astype(np.float64) - ref) ** 2))),
        mean_rel=float(rel.mean()), median_rel=float(np.median(rel)), max_rel=float(rel.max()),
        frac_over_5pct=float((rel > 0.05).mean()), mean_tracer=mt, mean_mitsuba=mr,
        mean_rel_diff=abs(mt - mr) / mr if mr != 0 else (0.0 if mt == 0 else math.inf),
        flip=flip_error(test, ref) if with_flip else None)


@dataclass
class ZTest:
    alpha_pixel: float
    fraction_passed: float
    min_p: float
    passed: bool
    p_values: np.ndarray = field(repr=False, default=None)


def z_test(test: np.ndarray, ref: np.ndarray, ref_var: np.ndarray,
           test_var: np.ndarray | None = None, alpha: float = ZTEST_ALPHA,
           pass_fraction: float = ZTEST_PASS_FRACTION) -> ZTest:
    """Per-pixel, per-channel two-sided z-test with the Sidak correction (see module doc)."""
    t = test.astype(np.float64)
    r = ref.astype(np.float64)
    var = ref_var.astype(np.float64) + (0 if test_var is None else test_var)
    var = var + (FLOAT_SIGMA * np.maximum(np.abs(r), np.abs(t))) ** 2
    var = np.maximum(var, 1e-300)
    z = np.abs(t - r) / np.sqrt(var)
    p = np.vectorize(math.erfc, otypes=[np.float64])(z / math.sqrt(2))
    pixels = test.shape[0] * test.shape[1]
    alpha_pixel = 1 - (1 - alpha) ** (1 / pixels)
    frac = float((p > alpha_pixel).mean())
    return ZTest(alpha_pixel, frac, float(p.min()), frac >= pass_fraction, p)


#: A block "differs" only when its difference is also this many standard deviations of
#: the two estimates' noise (see block_metrics).
BLOCK_SIGMAS = 3.0


def block_metrics(test: np.ndarray, ref: np.ndarray, var: np.ndarray | None = None) -> dict:
    """Median relative difference of 4x4 blocks, and the fraction of blocks beyond 5 %.

    With ``var`` (the per-pixel variance of test - ref), a block counts as beyond
    5 % only if its difference also exceeds BLOCK_SIGMAS standard deviations of
    that noise: in blocks far darker than the image (say 1 % of its mean) a
    1024-sample reference still carries several per cent of relative noise,
    and a relative threshold alone would then measure the reference, not the
    renderers.
    """
    bt, br = block_mean(test), block_mean(ref)
    rel = pixel_relative_difference(bt, br)
    beyond = rel > 0.05
    if var is not None:
        k = BLOCK
        sigma_block = np.sqrt(block_mean(var).sum(-1) / (k * k))  # Var(mean of k*k pixels)
        diff = np.abs(bt.astype(np.float64) - br).sum(-1)
        beyond &= diff > BLOCK_SIGMAS * sigma_block
    return {"block_median_rel": float(np.median(rel)),
            "block_frac_over_5pct": float(beyond.mean())}


@dataclass
class Verdict:
    test: str                       # "exact-strata" or "z-test"
    passed: bool
    checks: dict[str, dict]          # name -> {"value", "limit", "pass"}
    reason: str


def choose_test(scene) -> str:
    """``exact-strata`` or ``tessellated`` for deterministic scenes, ``z-test`` when either
    side samples."""
    if scene.has_specular() or scene.has_area_lights():
        return "z-test"
    return "tessellated" if scene.has_tessellated() else "exact-strata"


def judge(test_name: str, metrics: Metrics, tracer_img, ref_img, ref_var=None,
          tracer_var=None) -> tuple[Verdict, ZTest | None]:
    checks: dict[str, dict] = {}

    def check(name, value, limit):
        checks[name] = {"value": value, "limit": limit, "pass": bool(value < limit)}

    z = None
    if test_name in ("exact-strata", "tessellated"):
        limits = EXACT_LIMITS if test_name == "exact-strata" else TESSELLATED_LIMITS
        for k, limit in limits.items():
            check(k, getattr(metrics, k), limit)
        reason = ("same strata on both sides and no random numbers: float32 agreement "
                  "except single edge samples")
        if test_name == "tessellated":
            reason += ("; Mitsuba sees the paraboloid as a fine mesh (chords within 1e-4 of "
                       "its size), so shading may differ by ~1e-3 where it is seen")
    else:
        if ref_var is None:
            raise ValueError("the z-test needs the reference's variance")
        z = z_test(tracer_img, ref_img, ref_var, tracer_var)
        checks["z_fraction_passed"] = {"value": z.fraction_passed, "limit": ZTEST_PASS_FRACTION,
                                       "pass": z.passed, "alpha_pixel": z.alpha_pixel}
        noise = ref_var.astype(np.float64) + (0 if tracer_var is None else tracer_var)
        for k, v in block_metrics(tracer_img, ref_img, noise).items():
            check(k, v, BLOCK_LIMITS[k])
        reason = ("Mitsuba samples one lobe / light point per sample: per-pixel z-test "
                  "(Sidak alpha 0.01, >= 99.75 % pass) and 4x4-block relative differences "
                  "(beyond 5 % and 3 sigma of the noise)")
    passed = all(c["pass"] for c in checks.values())
    return Verdict(test_name, passed, checks, reason), z


# ---------------------------------------------------------------- pictures


def heat_map(rel: np.ndarray, path: str | Path, title: str = "", lo: float = 1e-6,
             hi: float = 1.0) -> None:
    """False-colour map of per-pixel relative difference on a log scale, with a scale bar."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import LogNorm

    h, w = rel.shape
    fig_w = max(4.0, min(10.0, w / 40 + 1.6))
    fig, ax = plt.subplots(figsize=(fig_w, fig_w * h / w * 0.85 + 0.6), dpi=100)
    im = ax.imshow(np.clip(rel, lo, hi), cmap="inferno", norm=LogNorm(vmin=lo, vmax=hi),
                   interpolation="nearest")
    ax.set_xticks([])
    ax.set_yticks([])
    if title:
        ax.set_title(title, fontsize=8)
    cb = fig.colorbar(im, ax=ax, fraction=0.046, pad=0.03)
    cb.set_label("|tracer - Mitsuba| / Mitsuba", fontsize=8)
    cb.ax.tick_params(labelsize=7)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


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

    def to_json(self) -> dict:
        d = asdict(self)
        d["size"] = list(self.size)
        return d


#: Samples per pixel the reference pools for the z-test, over ceil(N / spp) passes
#: at the same strata (see reference.render.render_reference).
ZTEST_SAMPLES = 1024


def ztest_passes(spp: int) -> int:
    return -(-ZTEST_SAMPLES // spp)


#: Tracer renders (seeds) pooled where the tracer samples area lights.
TRACER_SEEDS = 16


def tracer_pooled(scene, seeds: int = TRACER_SEEDS,
                  first_seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Mean of ``seeds`` tracer renders and the variance of that mean.

    Where the tracer samples area lights its image is random. The comparison
    then tests its expectation, estimated by the mean of renders with seeds
    first_seed + 0..seeds-1 (the same strata, independent light samples: as
    one render with seeds x spp samples), and the variance of that mean comes from the
    per-sample second moment pooled over all of them, (E[x^2] - E[x]^2) /
    (seeds x spp). One render's spp samples alone give too noisy a variance
    for a Sidak-corrected test (measured: 99.65 % of pixels passing on the
    Heckbert scene, against 100 % with 16 seeds).
    """
    from tracer.integrator import Integrator

    m1 = m2 = 0.0
    spp = scene.film.strata ** 2
    from tracer.sampling import seed32

    for k in range(seeds):
        r = Integrator(scene, seed=(seed32(first_seed) + k) & 0xFFFFFFFF).render(moments=True)
        mean = r.image.astype(np.float64)
        m1 = m1 + mean / seeds
        m2 = m2 + (r.variance.astype(np.float64) * spp + mean ** 2) / seeds
    var = np.maximum(m2 - m1 ** 2, 0) / (spp * seeds)
    return m1.astype(np.float32), var.astype(np.float32)


def comparable(scene):
    """The scene with its declared tracer-only parts replaced by what Mitsuba models.

    Schlick's approximation becomes the exact Fresnel equations; a Phong
    material's ambient term becomes zero. Parts that are not declared stay as
    they are, so an undeclared tracer-only part fails the comparison rather
    than being hidden.
    """
    from dataclasses import replace

    from tracer.scene import Dielectric, Phong

    if not scene.tracer_only:
        return scene
    mats = dict(scene.materials)
    for k, m in mats.items():
        if "schlick" in scene.tracer_only and isinstance(m, Dielectric):
            mats[k] = replace(m, fresnel="exact")
        if "ambient" in scene.tracer_only and isinstance(m, Phong):
            mats[k] = replace(m, ambient=(0.0, 0.0, 0.0))
    return replace(scene, materials=mats)


def compare_scene(scene, outdir: str | Path | None = None, integrator: str = "whitted",
                  progress=None, passes: int | None = None, seed: int = 0
                  ) -> tuple[Comparison, np.ndarray, np.ndarray]:
    """Render ``scene`` with the tracer and with Mitsuba, compare, and write the outputs.

    Returns the comparison and both images. With ``outdir`` the folder gets
    ``tracer.exr``, ``mitsuba.exr``, ``diff.png`` and ``metrics.json``. A scene
    that declares tracer-only parts is judged with those parts replaced by
    Mitsuba's equivalent (:func:`comparable`); the full render's difference
    from Mitsuba is reported as the expected deviation (``deviation.png``), and
    ``tracer.exr`` is the full render. ``seed`` seeds both sides' random numbers
    (the tracer's area-light samples, the reference's lobe and light choices).
    """
    from reference.render import render_reference
    from tracer import backend
    from tracer.imageio import write_exr
    from tracer.integrator import Integrator

    full_scene = scene
    scene = comparable(scene)
    test_name = choose_test(scene)
    needs_var = test_name == "z-test"
    # The tracer samples only area lights; elsewhere it is deterministic.
    tracer_random = needs_var and scene.has_area_lights()
    integ = Integrator(scene, seed=seed)
    integ.render()  # warm-up: compiles the kernels, so that both sides are timed warm
    tr = integ.render(progress)
    # The median of three warm renders, as Mitsuba's time is the median of warm passes.
    tr.seconds = float(np.median([tr.seconds] + [integ.render().seconds for _ in range(2)]))
    if passes is None:
        passes = ztest_passes(scene.film.strata ** 2) if needs_var else 1
    ref = render_reference(scene, integrator, seed=seed,
                           moments=needs_var and integrator == "whitted", passes=passes)
    tracer_var = None
    if tracer_random:
        tr.image, tracer_var = tracer_pooled(scene, first_seed=seed)
    metrics = image_metrics(tr.image, ref.image)
    ref_var = ref.variance
    if needs_var and ref_var is None:
        raise ValueError(f"the z-test needs moments, which the {integrator!r} integrator "
                         "does not give; compare with --integrator whitted")
    verdict, _ = judge(test_name, metrics, tr.image, ref.image, ref_var, tracer_var)
    reason = verdict.reason
    full_image, deviation = tr.image, None
    if scene is not full_scene:
        full_image = Integrator(full_scene, seed=seed).render().image
        deviation = asdict(image_metrics(full_image, ref.image))
        reason += ("; tracer-only parts (" + ", ".join(full_scene.tracer_only) +
                   ") replaced by Mitsuba's equivalent for the check, their effect shown as "
                   "the expected deviation")
    if tracer_random:
        reason += (f"; the tracer samples area lights, so its image is the mean of "
                   f"{TRACER_SEEDS} seeds")
    for part, used in (("schlick", full_scene.uses_schlick()),
                       ("ambient", full_scene.uses_ambient())):
        if used and part not in full_scene.tracer_only:
            reason += (f"; this scene uses {part}, which Mitsuba does not model: declare "
                       f"[compare] tracer_only = [\"{part}\"] to check the rest")
    result = Comparison(
        scene=scene.name, test=verdict.test, passed=verdict.passed, metrics=asdict(metrics),
        checks=verdict.checks, reason=reason,
        seconds={"tracer": tr.seconds, "mitsuba": ref.seconds,
                 "ratio_mitsuba_over_tracer": ref.seconds / tr.seconds if tr.seconds else None,
                 "mitsuba_all_passes": ref.seconds_total, "reference_passes": ref.passes},
        spp=tr.spp, size=(scene.film.width, scene.film.height), integrator=integrator,
        backend=backend.name(), max_depth=scene.film.max_depth,
        description=full_scene.description, tracer_only=list(full_scene.tracer_only),
        expected_deviation=deviation)
    if outdir is not None:
        from tracer.errors import UserError

        for side, img in (("the tracer's", full_image), ("Mitsuba's", ref.image)):
            if not np.isfinite(img).all():
                raise UserError(f"{side} render overflowed float32 (light too strong: scale "
                                "intensities and radiances down); nothing was written")
        out = Path(outdir)
        out.mkdir(parents=True, exist_ok=True)
        write_exr(out / "tracer.exr", full_image)
        write_exr(out / "mitsuba.exr", ref.image)
        title = (f"{scene.name}: median {metrics.median_rel:.1e}, "
                 f">5%: {100 * metrics.frac_over_5pct:.2f}% of pixels")
        heat_map(pixel_relative_difference(tr.image, ref.image), out / "diff.png", title)
        names = ["tracer.exr", "mitsuba.exr", "diff.png", "metrics.json"]
        if deviation is not None:
            heat_map(pixel_relative_difference(full_image, ref.image), out / "deviation.png",
                     f"{scene.name}: expected deviation ({', '.join(full_scene.tracer_only)})")
            names.append("deviation.png")
        result.files = {k: str(out / k) for k in names}
        write_json(out / "metrics.json", result.to_json())
    return result, full_image, ref.image


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
