"""Render a scene on Mitsuba 3 (the reference side of every comparison)."""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from whitted.reference import mitsuba
from whitted.reference.renderers.mitsuba.scene import load
from whitted.reference.shared import reused
from whitted.tracer.scene import Scene

INTEGRATORS = ("whitted", "direct", "path", "deterministic")


def deterministic_image(scene: Scene, seed: int = 0, models: bool = False,
                        renderer=None) -> np.ndarray:
    """The deterministic reference's image
    (:mod:`reference.renderers.mitsuba.deterministic`; ``models``:
    the harness's own models of the scene's tracer-only parts), shared as
    :mod:`reference.shared` says. ``renderer``: the DeterministicReference of these
    arguments to render it with, where the caller renders with it again."""
    from whitted.reference.renderers.mitsuba.deterministic import DeterministicReference

    def make():
        ref = renderer or DeterministicReference(scene, seed, models=models)
        return ref.render().image

    return reused(make, scene, "deterministic image", seed, models)


@dataclass
class ReferenceResult:
    """Mitsuba's image, and (with moments) the variance of each pixel's mean."""
    image: np.ndarray                 # H x W x 3 float32, linear
    seconds: float                    # one warm pass at the scene's spp (kernels compiled)
    spp: int
    integrator: str
    variance: np.ndarray | None = None  # H x W x 3, variance of the pixel mean
    passes: int = 1
    seconds_total: float = 0.0
    #: H x W, variance of the pooled pixel mean of the channel sum R + G + B, from the
    #: spread of the passes' means (unbiased for stratified samples; ``passes`` - 1
    #: degrees of freedom); None with a single pass
    pass_variance: np.ndarray | None = None
    #: H x W, the fraction of samples that drew a random number that could change them
    random_fraction: np.ndarray | None = None


def render_reference(scene: Scene, integrator: str = "whitted", seed: int = 0,
                     moments: bool = False, jitter: bool = False,
                     passes: int = 1) -> ReferenceResult:
    """Render ``scene`` on Mitsuba with the given integrator.

    ``moments`` (``whitted`` only) also estimates each pixel's variance from the
    per-sample second moment: Var(mean) = (E[x^2] - E[x]^2) / spp. With
    stratified samples this bounds the true variance of the mean from above.
    ``jitter`` moves samples to random places inside their strata (the default,
    strata centres, is what the tracer uses).

    ``seed`` may be any integer (see :func:`tracer.sampling.seed32`).
    ``passes`` renders the scene that many times with seeds seed, seed + 1, ...
    and pools them: the same sample positions, independent random choices,
    ``passes x spp`` samples per pixel. A single pass of 64 samples misses the
    Fresnel paths whose probability is below about 1/64, and then
    underestimates the variance of exactly those pixels; pooled passes see
    paths 16 times rarer at 16 passes. The passes are independent replicates
    of one stratified estimator, so the spread of their means also gives an
    unbiased variance of the pooled mean (``pass_variance``), which the
    per-sample second moment overestimates wherever radiance varies across a
    pixel.

    ``integrator = "deterministic"`` renders :mod:`reference.renderers.mitsuba.deterministic`
    instead (one pass; ``seed`` picks the tracer's light samples).

    Inside :func:`reference.shared.shared` an equal call returns the first call's result.
    """
    return reused(lambda: _render_reference(scene, integrator, seed, moments, jitter, passes),
                  scene, integrator, seed, moments, jitter, passes)


def _render_reference(scene: Scene, integrator: str, seed: int, moments: bool, jitter: bool,
                      passes: int) -> ReferenceResult:
    if integrator == "deterministic":
        from whitted.reference.renderers.mitsuba.deterministic import DeterministicReference

        ref = DeterministicReference(scene, seed)
        start = time.perf_counter()
        image = deterministic_image(scene, seed, renderer=ref)
        first = time.perf_counter() - start
        warm = ref.render()  # kernels compiled: timed as the tracer is
        return ReferenceResult(image, warm.seconds, warm.spp, integrator, passes=1,
                               seconds_total=first + warm.seconds)
    if integrator not in INTEGRATORS:
        raise ValueError(f"unknown reference integrator {integrator!r}")
    from whitted.tracer.limits import check_render
    from whitted.tracer.sampling import seed32

    check_render(scene, moments=moments, mitsuba=True)
    seed = seed32(seed)

    def pass_seed(k: int) -> int:  # Mitsuba's seeds are 32-bit
        return (seed + k) & 0xFFFFFFFF

    mi = mitsuba()
    with_moments = moments and integrator == "whitted"
    ms = load(scene, mi, integrator, with_moments, jitter)
    spp = scene.film.strata ** 2
    total = 0.0
    warm = []
    mean = m2 = rand = None
    pass_sum = pass_sq = 0.0
    integ = ms.integrator()
    for k in range(passes):
        if hasattr(integ, "pass_seed"):  # our integrator's own random stream
            integ.pass_seed = pass_seed(k)
        start = time.perf_counter()
        out = np.asarray(mi.render(ms, seed=pass_seed(k), spp=spp), dtype=np.float64)
        elapsed = time.perf_counter() - start
        total += elapsed
        if k > 0:
            warm.append(elapsed)
        img = out[..., :3]
        mean = img / passes if mean is None else mean + img / passes
        total_c = img.sum(-1)
        pass_sum = pass_sum + total_c
        pass_sq = pass_sq + total_c ** 2
        if with_moments:
            m2 = out[..., 3:6] / passes if m2 is None else m2 + out[..., 3:6] / passes
            rand = out[..., 6] / passes if rand is None else rand + out[..., 6] / passes
    if not warm:  # one pass: time a second, warm one (its image is not used)
        if hasattr(integ, "pass_seed"):
            integ.pass_seed = pass_seed(1)
        start = time.perf_counter()
        np.asarray(mi.render(ms, seed=pass_seed(1), spp=spp))
        warm.append(time.perf_counter() - start)
    variance = pass_variance = None
    if with_moments:
        variance = (np.maximum(m2 - mean ** 2, 0) / (spp * passes)).astype(np.float32)
    if passes > 1:
        spread = np.maximum(pass_sq - pass_sum ** 2 / passes, 0) / (passes - 1)
        pass_variance = spread / passes
    return ReferenceResult(mean.astype(np.float32), float(np.median(warm)), spp, integrator,
                           variance, passes, total, pass_variance,
                           None if rand is None else rand.astype(np.float32))
