"""Render a scene on Mitsuba 3 (the reference side of every comparison)."""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from reference import mitsuba
from reference.mitsuba_scene import load
from tracer.scene import Scene

INTEGRATORS = ("whitted", "direct", "path")


@dataclass
class ReferenceResult:
    """Mitsuba's image, and (with moments) the variance of each pixel's mean."""
    image: np.ndarray                 # H x W x 3 float32, linear
    seconds: float
    spp: int
    integrator: str
    variance: np.ndarray | None = None  # H x W x 3, variance of the pixel mean


def render_reference(scene: Scene, integrator: str = "whitted", seed: int = 0,
                     moments: bool = False, jitter: bool = False) -> ReferenceResult:
    """Render ``scene`` on Mitsuba with the given integrator.

    ``moments`` (``whitted`` only) also estimates each pixel's variance from the
    per-sample second moment: Var(mean) = (E[x^2] - E[x]^2) / spp. With
    stratified samples this bounds the true variance of the mean from above.
    ``jitter`` moves samples to random places inside their strata (the default,
    strata centres, is what the tracer uses).
    """
    if integrator not in INTEGRATORS:
        raise ValueError(f"unknown reference integrator {integrator!r}")
    mi = mitsuba()
    ms = load(scene, mi, integrator, moments and integrator == "whitted", jitter)
    spp = scene.film.strata ** 2
    start = time.perf_counter()
    out = np.asarray(mi.render(ms, seed=seed, spp=spp), dtype=np.float32)
    seconds = time.perf_counter() - start
    image = np.ascontiguousarray(out[..., :3])
    variance = None
    if moments and integrator == "whitted":
        m2 = out[..., -3:]
        variance = np.maximum(m2 - image.astype(np.float64) ** 2, 0).astype(np.float32) / spp
    return ReferenceResult(image, seconds, spp, integrator, variance)
