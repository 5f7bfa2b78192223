"""Sample positions and the random numbers of the tracer.

Pixel samples: ``spp = n^2`` samples per pixel on an n x n grid of strata, at
the strata centres (x + (i + 1/2)/n, y + (j + 1/2)/n): the positions of
Mitsuba's ``stratified`` sampler with ``jitter = false``. The tracer itself
is deterministic wherever it does not sample area lights.

Random numbers (area-light sampling only) come from a stateless hash of
(sample index, dimension), so every sample and every dimension draws
independent numbers without carried state: the PCG hash of Jarzynski and
Olano, "Hash Functions for GPU Rendering", JCGT 9(3), 2020.

:func:`light_sample` names the one stream of light samples: the tracer draws
from it, and the harness's deterministic reference on Mitsuba reads the very
same numbers, so that both sides sample every area light at the same points.
"""

import hashlib

import drjit as dr

from whitted.tracer import faults
from whitted.tracer.backend import jit


def seed32(seed: int) -> int:
    """Any integer seed as a 32-bit one: 0 .. 2^32 - 1 as they are, others hashed.

    Seeds beyond 32 bits (negative ones, 2^40, ...) are hashed (BLAKE2b of
    their decimal digits, the first 4 bytes) rather than wrapped, so that
    2^32 + 7 draws other numbers than 7.
    """
    seed = int(seed)
    if 0 <= seed < 1 << 32:
        return seed
    digest = hashlib.blake2b(str(seed).encode(), digest_size=4, person=b"whitted-seed")
    return int.from_bytes(digest.digest(), "little")


def mix32(*values: int) -> int:
    """A 32-bit hash of a few non-negative integers (each < 2^32), on the CPU.

    Used to derive one 32-bit dimension key from (seed, level, light) without
    the collisions of packing them into bit fields; the same PCG permutation
    as :func:`pcg_hash`, applied after each value is added.
    """
    h = 0x9E3779B9
    for v in values:
        h = (h ^ (int(v) & 0xFFFFFFFF)) & 0xFFFFFFFF
        state = (h * 747796405 + 2891336453) & 0xFFFFFFFF
        word = (((state >> ((state >> 28) + 4)) ^ state) * 277803737) & 0xFFFFFFFF
        h = (word >> 22) ^ word
    return h


def pixel_and_sample(idx, spp: int, first_pixel: int):
    """(global pixel index, sample index within the pixel) of sample ``idx`` of a chunk
    whose pixels start at ``first_pixel``, ``spp`` consecutive samples per pixel."""
    local_pixel = idx // spp
    return local_pixel + dr.opaque(jit.UInt32, first_pixel), idx - local_pixel * spp


def pixel_seed_and_sample(idx, spp: int, seeds: int, first_pixel: int):
    """(global pixel index, sample index within the pixel, seed index) of sample ``idx``
    of a chunk that holds ``seeds`` x ``spp`` samples per pixel, seed after seed, from
    pixel ``first_pixel`` (a render of several seeds at once, see
    :meth:`tracer.integrator.Integrator.render_seeds`)."""
    group = spp * seeds
    local_pixel = idx // group
    rest = idx - local_pixel * group
    k = rest // spp
    return local_pixel + dr.opaque(jit.UInt32, first_pixel), rest - k * spp, k


def pixel_samples(width: int, n: int, first_pixel: int, pixel_count: int, seeds: int = 1,
                  idx=None):
    """(global pixel index, sample index within the pixel, film x, film y) for a range of pixels.

    Samples are ordered pixel by pixel, ``n * n`` consecutive samples per pixel,
    so a per-pixel mean is a block reduction. With ``seeds`` > 1 each pixel holds
    that many such runs of samples at the same positions, and a fifth value is each
    sample's seed index (:func:`pixel_seed_and_sample`). ``idx`` (a jit.UInt32)
    picks some of the range's samples by their index in it; by default all.
    """
    spp = n * n
    if idx is None:
        idx = dr.arange(jit.UInt32, pixel_count * spp * seeds)
    if seeds == 1:
        pixel, s = pixel_and_sample(idx, spp, first_pixel)
    else:
        pixel, s, k = pixel_seed_and_sample(idx, spp, seeds, first_pixel)
    # the width an input of the kernel, not a constant in it (tracer/camera.py)
    w = dr.opaque(jit.UInt32, width)
    py = pixel // w
    px = pixel - py * w
    sy = s // n
    sx = s - sy * n
    inv = 1.0 / n
    film_x = jit.Float(px) + (jit.Float(sx) + 0.5) * inv
    film_y = jit.Float(py) + (jit.Float(sy) + 0.5) * inv
    film_x, film_y = faults.pick(
        "pixel-sample-corner",
        lambda: (jit.Float(px) + jit.Float(sx) * inv, jit.Float(py) + jit.Float(sy) * inv),
        (film_x, film_y))
    if seeds > 1:
        return pixel, s, film_x, film_y, k
    return pixel, s, film_x, film_y


def pcg_hash(v):
    """32-bit PCG output permutation of a 32-bit input (Jarzynski & Olano 2020)."""
    state = v * 747796405 + 2891336453
    word = ((state >> ((state >> 28) + 4)) ^ state) * 277803737
    return (word >> 22) ^ word


def uniform(key):
    """A float in [0, 1) from a 32-bit hash value (its top 24 bits)."""
    return jit.Float(key >> 8) * (1.0 / (1 << 24))


def stratified_2d(pixel, s, n: int, dimension: int):
    """A 2D point in [0, 1)^2, stratified over the n*n samples of each pixel.

    Sample ``s`` of a pixel takes stratum (s + k) mod n^2, with k a random
    offset per (pixel, dimension), and a uniform position inside it: each point
    is uniformly distributed, and the points of one pixel cover every stratum
    once, which lowers the variance of area-light estimates.
    """
    spp = n * n
    dim = pcg_hash(jit.UInt32(dimension) * 0x9E3779B9 + 0x7F4A7C15)
    key = pcg_hash(pixel ^ dim)
    stratum = (s + key % spp) % spp
    cy = stratum // n
    cx = stratum - cy * n
    h1 = pcg_hash(key ^ (s * 0x85EBCA6B + 0x68E31DA4))
    h2 = pcg_hash(h1 + 0x632BE5AB)
    inv = 1.0 / n
    x = (jit.Float(cx) + uniform(h1)) * inv
    return faults.pick("light-sample-same-uv", lambda: jit.Array2f(x, x),
                       jit.Array2f(x, (jit.Float(cy) + uniform(h2)) * inv))


def jitter_2d(pixel, s, seed):
    """A uniform 2D point in [0, 1)^2 per (pixel, sample, seed): where a jittered pixel
    sample sits inside its stratum (independent of the light samples' streams).
    ``seed``: an int, or a jit.UInt32 of each lane's seed. An int seed is an input of
    the kernel, not a constant in it, so that one compiled kernel serves every seed (an
    imported scene's gaussian-filtered film renders its 8 seeds one by one)."""
    if isinstance(seed, int):
        seed = dr.opaque(jit.UInt32, seed)
    key = pcg_hash(pixel * 0x27D4EB2D ^ pcg_hash(seed + 0x165667B1))
    h1 = pcg_hash(key ^ (s * 0x85EBCA6B + 0x3C6EF372))
    h2 = pcg_hash(h1 + 0x632BE5AB)
    return jit.Array2f(uniform(h1), uniform(h2))


def light_sample(pixel, s, n: int, seed, depth, light: int, max_depth: int | None = None,
                 which=None):
    """The 2D sample of area light ``light`` for sample ``s`` of ``pixel`` at level ``depth``.

    One dimension of :func:`stratified_2d` per (seed, recursion level, light):
    every level and every light draws independent, stratified points, and a
    render with another ``seed`` draws another set. Levels count from 1 (camera
    rays); lights are numbered in scene order among the emitting shapes.
    ``depth`` is an int, or a jit.UInt32 of levels (at most ``max_depth``, then
    required) where the rays of one kernel sit at different levels. ``seed`` may
    be a sequence of seeds when ``which`` (a jit.UInt32) says which one each sample
    uses: the sample is then the one a render with that seed alone draws.
    """
    if which is not None:  # the same keys, looked up per lane by seed (and level)
        if isinstance(depth, int):
            keys, index = [mix32(seed32(sd), depth, light) for sd in seed], which
        else:
            rows = max_depth + 1
            keys = [mix32(seed32(sd), k, light) for sd in seed for k in range(rows)]
            index = which * rows + depth
        return stratified_2d(pixel, s, n, dr.gather(jit.UInt32, jit.UInt32(keys), index))
    # A hash, not bit fields, so that any 32-bit seed works (seed32 maps other integers);
    # opaque, so that every level and light reuses one compiled kernel.
    if isinstance(depth, int):
        dimension = dr.opaque(jit.UInt32, mix32(seed32(seed), depth, light))
    else:  # the same keys, looked up per lane
        table = jit.UInt32([mix32(seed32(seed), k, light) for k in range(max_depth + 1)])
        dimension = dr.gather(jit.UInt32, table, depth)
    return stratified_2d(pixel, s, n, dimension)
