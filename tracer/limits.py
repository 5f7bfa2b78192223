"""Limits on the work and memory a job may take, checked before it starts.

A render that cannot finish (more samples than 32-bit indices count, more
memory than the machine has, a recursion a million levels deep) is refused at
once, in one line that names the limit and the environment variable that
changes it, rather than failing after minutes with a MemoryError, or being
killed. Each limit has a default and an environment variable:

========================  ============================  =================================
variable                  default                       what it bounds
========================  ============================  =================================
WHITTED_MAX_SAMPLES       2^32 - 1                      camera samples of one render
                                                        (width x height x spp), and
                                                        samples of one Fresnel table
WHITTED_MAX_MEMORY        half the machine's memory     estimated memory of one job, and
                                                        of reading a mesh file
                                                        (tracer/meshio.py) or an image
                                                        (tracer/imageheader.py)
WHITTED_MAX_DEPTH         1000                          max_depth (path segments)
WHITTED_MAX_PRIMITIVES    2^31                          primitives, instances counted
                                                        once per instance
WHITTED_MAX_SCENE_BYTES   64 MiB                        size of a scene file (of a Mitsuba
                                                        XML scene: with all its includes)
WHITTED_MAX_INCLUDES      1000                          <include>s of a Mitsuba XML scene,
                                                        all levels together
WHITTED_LPE_MAX_STATES    1000                          states of a light-path automaton
========================  ============================  =================================

Sizes take the suffixes K, M, G, T (powers of 1024). The memory estimates
are deliberately rough upper bounds, per sample and per pixel, of what the
tracer's wavefront, its image buffers and Mitsuba's film hold; they decide
only whether a job is refused, never how it runs.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

from whitted.tracer.errors import UserError

_SUFFIX = {"": 1, "K": 1 << 10, "M": 1 << 20, "G": 1 << 30, "T": 1 << 40}


def _physical_memory() -> int:
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):  # pragma: no cover (not POSIX)
        return 8 << 30


@dataclass(frozen=True)
class Limit:
    variable: str
    default: int
    what: str

    def value(self) -> int:
        """The limit in force: the environment variable if set (checked), else the default."""
        text = os.environ.get(self.variable)
        if text is None or not text.strip():
            return self.default
        t = text.strip().upper().removesuffix("B").removesuffix("I")
        unit = t[-1] if t and t[-1] in _SUFFIX else ""
        try:
            v = int(float(t[:len(t) - len(unit)]) * _SUFFIX[unit])
        except (ValueError, OverflowError):
            v = 0
        if v < 1:
            raise UserError(f"{self.variable}={text[:40]!r}: expected a positive number "
                            f"(suffixes K, M, G, T allowed)")
        return v


MAX_SAMPLES = Limit("WHITTED_MAX_SAMPLES", (1 << 32) - 1, "samples")
MAX_MEMORY = Limit("WHITTED_MAX_MEMORY", _physical_memory() // 2, "")
MAX_DEPTH = Limit("WHITTED_MAX_DEPTH", 1000, "max_depth")
MAX_PRIMITIVES = Limit("WHITTED_MAX_PRIMITIVES", 1 << 31, "primitives")
MAX_SCENE_BYTES = Limit("WHITTED_MAX_SCENE_BYTES", 64 << 20, "scene file size")
LPE_MAX_STATES = Limit("WHITTED_LPE_MAX_STATES", 1000, "automaton states")
MAX_INCLUDES = Limit("WHITTED_MAX_INCLUDES", 1000, "includes")

#: Upper bounds of memory per sample in flight and per pixel (see the module docstring):
#: the tracer's wavefront state over a recursion level (origins, directions, weights,
#: indices, radiance, the next level's two children) is under 200 bytes per sample.
TRACER_BYTES_PER_SAMPLE = 256
#: Per pixel: the float32 image, its second moments, copies made to write it.
BYTES_PER_PIXEL = 96
#: Per primitive: its table rows, a BVH node share, material id and radiance.
BYTES_PER_PRIMITIVE = 128
#: Mitsuba renders the whole image as one wavefront: per sample, its sample state.
MITSUBA_BYTES_PER_SAMPLE = 64
#: A Fresnel-table sample: a surface interaction of Mitsuba's and numpy's inputs.
FRESNEL_BYTES_PER_SAMPLE = 320
#: Samples the tracer keeps in flight at once (the chunk size on a CPU; see integrator):
#: at most this, fewer for deep scenes (:func:`chunk_samples`).
CHUNK_SAMPLES = 1 << 21
#: Bytes one sample of a batch holds while it waits on the depth-first stack (origin,
#: direction, weight, tmax, pixel, stratum, slot, LPE state, Dr.Jit's rounding). Measured:
#: heckbert_minray at 1920 x 1080, 4 spp, max_depth 26 peaked at 4.1 GB with 2^21 samples a
#: chunk, 1.6 GB with 2^19, 0.94 GB with 2^18: about 72 bytes a sample for each level.
PENDING_BYTES_PER_SAMPLE = 72
#: Memory the batches waiting for their turn may take.
PENDING_BUDGET = 1 << 30


#: Samples of a chunk on a CPU where no ray has a child (no mirror, glass or mask: a camera
#: ray is shaded and ends), and the bytes such a sample holds in flight (its ray, slot,
#: radiance, the lane's state; Dr.Jit's buffers). Each chunk's kernel is traced anew from
#: Python, while a process's first render faults in all of a chunk's fresh pages at once;
#: ``benchmarks/bench_chunks.py`` times both against each other. On its two scenes (640 x
#: 480, 16 spp, instanced meshes), 2^22 samples rendered the instanced torus faster than
#: 2^21 in each run, and the knot within the noise (faster in one run, slower in the
#: next); 2^23 was faster still for the torus and slower for the knot. Measured, peak
#: resident memory at 1920 x 1080, 16 spp, chunks of 2^21 against 2^23 (a throwaway
#: script): three_lights 19, shapes_zoo 28, mesh_knot (4 rays a lane) 38 bytes a sample
#: more; 128 bounds them, and FLAT_CHUNK_SAMPLES x 128 is the memory CHUNK_SAMPLES x
#: TRACER_BYTES_PER_SAMPLE allows.
FLAT_CHUNK_SAMPLES = 1 << 22
FLAT_BYTES_PER_SAMPLE = 128
#: Where no ray spawns another, a render's last chunk takes in a remainder of up to
#: 1 / FLAT_TAIL_PART of a chunk (tracer/integrator.py's ``_chunk_spans``): at most
#: FLAT_CHUNK_SAMPLES (1 + 1 / FLAT_TAIL_PART) samples in flight.
FLAT_TAIL_PART = 4


def chunk_samples(max_depth: int, spawns: bool = True) -> int:
    """The CPU chunk for a scene of ``max_depth``: CHUNK_SAMPLES, halved (to 2^16 at the
    least) until the batches a depth-first walk can hold pending, one a level, fit
    PENDING_BUDGET. Where glass splits every ray in two, each level keeps one pending
    half while the other goes deeper, so the pending samples grow with max_depth, not
    with the image. max_depth up to 6 keeps 2^21; DEPTH 25 (max_depth 26) gets 2^19.
    A scene whose rays never ``spawn`` another gets FLAT_CHUNK_SAMPLES."""
    if not spawns:
        return FLAT_CHUNK_SAMPLES
    c = CHUNK_SAMPLES
    while c > (1 << 16) and c * PENDING_BYTES_PER_SAMPLE * (max_depth + 1) > PENDING_BUDGET:
        c //= 2
    return c


def flat_tail(chunk: int) -> int:
    """The most samples a scene's last chunk takes in beyond ``chunk`` where no ray
    spawns another (FLAT_TAIL_PART)."""
    return chunk // FLAT_TAIL_PART


#: The most samples a chunk holds where no ray spawns another.
FLAT_MAX_CHUNK_SAMPLES = FLAT_CHUNK_SAMPLES + flat_tail(FLAT_CHUNK_SAMPLES)


def _gib(n: float) -> str:
    return f"{n / (1 << 30):.3g} GiB" if n >= 1 << 30 else f"{n / (1 << 20):.3g} MiB"


def refuse(limit: Limit, needed: str, value_text: str | None = None) -> None:
    """Raise the one-line refusal: what is needed, the limit, how to change it."""
    lim = value_text or f"{limit.value():,}"
    what = f" {limit.what}" if limit.what else ""
    raise UserError(f"{needed}, beyond the limit of {lim}{what} "
                    f"(set {limit.variable} to change it)")


def check_samples(n: int, what: str) -> None:
    if n > MAX_SAMPLES.value():
        refuse(MAX_SAMPLES, f"{what} takes {n:,} samples")


def check_memory(nbytes: float, what: str) -> None:
    lim = MAX_MEMORY.value()
    if nbytes > lim:
        refuse(MAX_MEMORY, f"{what} needs about {_gib(nbytes)} of memory", _gib(lim))


#: Reading an image: per value (a pixel's channel, at least 3 a pixel, since grey and
#: palettes are widened to RGB), the decoded value and the readers' working copies
#: (float64 conversions, the linear values, their rounding steps). Measured as the peak
#: over the reader's start, 2000 x 1500 RGB: ``whitted check``'s input 75 bytes a value
#: as PNG, 74 as binary PPM, 78 as plain PPM, 29 as half EXR, 20 as float EXR, 12 as PFM.
IMAGE_BYTES_PER_VALUE = 4
IMAGE_WORK_BYTES_PER_VALUE = 92
#: A plain (P3) PPM's text: its lines and numbers as Python objects while parsed, per byte
#: (the same bound as a mesh's text, tracer/meshio.py).
PPM_TEXT_BYTES_PER_BYTE = 32


def check_image_memory(header, work_bytes_per_value: int | None = None) -> None:
    """Refuse an image (a :class:`tracer.imageheader.ImageHeader`) whose reading would
    exceed WHITTED_MAX_MEMORY: the file's bytes and, per value, the decoded value and the
    reader's working copies (``work_bytes_per_value``, IMAGE_WORK_BYTES_PER_VALUE unless
    a reader knows better)."""
    work = IMAGE_WORK_BYTES_PER_VALUE if work_bytes_per_value is None else work_bytes_per_value
    values = max(header.values, header.width * header.height * 3)
    check_memory(header.file_bytes + values * (IMAGE_BYTES_PER_VALUE + work),
                 f"reading this {header.width:,} x {header.height:,} "
                 f"{header.name} image")


def check_depth(max_depth: int) -> None:
    if max_depth > MAX_DEPTH.value():
        refuse(MAX_DEPTH, f"max_depth {max_depth:,} is too deep")


def check_render(scene, moments: bool = False, mitsuba: bool = False) -> None:
    """Refuse a render of ``scene`` (tracer, or with ``mitsuba`` Mitsuba's) that cannot finish."""
    f = scene.film
    spp = f.strata ** 2
    pixels = f.width * f.height
    what = f"a {f.width}x{f.height} render at {spp:,} spp"
    check_depth(f.max_depth)
    check_samples(pixels * spp, what)
    prims = scene.primitive_count()
    if prims > MAX_PRIMITIVES.value():
        refuse(MAX_PRIMITIVES, f"the scene has {prims:,} primitives (instances counted "
                               "once per instance)")
    per_pixel = BYTES_PER_PIXEL * (2 if moments else 1)
    nbytes = prims * BYTES_PER_PRIMITIVE
    if mitsuba:
        nbytes += pixels * per_pixel + pixels * spp * MITSUBA_BYTES_PER_SAMPLE
    else:
        # a chunk: CHUNK_SAMPLES where rays spawn others, else up to FLAT_MAX_CHUNK_SAMPLES
        nbytes += pixels * per_pixel + max(max(CHUNK_SAMPLES, spp) * TRACER_BYTES_PER_SAMPLE,
                                           FLAT_MAX_CHUNK_SAMPLES * FLAT_BYTES_PER_SAMPLE)
    check_memory(nbytes, what)
