"""Three renderers, one vote: the tracer, Mitsuba and LuxCore judged pairwise.

Where the tracer and Mitsuba disagree, one of them is wrong and only a person
could say which; LuxCore (:mod:`reference.renderers.luxcore.render`) is a third, independent
opinion. Each scene is rendered small (:func:`luxcore_scene`: at most
``PIXELS`` pixels).

Same pixels. LuxCore's pixel is the mean of radiance over the pixel's square
(its samples jitter); the tracer and Mitsuba sample fixed strata centres, a
midpoint rule of that mean which is off by up to the edge's contrast / (2 s)
wherever an edge crosses a pixel, coherently along a straight edge
(measured on sphere_point: the image row where the floor ends was 1 %
brighter in LuxCore all along it, |Z| = 14 for its tile). So the tracer and
Mitsuba render ``PASSES`` times with their whole grid of STRATA x STRATA
strata shifted by an offset within a stratum (:func:`shifted`, the camera's
``pixel_offset``). The offsets are a rank-1 lattice, ((k + 1/2) / P,
((g k mod P) + 1/2) / P) of a stratum (P = 16, g = 7; a quick report P = 8,
g = 3): their mean is the stratum's centre, and along each axis they take
P distinct values, so a horizontal or vertical edge is resolved to
1 / (STRATA x P) = 1/128 of a pixel (a square grid of 16 offsets would give
1/32) and a straight edge along a pixel row is off by at most contrast / 256
in each of its pixels (1/128 in a quick report).
Pass k uses the same offset and seed k on both sides:

* the tracer (seed k: its area-light samples);
* Mitsuba: the deterministic reference (reference/renderers/mitsuba/deterministic.py) at the
  tracer's light samples of seed k, so the two agree at float precision,
  pass by pass;
* LuxCore: 1024 jittered samples per pixel (``reference.renderers.luxcore.render``).

Noise: none on the tracer's and Mitsuba's side where no light is sampled
(the passes are fixed); with area lights, the spread of their passes (seeds)
/ PASSES for the region sums, and for rule 1 the tracer's per-sample second
moment (many degrees of freedom; Mitsuba's deterministic reference has the
tracer's light samples and so its noise). LuxCore's from its per-sample
second moment (an upper bound that counts an edge's contrast as noise) and
from its passes' spread (region sums). Every LuxCore sample is random
(jittered), so rule 2 (zero-variance pixels) applies wherever its variance
vanishes.

The two pairs with LuxCore are judged by the statistical verdict of
:mod:`reference.verdicts.compare` (the z-test's rules 1 to 4: per pixel, 4 x 4
blocks, signed sums over materials, tiles and the image), with both sides'
noise; rule 3's block median, which has no allowance for noise, is shown
but not judged (:func:`judge_pair`). The verdict of a scene
(:func:`three_way`):

* all agree: the three pairs pass;
* X is the odd one out: the two pairs with X fail and the third passes
  (with the region where X differs most, and by how much);
* otherwise no majority (all three pairs fail, or one pair alone fails: the
  comparison is not sharp enough to name anyone).

The tracer-Mitsuba pair is the main comparison of ``whitted compare`` at the
scene's own size and strata (its float-precision limits are set for those;
the small images here only feed the two LuxCore pairs).

Scenes with area lights and mirrors or glass are not compared: LuxCore's
paths continue from a diffuse surface (to reach the area light by BSDF
sampling), and through a mirror or glass they reach the light as a caustic,
light Whitted's model leaves out (measured on heckbert_physical: LuxCore
+54 % on the floor lit through the glass sphere).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

#: LuxCore's comparisons render at most this many pixels (the scene scaled down) ...
PIXELS = 64 * 48
#: ... and in a quick report (``whitted report --quick``, CI).
QUICK_PIXELS = 32 * 24
RENDERERS = ("tracer", "mitsuba", "luxcore")


#: Strata per pixel side of the tracer's and Mitsuba's images here.
STRATA = 8
#: Renders of the tracer and of Mitsuba, each with its grid shifted (module docstring) ...
PASSES = 16
#: ... and in a quick report.
QUICK_PASSES = 8
#: Generator of the offsets' rank-1 lattice for a number of passes (coprime to it, and not
#: P - 1, which would put the offsets on one diagonal).
LATTICE = {16: 7, 8: 3}


def luxcore_scene(scene, pixels: int = 0):
    """The scene at most ``pixels`` (PIXELS) large, aspect kept, STRATA^2 samples per pixel."""
    pixels = pixels or PIXELS
    w, h = scene.film.width, scene.film.height
    if w * h > pixels:
        k = math.sqrt(pixels / (w * h))
        w, h = max(1, int(w * k)), max(1, int(h * k))
    return scene.with_overrides(spp=STRATA * STRATA, size=(w, h))


def not_comparable(scene) -> str | None:
    """Why LuxCore's image of ``scene`` cannot be compared (module docstring), or None."""
    if scene.has_area_lights() and scene.has_specular():
        return ("area lights with mirrors or glass: LuxCore adds their caustics, which "
                "Whitted's model leaves out")
    return None


@dataclass
class Side:
    """One renderer's image at the small size, and the noise of that image."""
    name: str
    image: np.ndarray
    variance: np.ndarray | None = None       # H x W x 3, of the image
    pass_variance: np.ndarray | None = None  # H x W, channel sum
    samples: int = 1
    seconds: float = 0.0
    #: H x W: the fraction of samples that made a random choice (rule 2), or None
    random_fraction: np.ndarray | None = None


@dataclass
class ThreeWay:
    scene: str
    size: tuple[int, int]
    #: "tracer-mitsuba" etc. -> {"passed", "checks", "metrics", "worst"}
    pairs: dict = field(default_factory=dict)
    verdict: str = ""        # "all agree", "tracer is the odd one out", ...
    odd: str | None = None   # the odd renderer, or None
    detail: str = ""         # where and by how much
    seconds: dict = field(default_factory=dict)

    @property
    def compared(self) -> bool:
        return bool(self.pairs)

    def to_json(self) -> dict:
        return {"scene": self.scene, "size": list(self.size), "pairs": self.pairs,
                "verdict": self.verdict, "odd": self.odd, "detail": self.detail,
                "seconds": self.seconds}


def shifted(scene, k: int, passes: int = 0):
    """The scene with its whole sample grid moved by pass k's offset (module docstring)."""
    from dataclasses import replace

    passes = passes or PASSES
    u = ((k + 0.5) / passes, ((LATTICE[passes] * k) % passes + 0.5) / passes)
    dx, dy = ((x - 0.5) / scene.film.strata for x in u)
    return replace(scene, camera=replace(scene.camera, pixel_offset=(dx, dy)))


def _passes(name: str, scene, render_one, passes: int = 0) -> Side:
    """Renders with shifted grids and seeds 0, 1, ...: their mean and its noise.

    ``render_one(scene, k)`` returns the image, or (image, variance of its mean from
    its per-sample second moment), which then bounds rule 1's variance (many degrees
    of freedom, where the passes' spread has passes - 1).
    """
    passes = passes or PASSES
    start = time.perf_counter()
    outs = [render_one(shifted(scene, k, passes), k) for k in range(passes)]
    moments = isinstance(outs[0], tuple)
    imgs = np.stack([np.asarray(o[0] if moments else o, dtype=np.float64) for o in outs])
    mean = imgs.mean(0)
    var = pass_var = None
    if scene.samples_lights():   # seeds differ: random; otherwise the passes are fixed
        var = (np.mean([o[1] for o in outs], axis=0) if moments
               else imgs.var(0, ddof=1)) / passes
        pass_var = imgs.sum(-1).var(0, ddof=1) / passes
    return Side(name, mean.astype(np.float32), var, pass_var,
                passes * scene.film.strata ** 2, time.perf_counter() - start)


def tracer_side(scene, passes: int = 0) -> Side:
    from whitted.tracer.integrator import Integrator

    def one(s, k):
        if not s.samples_lights():
            return Integrator(s, seed=k).render().image
        r = Integrator(s, seed=k).render(moments=True)
        return r.image, np.asarray(r.variance, dtype=np.float64)

    return _passes("tracer", scene, one, passes)


def mitsuba_side(scene, passes: int = 0) -> Side:
    """Mitsuba: the deterministic reference at the tracer's light samples of each seed."""
    from whitted.reference.renderers.mitsuba.deterministic import DeterministicReference

    return _passes("mitsuba", scene, lambda s, k: DeterministicReference(s, k).render().image,
                   passes)


def luxcore_side(result) -> Side:
    # every LuxCore sample is random (a jittered position at least)
    return Side("luxcore", result.image, result.variance, result.pass_variance,
                result.samples, result.seconds, np.ones(result.image.shape[:2]))


#: Family-wise false-alarm rate of the count of blocks beyond 5 % and 3 sigma.
BLOCK_ALPHA = 1e-3


def blocks_allowed(n_blocks: int, alpha: float = BLOCK_ALPHA) -> int:
    """The most blocks that noise alone puts beyond 3 sigma, at family-wise ``alpha``.

    Under a correct pair each block is beyond 3 sigma of its noise with probability
    p = 2 (1 - Phi(3)) = 0.0027 (Gaussian block means: a block averages 16 pixels of
    1024 samples each), independently, so the count is Binomial(n, p); the allowance is
    the smallest k with P(count > k) < alpha. At the vote's sizes (32 x 24 quick: 48
    blocks) rule 3's 2 % would allow no block at all, a false alarm in about one pair
    in eight; k is 2 there (P(count > 2) = 1e-4). At the report's sizes 2 % of the
    blocks is the larger allowance and stays.
    """
    from math import comb, erf, sqrt

    p = 1 - erf(3 / sqrt(2))
    tail, k = 1.0, -1
    while tail >= alpha:
        k += 1
        tail -= comb(n_blocks, k) * p ** k * (1 - p) ** (n_blocks - k)
    return k


def _block_allowance(check: dict | None, image: np.ndarray) -> None:
    """Rule 3's count of blocks beyond 5 % and 3 sigma, judged against the larger of its
    2 % and :func:`blocks_allowed` (the vote's images are small)."""
    from whitted.reference.verdicts.compare import block_mean

    if check is None:
        return
    n = int(np.prod(block_mean(image).shape[:2]))
    limit = max(check["limit"], (blocks_allowed(n) + 0.5) / n)
    check["limit"] = limit
    check["pass"] = check["value"] < limit


def judge_pair(scene, a: Side, b: Side, regions: dict) -> dict:
    """Side a against side b by the statistical verdict, both sides' noise counted."""
    from whitted.reference.verdicts.compare import Noise, image_metrics, judge

    ref, test = (b, a) if b.variance is not None else (a, b)
    metrics = image_metrics(test.image, ref.image, with_flip=False)
    if ref.variance is None and test.variance is None:
        # neither side random (no area light): the float-precision verdict
        kind = "tessellated" if scene.has_tessellated() else "exact-strata"
        verdict, _ = judge(kind, metrics, test.image, ref.image, scene=scene)
    else:
        zero = np.zeros_like(ref.image, dtype=np.float64)
        ref_var = zero if ref.variance is None else ref.variance
        noise = Noise(ref_var, ref.samples, ref.pass_variance, ref.random_fraction, test.variance,
                      test.pass_variance, regions)
        verdict, _ = judge("z-test", metrics, test.image, ref.image, noise)
    if "block_median_rel" in verdict.checks:
        # Rule 3's block median has no allowance for noise: its 1 % was set for Mitsuba's
        # 1024 pooled samples of a one-lobe path each, not for a path tracer's samples,
        # whose noise differs. It is shown, not judged; the blocks beyond 5 % and
        # 3 sigma and the region sums keep rule 3's and rule 4's roles.
        verdict.checks["block_median_rel"]["judged"] = False
        _block_allowance(verdict.checks.get("block_frac_over_5pct"), test.image)
        verdict.passed = all(c["pass"] for k, c in verdict.checks.items()
                             if k != "block_median_rel")
    worst = None
    regions_tested = verdict.checks.get("region_max_z", {}).get("regions") or []
    if regions_tested:
        g = max(regions_tested, key=lambda r: abs(r["z"]))
        d = g["z"] * g["sigma"]
        worst = {"region": g["name"], "z": g["z"],
                 "relative": d / g["level"] if g["level"] else math.inf}
    checks = {k: {kk: vv for kk, vv in v.items() if kk != "regions"}
              for k, v in verdict.checks.items()}
    return {"passed": verdict.passed, "checks": checks,
            "metrics": {"mean_rel_diff": metrics.mean_rel_diff,
                        "median_rel": metrics.median_rel, "rmse": metrics.rmse},
            "worst": worst, "test": test.name, "reference": ref.name}


def three_way(pairs: dict) -> tuple[str, str | None, str]:
    """(verdict, odd renderer or None, detail) from the three pairs' verdicts."""
    ok = {k: v["passed"] for k, v in pairs.items()}
    if all(ok.values()):
        return "all agree", None, ""
    for odd in RENDERERS:
        others = [r for r in RENDERERS if r != odd]
        with_odd = [k for k in pairs if odd in k.split("-")]
        if ok[f"{others[0]}-{others[1]}"] and not any(ok[k] for k in with_odd):
            return f"{odd} is the odd one out", odd, _detail(pairs, odd, with_odd)
    failed = ", ".join(k for k, v in ok.items() if not v)
    return "no majority", None, f"failing pairs: {failed}"


def _detail(pairs: dict, odd: str, with_odd: list[str]) -> str:
    parts = []
    for k in with_odd:
        other = [r for r in k.split("-") if r != odd][0]
        w = pairs[k]["worst"]
        if w is None:   # the main comparison (tracer-Mitsuba)
            parts.append(f"against {other}: the main comparison fails")
            continue
        sign = 1 if pairs[k]["test"] == odd else -1   # the difference as odd - other
        rel = sign * w.get("relative", 0.0)
        parts.append(f"against {other}: largest in {w.get('region', '?')}, "
                     f"{100 * rel:+.2f} % (|Z| {abs(w.get('z', 0.0)):.1f})")
    return "; ".join(parts)


@dataclass
class Started:
    """:func:`start_three`'s work: the scenes at LuxCore's size, why each one cannot be
    compared (None where it can), and the LuxCore child rendering those that can."""
    scenes: list
    small: list
    why: list
    job: object = None       # renderers.luxcore.render.LuxJob, None when no scene is compared

    def close(self) -> None:
        if self.job is not None:
            self.job.close()


def start_three(scenes: list, quick: bool = False, nice: int = 0) -> Started:
    """Convert the scenes and start LuxCore on those it can compare (one child process,
    its priority lowered by ``nice``).

    :func:`compare_three` finishes the work; in between the caller may go on (``whitted
    report`` runs its comparisons and the formula-bug sweep while LuxCore renders). A
    scene that does not convert gets its one-line reason.
    """
    from whitted.reference.renderers.luxcore import render as luxcore
    from whitted.reference.renderers.luxcore.scene import describe
    from whitted.reference.renderers.mitsuba.deterministic import shares_light_samples
    from whitted.reference.verdicts.compare import comparable
    from whitted.tracer.errors import UserError

    small = [comparable(luxcore_scene(s, QUICK_PIXELS if quick else PIXELS)) for s in scenes]
    why = []
    for s in small:
        reason = not_comparable(s)
        if reason is None and not shares_light_samples(s):
            # Mitsuba's side of the vote is the deterministic reference, which samples
            # lights as the tracer does only where it has their sample maps
            reason = ("an emitter has no shared light samples (a mesh, polygon or cylinder "
                      "light): Mitsuba's side of the vote cannot be the deterministic "
                      "reference")
        if reason is None:
            try:
                describe(s)
            except UserError as e:
                reason = str(e)
        why.append(reason)
    todo = [s for s, w in zip(small, why, strict=True) if w is None]
    return Started(list(scenes), small, why,
                   luxcore.start_many(todo, nice=nice) if todo else None)


def compare_three(scenes: list, progress=None, quick: bool = False,
                  main: list | None = None, started: Started | None = None) -> list[ThreeWay]:
    """The three-way verdict of each scene (one LuxCore child process for all of them).

    ``main``: per scene, the main tracer-Mitsuba comparison (``whitted compare`` at the
    scene's own settings) as ``{"passed", "checks"}``, which is that pair's verdict;
    run here (:func:`reference.verdicts.compare.compare_scene`) where not given. ``quick``:
    QUICK_PIXELS pixels. Scenes that do not convert, or cannot be compared, get the
    one-line reason. ``started``: :func:`start_three` of the same scenes, called
    earlier (otherwise called here). The tracer's and Mitsuba's sides render while
    LuxCore does, and ``progress(done, total)`` counts LuxCore's passes after that.
    """
    from whitted.reference.verdicts.compare import regions_of
    from whitted.tracer.integrator import material_ids

    if started is None:
        started = start_three(scenes, quick)
    passes = QUICK_PASSES if quick else PASSES
    try:
        sides = {i: {"tracer": tracer_side(s, passes), "mitsuba": mitsuba_side(s, passes)}
                 for i, (s, w) in enumerate(zip(started.small, started.why, strict=True))
                 if w is None}
        results = iter(started.job.results(progress) if started.job is not None else [])
    finally:
        started.close()
    out = []
    for i, (s, reason) in enumerate(zip(started.small, started.why, strict=True)):
        size = (s.film.width, s.film.height)
        if reason is not None:
            out.append(ThreeWay(s.name, size, {}, "not compared", None, reason))
            continue
        sides[i]["luxcore"] = luxcore_side(next(results))
        regions = regions_of(material_ids(s), list(s.materials))
        if main is not None:
            m = main[i]
        else:
            from whitted.reference.verdicts.compare import compare_scene

            c, _, _ = compare_scene(scenes[i])
            m = {"passed": c.passed, "checks": c.checks}
        # the tracer and Mitsuba (the deterministic reference) are judged at their own
        # strata by the main comparison, whose float-precision limits are set for them
        pairs = {"tracer-mitsuba": {"passed": bool(m["passed"]), "checks": m["checks"],
                                    "worst": None, "from": "the main comparison"}}
        for a, b in (("tracer", "luxcore"), ("mitsuba", "luxcore")):
            pairs[f"{a}-{b}"] = judge_pair(s, sides[i][a], sides[i][b], regions)
        verdict, odd, detail = three_way(pairs)
        out.append(ThreeWay(s.name, size, pairs, verdict, odd, detail,
                            {k: v.seconds for k, v in sides[i].items()}))
    return out
