"""Whitted's recursive ray tracer, scheduled as a wavefront over recursion levels or,
where rays recurse, as one kernel a chunk whose lanes walk their ray trees on a stack.

Recursion is unrolled into levels: level k holds every ray with k path
segments behind it (camera rays are level 1). Each level is traced in one go
for all its rays; its hits add

* the radiance of an area light hit on its front side (the LE, LS+E paths),
* at diffuse hits, the light of every light source, each through one shadow
  ray (Lambert's law, BRDF = reflectance / pi; lecture 1, "The illumination
  equation"; shadow rays are blocked by every surface, glass included),

and spawn the next level: at mirrors the reflected ray (weight = the
reflectance), at dielectrics both the reflected ray (weight R) and the
refracted ray (weight (1 - R) (n1 / n2)^2), with R from the exact Fresnel
equations or Schlick's approximation, and only reflection under total
internal reflection. Rays that miss, end on a diffuse surface or carry zero
weight spawn nothing, and the next level is compacted to the rays that
remain, so the cost follows the rays actually traced rather than 2^depth.

The integrator never asks which material or light it holds: at a hit it asks
the material interface (:mod:`tracer.materials.dispatch`) for the smooth
part f(wo, wi) to sum over the lights, the delta lobes to follow and any
emission, and it asks each light (:mod:`tracer.emitters`) for a direction,
a shadow-ray length and the incident quantity (diffuse and Phong materials
have a smooth part, mirrors and glass delta lobes).

``max_depth`` counts path segments as Mitsuba does: 1 sees only emitters,
2 adds direct light at the first hit, each further unit one more specular
bounce. The recursion "illumination equation with recursion" of lecture 1 is
exactly this sum, written level by level.

Material emission (an ambient term, the glow of the classic model's light
spheres) and a background that is a hit term are counted with the shading of
a hit, for rays with depth < max_depth, so that max_depth = DEPTH + 1 is
Heckbert's DEPTH exactly for the classic model (:mod:`tracer.emitters.base`).
Rays of the last segment are traced only if they can add light there (an
area light, or a background that is not a hit term).

Pixel samples sit at the centres of n x n strata, or at random inside them
with the film's ``jitter``; with the box filter a pixel is the mean of its
own samples, with the gaussian or tent filter every sample is splatted onto the
pixels within the filter's radius (:class:`_Splat`).

Work is bounded: the image is rendered in chunks of whole pixels, and a level
that grows beyond the chunk size is split and processed depth-first.

Each level costs a few kernels, and none waits on the host except the
compaction (which must know the next level's size): one kernel traces,
shades, casts the shadow rays and writes the next level's candidate rays; a
scatter adds the level's light to its samples (the camera level writes it
directly, :class:`_Radiance`); one compress and one gather build the next
level from every child batch at once (:func:`_compact`); the level's ray
counts are summed on the device and read when the render ends. A batch
carries only what cannot be recomputed (ray, weight, sample slot).

In a scene with a triangle mesh, placed or instanced, the camera level gives
each lane K samples of one pixel (:data:`GROUPS`, :attr:`Integrator.group`): the
K rays walk the mesh's BVH together, reading each node once
(:meth:`Geometry.closest_hit_group`), and a hierarchy of instances too, and so
do their shadow rays to each light; the rest of the shading is done for
each ray on its own, by the same operations, so the image and the ray counts
are those of one ray a lane, exactly (``tests/tracer/test_packets.py``). The light of
the K rays is put back in sample order after the level's kernel.

In a scene with mirrors or glass and max_depth > 2, the ``stack`` schedule
(:meth:`Integrator._render_stack`, the default there) traces the same rays
in one kernel a chunk: each lane follows its sample's tree depth first, with
the children it keeps waiting on a stack in local memory, and sums its light
in a register. The shading is the same function (:meth:`Integrator._shade`)
in both; what a level number decides for a whole wavefront becomes a mask per
ray. The per-level kernels, the compaction and the atomic adds of each
level's light are gone: Heckbert's scene at DEPTH 25 (256x256, 16 spp) went
from 684 kernels and 76 M rays/s to 18 kernels and about 140 M rays/s
(``benchmarks/bench_speed.py recursion``). The counts per level are equal
ray for ray, and the images equal to float32 rounding
(``tests/tracer/test_schedules.py``).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import drjit as dr
import numpy as np

from whitted.tracer import backend, faults, lights
from whitted.tracer.backend import any_mask, jit
from whitted.tracer.camera import generate_rays
from whitted.tracer.emitters import area, scene_emitters
from whitted.tracer.geometry import Geometry, Hit, spawn_offset
from whitted.tracer.limits import flat_tail
from whitted.tracer.materials.base import ShadingPoint
from whitted.tracer.materials.dispatch import SceneMaterials
from whitted.tracer.sampling import (
    jitter_2d,
    light_sample,
    pixel_and_sample,
    pixel_samples,
    pixel_seed_and_sample,
    seed32,
)
from whitted.tracer.scene import Scene

#: Shadow rays stop this fraction short of the light, so the light's own surface
#: (for area lights) never counts as an occluder.
SHADOW_EPSILON = 1e-3

#: A ray "still matters" in the statistics when its weight exceeds this: it can then
#: change its pixel by more than 0.1 % of the light it finds.
SIGNIFICANT_WEIGHT = 1e-3


#: Levels up to which the stack schedule sums its per-level ray counts with one scatter
#: each, written out in the kernel (:meth:`Integrator._render_stack`); deeper, a loop.
UNROLLED_LEVELS = 64

#: :meth:`Integrator._light_samples`'s "which sum" of a sampled light whose seeds a lane
#: carries (shared ray trees): its shadow rays are cast in a loop, one seed a pass.
SEED_LOOP = -2

#: How the recursion is scheduled (:class:`Integrator`'s ``schedule``).
SCHEDULES = ("auto", "wavefront", "stack")


#: The seeds a lane of shared ray trees (:meth:`Integrator.render_seeds`) carries for each
#: sample it counts as in a chunk. Such a lane traces one tree and keeps a sum of light
#: per seed: 16 seeds hold 16 sums (and their squares once evaluated) beside one ray's
#: state, not 16 rays'. Counted as 16 samples, a chunk of 2^21 samples was 2^17 lanes,
#: each chunk's kernel traced anew from Python (a 16-seed kernel: about 15-20 ms):
#: heckbert_physical_hd's 16 seeds (256 x 256, 16 spp) took 0.40 s in 8 chunks, peaking
#: at 232 MB; counted as 4, 0.26-0.29 s in 2 chunks, peaking at 407 MB (one chunk:
#: 0.22 s, 440 MB; a throwaway script, peak resident memory of the process).
SEEDS_PER_LANE_SAMPLE = 4

#: Camera rays a lane (:attr:`Integrator.group`) where the scene has a mesh (placed, or in
#: an instanced group), by the lanes of Dr.Jit's SIMD packets on this CPU
#: (:func:`tracer.backend.llvm_vector_width`): the lane's rays walk the BVH as a packet,
#: reading each node and triangle once for all of them
#: (:meth:`tracer.bvh.BVH.closest_hit_group`; instances:
#: :meth:`tracer.geometry._InstanceSetBlock.intersect_group`). A lane's K rays are K
#: consecutive samples of one pixel (K divides the samples of a pixel), so their walks
#: nearly coincide. Each ray of a packet holds its own registers through the walk, so a
#: larger K also means a larger kernel, which costs LLVM more time to compile the more it
#: spills: AVX-512 has 32 vector registers, AVX2 16.
#: ``python benchmarks/bench_group.py`` prints, for each K, a fresh process's compile
#: seconds and the warm render of five mesh scenes (``bench_speed.py process``'s two,
#: ``bench_mesh.py``'s, scenes/mesh_*.toml; 640x480, 16 spp):
#:
#: - 16 lanes (AVX-512): the render of ``benchmarks/bench_mesh.py``'s scene (144,000
#:   triangles, 640x480, 16 spp; a throwaway script of an earlier round, medians of 7):
#:   K = 1 249 ms, 2 190-197 ms, 4 177-185 ms, 8 186-188 ms. K = 4.
#: - 8 lanes (AVX2, an AMD EPYC of the Zen 3 family): K = 4 took LLVM 0.6-2.5 s longer
#:   than K = 2 on every scene (about twice as long); warm, it rendered four of the five
#:   3-20 % faster and the instanced knot 11 % slower (K = 1 and 8 on the two process
#:   scenes: 0.6 and 6.3 s of LLVM). K = 2: a render whose kernel is not yet cached (a
#:   first run, the case of a whole process on a fresh machine) saves more than a warm one
#:   loses.
#:   ``bench_speed.py mesh``'s render of one knot against Embree is then 1.74x on that
#:   machine (1.38x with K = 4).
GROUPS = {16: 4, 8: 2}

#: K where Dr.Jit's packets have another width (4 lanes: SSE, NEON; not measured) or the
#: width is unknown: the smaller of the measured kernels.
GROUP_ELSEWHERE = 2


def _loops_seeds(light, b) -> bool:
    """Whether ``light``'s shadow rays from batch ``b`` are cast in a loop over the seeds
    (:meth:`Integrator._seed_loop`): a sampled light, from lanes that carry several."""
    return not light.delta and b.sums() > 1


def default_group() -> int:
    """K for a scene with a mesh on this machine's LLVM backend (:data:`GROUPS`)."""
    return GROUPS.get(backend.llvm_vector_width(), GROUP_ELSEWHERE)


@dataclass
class RenderResult:
    """An image (H x W x 3, float32, linear radiance) and what it cost."""
    image: np.ndarray
    spp: int
    seconds: float = 0.0
    rays_per_level: list[int] = field(default_factory=list)
    shadow_rays_per_level: list[int] = field(default_factory=list)
    #: rays per level whose weight (in any channel) exceeds SIGNIFICANT_WEIGHT
    significant_rays_per_level: list[int] = field(default_factory=list)
    #: with ``moments``: variance of each pixel mean, (E[x^2] - E[x]^2) / spp
    variance: np.ndarray | None = None

    @property
    def rays_total(self) -> int:
        return sum(self.rays_per_level) + sum(self.shadow_rays_per_level)


@dataclass
class _Batch:
    """Rays of one recursion level: state carried from level to level.

    Only what a level cannot recompute is carried (and copied by each level's
    compaction): the ray, its weight, its sample's slot in the chunk and, with
    an expression, its automaton state. The pixel and the sample within it
    follow from the slot, since a chunk holds ``spp`` consecutive samples per
    pixel from pixel ``first``; rays after the first level have no tmax.
    """
    o: object
    d: object
    weight: object
    slot: object    # index of the sample in the chunk's radiance buffer
    state: object = None  # light-path-expression DFA state (only with an expression)
    first: int = 0  # the chunk's first pixel
    spp: int = 1
    tmax: object = None  # None: unbounded
    #: the render's seeds: one, or several (Integrator.render_seeds), each pixel then
    #: holding spp samples of each in turn, or, with ``shared``, each lane carrying
    #: every seed (its ray tree traced once, its light summed per seed)
    seeds: tuple = (0,)
    shared: bool = False

    FIELDS = ("o", "d", "weight", "slot", "state")

    def pixel_and_sample(self):
        """(global pixel index, sample index within the pixel) of each ray's sample."""
        return pixel_and_sample(self.slot, self.spp, self.first)

    def light_sample(self, n: int, depth, light: int, max_depth: int):
        """:func:`tracer.sampling.light_sample` of each ray's sample, with the seed of the
        ray's sample."""
        if len(self.seeds) == 1:
            return light_sample(*self.pixel_and_sample(), n, self.seeds[0], depth, light,
                                max_depth)
        pixel, s, k = pixel_seed_and_sample(self.slot, self.spp, len(self.seeds), self.first)
        return light_sample(pixel, s, n, self.seeds, depth, light, max_depth, which=k)

    def sums(self) -> int:
        """How many sums of light each lane keeps: one per seed with ``shared``, else one."""
        return len(self.seeds) if self.shared else 1

    def size(self) -> int:
        return dr.width(self.slot)

    def like(self, fields: list) -> _Batch:
        """A batch of this chunk with other field values (in FIELDS order)."""
        return _Batch(*fields, first=self.first, spp=self.spp, seeds=self.seeds,
                      shared=self.shared)

    def gather(self, index) -> _Batch:
        return self.like([None if getattr(self, f) is None else
                          dr.gather(type(getattr(self, f)), getattr(self, f), index)
                          for f in self.FIELDS])

    def split(self, cap: int) -> list[_Batch]:
        n = self.size()
        if n <= cap:
            return [self]
        return [self.gather(dr.arange(jit.UInt32, a, min(a + cap, n))) for a in range(0, n, cap)]


class _Radiance:
    """A chunk's radiance per sample: the camera level writes it, later levels add to it.

    The camera level holds every sample once, in slot order, so its light is the
    buffer itself; adding it with a scatter would cost a cleared buffer, a
    per-thread copy and a reduction for nothing. With K rays a lane
    (:attr:`Integrator.group`) the level's kernel writes K parts, lane j's ray k
    being sample j K + k, and :meth:`commit` gathers them into sample order in
    one small kernel (K scatters into one buffer each ran in a kernel of its
    own, every one tracing the whole level again). A later level's light is
    evaluated with the level's kernel and added by a scatter of its own
    (:meth:`commit`): on the CPU, with the scatter-add inside it, the level
    kernels of Heckbert's scene (256x256, 16 spp, DEPTH 25) took 0.33 s a
    render; without it 0.20 s, and the separate scatters 0.11 s (Dr.Jit's kernel
    history, as ``benchmarks/bench_speed.py recursion`` prints it).

    That scatter adds only the rays that found light (at a mirror or glass
    surface most find none), each by an atomic add into the buffer
    (``ReduceMode.Direct``). Dr.Jit's default on the CPU gives each thread a
    cleared copy of the buffer and sums the copies afterwards, which cost about
    2.5 ms a level at 2^19 samples, more than the adds themselves. Measured at
    320x240, 64 spp (median of 3): glass_sphere 0.35 -> 0.25 s, whitted_1980
    0.42 -> 0.28 s, tir_prisms 0.48 -> 0.36 s, emitter_in_glass unchanged.
    """

    def __init__(self):
        self.value = None
        self._pending = None
        self._parts = None   # the camera level's light, a part per ray of a lane

    def add(self, contribs: list, slots: list) -> None:
        """Add a level's light: one contrib and slot array per batch of the level (the
        camera level's K rays a lane are K batches, one a later level's)."""
        if self.value is None and self._parts is None:  # the camera level: slots 0, .., n - 1
            if len(contribs) == 1:  # in order
                self.value = contribs[0] + 0  # a variable of its own (may be a literal)
            else:  # lane j's K rays are the samples j K, ..., j K + K - 1
                # Evaluated by the level's kernel, then put in slot order by commit() (a
                # gather from them before that would evaluate each in a kernel of its own).
                self._parts = [c + 0 for c in contribs]
        else:
            (contrib,), (slot,) = contribs, slots
            self._pending = (contrib, slot)

    def outputs(self) -> tuple:
        """What the level's kernel must evaluate."""
        if self._pending is not None:
            return (self._pending[0],)
        return (self.value,) if self._parts is None else tuple(self._parts)

    def commit(self) -> None:
        if self._parts is not None:
            k = len(self._parts)
            i = dr.arange(jit.UInt32, k * dr.width(self._parts[0]))
            self.value = _own_child(self._parts, i % k, i // k)
            self._parts = None
            dr.eval(self.value)   # one kernel for the three channels
        if self._pending is not None:
            contrib, slot = self._pending
            self._pending = None
            dr.scatter_reduce(dr.ReduceOp.Add, self.value, contrib, slot, dr.any(contrib != 0),
                              mode=dr.ReduceMode.Direct)


def _chunk_spans(total: int, per_chunk: int, tail: int) -> list[tuple[int, int]]:
    """(first, count) of each chunk of ``total`` pixels: ``per_chunk`` pixels each, except
    that a remainder of at most ``tail`` pixels joins the chunk before it. Each chunk's
    kernel is traced anew from Python (about 15 ms at 2^22 samples), however few its
    samples: 640 x 480 at 16 spp in chunks of 2^22 samples left a last chunk of 17 %,
    and one chunk of the whole rendered the 1,000,000-triangle knot 17 ms faster, the
    instanced torus 16 ms (the kernels' own time the same; a throwaway script, four
    renders each)."""
    spans = [(first, min(per_chunk, total - first)) for first in range(0, total, per_chunk)]
    if len(spans) > 1 and spans[-1][1] <= tail:
        (first, count), (_, rest) = spans[-2], spans.pop()
        spans[-1] = (first, count + rest)
    return spans


def _split_index(i, n: int, k: int):
    """(i // n, i % n) for i < k n, by comparisons: a vector integer division costs more."""
    which = dr.zeros(jit.UInt32, dr.width(i))
    for m in range(1, k):
        which += dr.select(i >= m * n, jit.UInt32(1), jit.UInt32(0))
    return which, i - which * n


def _own_child(values: list, which, j):
    """Per lane, ``values[which][j]``: each lane reads (a masked gather) from its own child only."""
    t = type(values[0])
    v = dr.gather(t, values[0], j, which == 0)
    for k in range(1, len(values)):
        mine = which == k
        v = dr.select(mine, dr.gather(t, values[k], j, mine), v)
    return v


def _compact(children: list) -> _Batch | None:
    """The next level: the kept rays of every child batch, in order, in two kernels.

    Children are (batch, keep) pairs of equal width n; one compress over their
    keep masks read as a single array of width k n gives the kept positions, and
    one kernel gathers every field from the child each position falls in.
    """
    n, k = children[0][0].size(), len(children)
    masks = [keep for _, keep in children]
    if k == 1:  # the mask itself: no kernel to read it as one array
        idx = dr.compress(masks[0])
    else:
        idx = dr.compress(_own_child(masks, *_split_index(dr.arange(jit.UInt32, n * k), n, k)))
    if dr.width(idx) == 0:
        return None
    which, j = _split_index(idx, n, k)
    out = [None if getattr(children[0][0], f) is None else
           _own_child([getattr(c, f) for c, _ in children], which, j)
           for f in _Batch.FIELDS]
    dr.eval(*(x for x in out if x is not None))
    return children[0][0].like(out)


class Integrator:
    """Renders one validated scene; construct once, render any number of times."""

    def __init__(self, scene: Scene, seed: int = 0, chunk_samples: int | None = None,
                 lpe: str | None = None, min_weight: float = 0.0, offset_scale: float = 1.0,
                 schedule: str = "auto", group: int | None = None):
        backend.use()
        from whitted.tracer.limits import check_render

        check_render(scene, moments=False)
        self.scene = scene
        #: any integer; the streams use its 32-bit form (tracer.sampling.seed32)
        self.seed = seed32(seed)
        #: Scale of the distance new rays start off their surface (``spawn_offset``: a
        #: fixed number of float32 ulps of the position). Below 1 it trusts the
        #: intersection routines more (spheres are accurate to a few ulps); a diagnostic,
        #: e.g. to show which values that differ from a double-precision tracer come from
        #: this offset.
        self.offset_scale = float(offset_scale)
        #: Branches whose weight is at most this are dropped. 0 (exact Whitted) drops only
        #: zero-weight branches; a positive value is a biased speed-up.
        self.min_weight = float(min_weight)
        self.dfa = None
        if lpe is not None:
            from whitted.tracer.lpe import ALPHABET, compile_lpe

            self.dfa = compile_lpe(lpe)
            self.dfa_trans = jit.UInt32([t for row in self.dfa.transitions for t in row])
            self.dfa_accept = jit.Bool(list(self.dfa.accepting))
            self._letter = {c: i for i, c in enumerate(ALPHABET)}
        self.geo = Geometry(scene)
        self.materials = SceneMaterials(list(scene.materials.values()))
        self.emitters = scene_emitters(scene.lights, self.geo.emitters, scene.shape_lights())
        self.backgrounds = [e for e in self.emitters if e.infinite]
        #: Lights sampled at shading points (a backdrop that is only seen is not).
        self.illuminating = [e for e in self.emitters if e.illuminates]
        #: Whether a ray of the last segment (depth == max_depth) can add anything: an area
        #: light it hits, or a background that is not a hit term. If not, such rays are not
        #: traced at all (Heckbert's DEPTH counts exactly the rays it traces).
        self.last_level_sees = bool(self.geo.emitters) or any(
            not e.hit_term for e in self.backgrounds)
        if chunk_samples is None:  # on a CPU, bounded for deep scenes (limits.chunk_samples)
            from whitted.tracer.limits import chunk_samples as cpu_chunk

            chunk_samples = ((1 << 24) if backend.name() == "cuda" else
                             cpu_chunk(scene.film.max_depth, self.materials.has_delta))
        self.chunk_samples = chunk_samples
        #: Where no ray spawns another, the last chunk takes in a remainder of up to this
        #: many samples rather than leaving it a chunk of its own (tracer.limits.flat_tail).
        self.tail_samples = 0 if self.materials.has_delta else flat_tail(chunk_samples)
        if schedule not in SCHEDULES:
            raise ValueError(f"schedule must be one of {', '.join(SCHEDULES)}, not {schedule!r}")
        if schedule == "auto":
            schedule = "stack" if self.materials.has_delta and scene.film.max_depth > 2 \
                else "wavefront"
        #: "wavefront" (a kernel a level, :meth:`_level`) or "stack" (a kernel a chunk,
        #: :meth:`_render_stack`)
        self.schedule = schedule
        if group is None:
            # Measured on the CPU only; a GPU (none was lent) keeps one ray a thread.
            group = default_group() if self.geo.has_mesh and backend.name() == "llvm" else 1
        if group < 1:
            raise ValueError(f"group must be at least 1, not {group}")
        #: Camera rays a lane in the wavefront schedule: the K samples of a pixel that a
        #: lane traces together through a mesh's BVH (:meth:`Geometry.closest_hit_group`).
        self.group = int(group)

    # ------------------------------------------------------------------ one level

    def _level(self, bs: list, depth: int, L: _Radiance) -> tuple[_Batch | None, object]:
        """Trace one level, the rays of a lane given as a list of batches (one, or the
        camera level's K rays a lane, :attr:`Integrator.group`); add its light to L;
        return the next level and the level's tally.

        The tally (a UInt64 array of one element, read when the render ends, so
        that no level waits for it) holds the shadow rays cast in its high 32 bits
        and the rays whose weight is significant in its low 32 bits.
        """
        contribs, shadow_masks, children = self._shade(bs, depth)
        L.add([c for c, in contribs], [b.slot for b in bs])   # one seed a lane
        # The level's statistics as one count per lane, summed without waiting for them:
        # the shadow rays cast (high 32 bits) and whether the ray mattered (low bit).
        # Camera rays all have weight 1, so all matter: their lanes count only shadow
        # rays, in 32 bits where the sum fits (half the memory of the 64-bit tally; on
        # three_lights, 800x480, 64 spp, the tally was about 6 % of the render).
        n = bs[0].size()
        masks = [m for ms in shadow_masks for m in ms]
        narrow = bs[0].tmax is not None and len(masks) * n < (1 << 32)  # the camera's
        if narrow:
            tally = dr.zeros(jit.UInt32, n)
            for m in masks:
                tally += dr.select(m, jit.UInt32(1), jit.UInt32(0))
        else:
            tally = dr.zeros(jit.UInt64, n)
            for b in bs:
                tally += dr.select(dr.max(b.weight) > SIGNIFICANT_WEIGHT, jit.UInt64(1),
                                   jit.UInt64(0))
            for m in masks:
                tally += dr.select(m, jit.UInt64(1 << 32), jit.UInt64(0))
        # One kernel: intersection, shading, shadow rays and the next level's rays.
        dr.eval(*L.outputs(), tally, *(x for c, keep in children or ()
                                       for x in (c.o, c.d, c.weight, keep, c.state)
                                       if x is not None))
        L.commit()
        total = dr.sum(tally)
        if narrow:  # shadow rays in the high bits; all rays matter
            # (the count an input, so that every film size shares this small kernel)
            total = (jit.UInt64(total) << 32) | dr.opaque(jit.UInt64, n * len(bs))
        return (None if children is None else _compact(children)), total

    def _shade(self, bs: list, depth, active=True, limit=None) -> tuple[list, list,
                                                                        list | None]:
        """The light a group of batches of rays finds, and the rays they spawn: (contribs,
        shadow masks, children), each of the first two a list with an entry per batch:
        contribs a list of one light per seed a lane carries (:meth:`_Batch.sums`), shadow
        masks a list; children being (batch, keep) pairs (of all the batches) or None.

        ``bs`` holds the K rays of each lane, as K batches of one width: the rays of
        one lane are traced together, as a packet (:meth:`Geometry.closest_hit_group`),
        and so are their shadow rays to each light; everything else is done for each
        ray on its own, the same operations as with K = 1.

        A lane that carries several seeds (``b.shared``) shades once and samples each
        sampled light once per seed, adding each seed's light to its own sum; what no
        seed changes (emission, point lights, backgrounds) is added to every sum. Each
        sum is then, operation for operation, the light a render with that seed alone
        adds.

        ``depth`` is the batch's level, an int (the wavefront: every ray at one level), or
        a jit.UInt32 per ray (:meth:`_render_stack`: rays at many levels in one kernel,
        one batch), where what an int decides for the whole batch becomes a mask per ray,
        against ``limit``, max_depth as a jit.UInt32 (opaque, so that one kernel serves
        every max_depth that :meth:`_render_stack` rounds to the same size). Rays outside
        ``active`` are not traced.
        """
        scene, geo = self.scene, self.geo
        per_ray = not isinstance(depth, int)
        max_depth = limit if per_ray else scene.film.max_depth
        hits = geo.closest_hit_group([(b.o, b.d, dr.inf if b.tmax is None else b.tmax,
                                       active) for b in bs])
        surfs = [geo.surface(hit, b.o, b.d) for hit, b in zip(hits, bs, strict=True)]
        valids = tuple(hit.valid for hit in hits)
        S = bs[0].sums()
        contribs = [self._seen(b, hit, surf, depth, max_depth)
                    for b, hit, surf in zip(bs, hits, surfs, strict=True)]

        children = None
        shadow_masks = [[] for _ in bs]
        if per_ray or depth < max_depth:
            # The shading of the rays that hit something. At the camera level of a scene
            # without mirrors or glass it runs as a symbolic if, which a SIMD packet of
            # rays that all missed (sky) skips: three_lights, where 29 % of the camera
            # rays miss, 0.20 s to 0.18 s (800x480, 64 spp); phong_lobes and sphere_point
            # 15 % faster at 320x240. With child rays to return, the if's merge of every
            # output costs more than it saves (emitter_in_glass 8 % slower, tir_prisms
            # 2.4x slower when later levels used it too), so there it runs unconditionally.
            def shade(valids):
                adds, masks, kids, points = [], [], [], []
                for b, hit, surf, valid in zip(bs, hits, surfs, valids, strict=True):
                    add, point = self._hit_point(b, hit, surf, valid, S)
                    adds.append(add)
                    points.append(point)
                    masks.append([])
                if self.materials.has_smooth:
                    # The lights' samples of each ray, light after light; the K rays of
                    # a lane cast their shadow rays to one light together.
                    samples = [list(self._light_samples(b, depth)) for b in bs]
                    for j in range(len(samples[0])):
                        if samples[0][j][2] == SEED_LOOP:   # one ray a lane, S seeds
                            light = samples[0][j][0]
                            direct, cast = self._seed_loop(bs[0], points[0], light, depth)
                            adds[0] = [a + d for a, d in zip(adds[0], direct, strict=True)]
                            masks[0].append(cast)
                            continue
                        rays, rest = [], []
                        for b, point, sample in zip(bs, points, samples, strict=True):
                            light, u, _ = sample[j]
                            ray, unblocked = self._shadow_ray(b, point, light, u)
                            rays.append(ray)
                            rest.append(unblocked)
                        blocked = geo.occluded_group(rays)
                        for i in range(len(bs)):
                            k = samples[i][j][2]
                            ray_active = rays[i][3]
                            direct = dr.select(ray_active & ~blocked[i], rest[i], 0)
                            adds[i] = [a + direct if m == k or k < 0 else a
                                       for m, a in enumerate(adds[i])]
                            masks[i].append(ray_active)
                if self.materials.has_delta:
                    for b, point in zip(bs, points, strict=True):
                        si, mats, off = point[0], point[1], point[2]
                        if per_ray:  # the rays of the last segment only where they can add
                            kid = self._delta(b, mats, si, off)
                            if not self.last_level_sees:
                                kid = [(c, keep & (depth + 1 < max_depth)) for c, keep in kid]
                            kids += kid
                        elif depth + 1 < max_depth or self.last_level_sees:
                            kids += self._delta(b, mats, si, off)
                return (tuple(tuple(a) for a in adds), tuple(tuple(m) for m in masks),
                        kids or None)

            # Per batch, the shadow rays' entries of shade()'s masks: a mask per shadow
            # ray, or a count per seed loop.
            casts = ([jit.UInt32 if _loops_seeds(light, bs[0]) else jit.Bool
                      for light in self.illuminating] if self.materials.has_smooth else [])

            def unlit(m):  # the outputs of shade() where nothing is shaded
                return (tuple(tuple(dr.zeros(jit.Array3f, m) for _ in range(S)) for _ in bs),
                        tuple(tuple(dr.zeros(t, m) for t in casts) for _ in bs))

            b = bs[0]
            if per_ray:
                # In the stack's loop the if pays even with child rays: a SIMD packet whose
                # rays all missed (or all ended) skips the shading and pops its next rays.
                # Heckbert's scene at DEPTH 25: 113-115 to 127-128 M rays/s; at 320x240,
                # 64 spp: whitted_1980 0.272-0.282 to 0.248-0.250 s, emitter_in_glass
                # 0.289-0.296 to 0.255-0.261 s, glass_sphere 0.235 to 0.233 s (alternating
                # runs, benchmarks/bench_scenes.py). Child batches pass through the if as
                # flat fields.
                if len(bs) != 1:
                    raise ValueError("the stack schedule shades one ray a lane")
                width = 4 + (self.dfa is not None)

                def hit_fn(v):
                    add, masks, kids = shade(v)
                    return add, masks, tuple(x for c, keep in kids or () for x in (
                        c.o, c.d, c.weight, keep, c.state) if x is not None)

                def miss_fn(v):
                    m = b.size()
                    kid = [dr.zeros(jit.Array3f, m)] * 3 + [dr.zeros(jit.Bool, m)]
                    kid += [dr.zeros(jit.UInt32, m)] if self.dfa is not None else []
                    return (*unlit(m), tuple(kid * self.materials.delta_slots
                                             if self.materials.has_delta else ()))

                sh = valids[0] & (depth < max_depth)
                add, masks, flat = dr.if_stmt(((sh,),), sh, hit_fn, miss_fn)
                children = [(b.like([*flat[i:i + 3], b.slot,
                                     flat[i + 4] if width == 5 else None]), flat[i + 3])
                            for i in range(0, len(flat), width)]
            elif b.tmax is not None and not self.materials.has_delta:
                add, masks = dr.if_stmt((valids,), any_mask(valids), lambda v: shade(v)[:2],
                                        lambda v: unlit(b.size()))
            else:
                add, masks, children = shade(valids)
            contribs = [[c + a for c, a in zip(contrib, ad, strict=True)]
                        for contrib, ad in zip(contribs, add, strict=True)]
            shadow_masks = [list(m) for m in masks]
        return contribs, shadow_masks, children

    def _seen(self, b: _Batch, hit: Hit, surf, depth, max_depth) -> list:
        """The light a batch's rays see directly, a list of one per sum a lane carries:
        an area light's emission on its front side, the backgrounds where they miss."""
        geo = self.geo
        per_ray = not isinstance(depth, int)
        valid = hit.valid
        cos_o = -dr.dot(surf.n, b.d)              # > 0: the ray arrives on the front side
        contrib = [dr.zeros(jit.Array3f, b.size()) for _ in range(b.sums())]
        if geo.emitters:
            le, seen = area.emitted(geo.radiance, hit.prim, cos_o, valid)
            if self.dfa is not None:  # the light is the path's L: ... E + L
                seen &= self._accepts(self._step(b.state, "L"))
            term = dr.select(seen, b.weight * le, 0)
            contrib = [c + term for c in contrib]
        if self.backgrounds:  # lights at infinity, seen by the rays that escape
            missed = ~valid
            if self.dfa is not None:
                missed &= self._accepts(self._step(b.state, "L"))
            for light in self.backgrounds:
                gate = missed
                if light.hit_term:  # a hit term, counted only where rays are still shaded
                    if per_ray:
                        gate = missed & (depth < max_depth)
                    elif depth >= max_depth:
                        continue
                term = dr.select(gate, b.weight * light.background(b.d), 0)
                contrib = [c + term for c in contrib]
        return contrib

    def _hit_point(self, b: _Batch, hit: Hit, surf, valid, S: int) -> tuple:
        """At each valid hit: (the emission of its material, a list of one per sum, and
        the point: (si, mats, off, p_front, lit)) for the lights and the delta lobes."""
        geo = self.geo
        p, n, n_sh = surf.p, surf.n, surf.ns
        cos_o = -dr.dot(n, b.d)
        add = [dr.zeros(jit.Array3f, b.size()) for _ in range(S)]
        mid = dr.gather(jit.UInt32, geo.material_id, hit.prim, valid)
        # Two-sided: shading happens on the side the ray arrives from (judged, as
        # Mitsuba's twosided BSDF does, by the shading normal); ray origins move off
        # the surface along the geometric normal.
        cos_sh = -dr.dot(n_sh, b.d)
        nl = dr.select(cos_sh >= 0, n_sh, -n_sh)
        nl = faults.pick("backface-not-flipped", lambda: n_sh, nl)
        ng = dr.select(cos_o >= 0, n, -n)
        off = spawn_offset(p)
        if self.offset_scale != 1.0:
            off = off * self.offset_scale
        p_front = dr.fma(ng, off, p)
        si = ShadingPoint(p, n, n_sh, surf.uv, b.d, nl, ng, cos_sh)
        mats = self.materials.at(mid, si, valid)
        lit = mats.smooth
        if self.dfa is not None:  # light at a diffuse vertex: ... E + D + L
            # Not &=: Dr.Jit updates in place, and lit may be a kind's own lane mask.
            lit = lit & self._accepts(self._steps(b.state, "DL"))
        for mask, value, letters in mats.emission():
            gate = mask
            if self.dfa is not None:
                gate = gate & self._accepts(self._steps(b.state, letters))
            term = dr.select(gate, b.weight * value, 0)
            add = [a + term for a in add]
        return add, (si, mats, off, p_front, lit)

    def _shadow_ray(self, b: _Batch, point, light, u) -> tuple:
        """A hit's shadow ray to one light, (o, d, tmax, active), and the light it brings
        where nothing blocks it (lecture 1, "The illumination equation")."""
        si, mats, off, p_front, lit = point
        p, n, nl = si.p, si.n, si.nl
        wi, dist, e = light.sample(p, p_front, u)
        cos = lights.lambert_cosine(nl, wi)
        f = mats.eval(wi)
        active = lit & (cos > 0) & (dr.max(e) > 0)
        # Leave the surface on the side the shadow ray goes to (as Mitsuba's
        # spawn_ray_to does): with interpolated normals a lit direction can lie
        # behind the geometric surface near a shadow terminator.
        origin = dr.fma(dr.select(dr.dot(n, wi) >= 0, n, -n), off, p)
        # the bug: no offset, the shadow ray may hit its own surface
        origin = faults.pick("shadow-acne", lambda: p, origin)
        d_shadow, length = light.shadow_ray(p, origin, wi, dist)
        tmax = length * (1 - SHADOW_EPSILON)
        tmax = faults.pick("shadow-ray-past-light", lambda: dr.full(jit.Float, dr.inf, dr.width(p)),
                           tmax)
        return (origin, d_shadow, tmax, active), b.weight * f * e * cos

    def _light_samples(self, b: _Batch, depth):
        """(light, sample, which sum) for each light's shadow rays, in the lights' order:
        a light no seed changes (a delta light), with which = -1 (its light goes to every
        sum); a sampled light with its sample and -1 where the lane carries one seed,
        else with no sample and :data:`SEED_LOOP` (:meth:`_seed_loop` casts one shadow
        ray per seed)."""
        film = self.scene.film
        for light in self.illuminating:
            if light.delta:
                yield light, None, -1
            elif _loops_seeds(light, b):
                yield light, None, SEED_LOOP
            else:
                yield light, b.light_sample(film.strata, depth, light.index, film.max_depth), -1

    def _seed_loop(self, b: _Batch, point, light, depth) -> tuple[list, object]:
        """A lane that carries S seeds (shared ray trees): the shadow rays of a sampled
        light, one seed a pass of a symbolic loop, each with that seed's sample.

        Returns (the light each seed's sum gains, the shadow rays cast a lane). The light
        of seed k is kept in local memory at 3k..3k+2 (k is the same in every lane, so
        Dr.Jit reads and writes it as one vector) and added to sum k afterwards: the
        same operations, in the same order, as with the seed's sample written into the
        kernel once per seed, so each sum stays bit for bit the render of its seed
        (``tests/tracer/test_schedules.py``). Written out per seed, a kernel held S
        shadow-ray tests of every light: the report's pooled renders of 16 seeds were
        its largest kernels (about 11,000-15,000 operations, 1.3-1.7 s of LLVM each on
        an AVX2 CPU; ``python benchmarks/bench_seeds.py`` prints both ways).
        """
        film = self.scene.film
        S, n = b.sums(), b.size()
        pixel, s = b.pixel_and_sample()
        light_of = dr.alloc_local(jit.Float, 3 * S, jit.Float(0))

        def body(k, cast, light_of):
            u = light_sample(pixel, s, film.strata, b.seeds, depth, light.index,
                             film.max_depth, which=k)
            ray, unblocked = self._shadow_ray(b, point, light, u)
            blocked, = self.geo.occluded_group([ray])
            direct = dr.select(ray[3] & ~blocked, unblocked, 0)
            for c in range(3):
                light_of[k * 3 + c] = direct[c]
            return k + 1, cast + dr.select(ray[3], jit.UInt32(1), jit.UInt32(0)), light_of

        _, cast, light_of = dr.while_loop(
            (dr.zeros(jit.UInt32, n), dr.zeros(jit.UInt32, n), light_of),
            lambda k, cast, light_of: k < S, body, labels=("k", "cast", "light_of"))
        return [jit.Array3f(*(light_of[3 * k + c] for c in range(3))) for k in range(S)], cast

    def _render_stack(self, b: _Batch) -> tuple[object, object]:
        """A chunk's radiance per sample (a tuple: one per seed a lane carries) and its
        counts, every level in one kernel.

        Each lane follows its sample's ray tree depth first: a loop traces and shades
        one ray a pass (:meth:`_shade`, the wavefront's shading), goes on with the first
        child ray it keeps and pushes the others onto a stack of its own in local memory
        (:func:`drjit.alloc_local`), and pops one when a ray keeps none. The tree of
        a sample is the wavefront's, ray for ray; only the order in which its light is
        summed differs. There is no compaction, no atomic add of a level's light and
        no kernel a level: on Heckbert's scene at DEPTH 25 (256x256, 16 spp), the
        wavefront ran 684 kernels a render.

        A push and a pop each run in a symbolic if, which a SIMD packet with no lane
        pushing (popping) skips: local memory indexed per lane costs a masked
        scatter (gather) of 16 lanes for each of the ray's 10 values, and Dr.Jit's
        test first whether all lanes index one place. On Heckbert's scene, where a
        glass hit pushes and a ray that escapes pops, ``benchmarks/bench_speed.py
        recursion`` went from 149.2 and 145.8 to 168.6 and 168.1 M rays/s (runs
        alternating with the unguarded stack).

        A lane keeps at most ``slots - 1`` rays pending per level below it, so the stack
        holds (slots - 1) max_depth rays (it has room for (slots - 1) ``levels``). The
        counts (rays, significant rays and shadow rays of each level) are summed per
        lane in local memory, added per SIMD packet with one scatter each after the
        loop, and summed per level by the caller: a jit.UInt32 of 3 x ``levels``
        values, (rays, significant, shadow) of level 1, then of level 2, ...

        The stack and the counts are sized for ``levels``, max_depth rounded up to a
        multiple of 8, and max_depth enters the kernel as an opaque value: one kernel
        serves max_depth 1 to 8, another 9 to 16, and so on. A depth sweep of 60
        depths then compiles 8 kernels, not 60 (each about 0.3 s on the CPU here).
        """
        max_depth = self.scene.film.max_depth
        levels = -(-max_depth // 8) * 8
        limit = dr.opaque(jit.UInt32, max_depth)
        n = b.size()
        cap = max(1, (self.materials.delta_slots - 1) * levels)
        dfa = self.dfa is not None
        NF = 9  # o, d, weight
        pend_f = dr.alloc_local(jit.Float, NF * cap, jit.Float(0))
        pend_u = dr.alloc_local(jit.UInt32, 2 * cap, jit.UInt32(0))  # level, DFA state
        counts = dr.alloc_local(jit.UInt32, 3 * levels, jit.UInt32(0))
        state0 = b.state if dfa else dr.zeros(jit.UInt32, n)
        loop_state = (dr.full(jit.Bool, True, n), dr.zeros(jit.UInt32, n),
                      dr.full(jit.UInt32, 1, n), jit.Float(b.tmax), jit.Array3f(b.o),
                      jit.Array3f(b.d), jit.Array3f(b.weight), jit.UInt32(state0),
                      tuple(dr.zeros(jit.Array3f, n) for _ in range(b.sums())), pend_f, pend_u,
                      counts)
        one, zero = jit.UInt32(1), jit.UInt32(0)

        def body(alive, sp, depth, tmax, o, d, w, st, L, pend_f, pend_u, counts):
            cur = b.like([o, d, w, b.slot, st if dfa else None])
            cur.tmax = tmax
            (contrib,), (masks,), kids = self._shade([cur], depth, alive, limit)
            L = tuple(x + dr.select(alive, c, 0) for x, c in zip(L, contrib, strict=True))
            base = (depth - 1) * 3
            sig = dr.select(dr.max(w) > SIGNIFICANT_WEIGHT, one, zero)
            shadows = zero
            for m in masks:   # a mask per shadow ray, or a seed loop's count
                shadows = shadows + (m if isinstance(m, jit.UInt32) else dr.select(m, one, zero))
            for k, v in enumerate((one, sig, shadows)):
                counts.write(counts.read(base + k, alive) + v, base + k, alive)
            # The first child kept goes on; the others wait on the stack.
            have = dr.zeros(jit.Bool, n)
            for c, keep in kids or ():
                keep = alive & keep
                push = keep & have
                def pushed(pend_f, pend_u, c=c, push=push, sp=sp):  # called at once
                    for j, x in enumerate((*c.o, *c.d, *c.weight)):
                        pend_f.write(x, sp * NF + j, push)
                    pend_u.write(depth + 1, sp * 2, push)
                    if dfa:
                        pend_u.write(c.state, sp * 2 + 1, push)
                    return pend_f, pend_u

                pend_f, pend_u = dr.if_stmt((pend_f, pend_u), push, pushed, lambda *a: a)
                sp = dr.select(push, sp + 1, sp)
                take = keep & ~have
                o, d, w = (dr.select(take, x, y) for x, y in ((c.o, o), (c.d, d), (c.weight, w)))
                if dfa:
                    st = dr.select(take, c.state, st)
                have = have | keep
            depth = dr.select(have, depth + 1, depth)
            # None kept: the ray pushed last, or the end of this sample's tree.
            pop = alive & ~have & (sp > 0)
            sp = dr.select(pop, sp - 1, sp)
            def popped(o, d, w, depth, st, pend_f, pend_u):
                f = [pend_f.read(sp * NF + j, pop) for j in range(NF)]
                depth = pend_u.read(sp * 2, pop)
                if dfa:
                    st = pend_u.read(sp * 2 + 1, pop)
                return (jit.Array3f(*f[0:3]), jit.Array3f(*f[3:6]), jit.Array3f(*f[6:9]),
                        depth, st, pend_f, pend_u)

            o, d, w, depth, st, pend_f, pend_u = dr.if_stmt(
                (o, d, w, depth, st, pend_f, pend_u), pop, popped, lambda *a: a)
            tmax = dr.select(have | pop, dr.inf, tmax)
            return (have | pop, sp, depth, tmax, o, d, w, st, L, pend_f, pend_u, counts)

        out = dr.while_loop(loop_state, lambda alive, *_: alive, body)
        L, counts = out[8], out[11]
        # Per-packet sums of the lanes' counts, level-major, then one sum a count.
        packets = (n + 15) // 16
        total = dr.zeros(jit.UInt32, 3 * levels * packets)
        # The chunk's size is not written into the kernel (opaque), so that chunks of
        # every size share it: a literal here made each image size compile its own.
        stride = dr.opaque(jit.UInt32, packets)
        packet = b.slot >> 4
        if levels <= UNROLLED_LEVELS:
            for j in range(3 * levels):
                dr.scatter_reduce(dr.ReduceOp.Add, total, counts.read(j), j * stride + packet,
                                  mode=dr.ReduceMode.Local)
        else:
            # One scatter a count written out would make a kernel whose build grows faster
            # than its size: LLVM took 7 s for 912 of them (max_depth 304) and about 38 s
            # for 3,000 (max_depth 1000; more than 120 s on a busy machine); a loop over
            # the counts builds in constant time (the whole render then takes 1.5 s).
            def add(j, counts):
                dr.scatter_reduce(dr.ReduceOp.Add, total, counts.read(j), j * stride + packet,
                                  mode=dr.ReduceMode.Local)
                return j + 1, counts

            dr.while_loop((dr.zeros(jit.UInt32, n), counts),
                          lambda j, _: j < 3 * levels, add)
        dr.eval(*L, total)
        return L, dr.block_sum(jit.UInt64(total), packets)

    def _delta(self, b: _Batch, mats, si: ShadingPoint, off) -> list:
        """The next level's rays: one batch per delta-lobe slot, and which of them to keep."""
        states: dict = {}
        out = []
        for slot in mats.delta_lobes(b.weight):
            w = slot.weight
            state = None
            if self.dfa is not None:  # a specular vertex: ... + S; dead states carry nothing
                for letter, mask in slot.letters.items():
                    if letter not in states:
                        states[letter] = self._steps(b.state, letter)
                    state = (states[letter] if state is None else
                             dr.select(mask, states[letter], state))
                w = dr.select(state != 0, w, 0)
            # Origins leave the surface on the side each new direction goes to.
            side = dr.select(dr.dot(si.ng, slot.d) >= 0, si.ng, -si.ng)
            child = b.like([dr.fma(side, off, si.p), slot.d, w, b.slot, state])
            out.append((child, dr.max(w) > self.min_weight))
        return out

    def _steps(self, state, letters: str):
        """The DFA state after reading ``letters`` (none: unchanged)."""
        for letter in letters:
            state = self._step(state, letter)
        return state

    def _step(self, state, letter: str):
        return dr.gather(jit.UInt32, self.dfa_trans, state * len(self._letter) +
                         self._letter[letter])

    def _accepts(self, state):
        return dr.gather(jit.Bool, self.dfa_accept, state)

    # ------------------------------------------------------------------ the image

    def render(self, progress: Callable[[int, int], None] | None = None,
               moments: bool = False, seed: int | None = None) -> RenderResult:
        """Render the image; ``moments`` also estimates each pixel's variance.

        ``seed``: this render's seed, instead of the one the Integrator was made with (a
        caller that pools seeds builds the scene once).
        """
        seed = self.seed if seed is None else seed32(seed)
        return self._render((seed,), progress, moments)[0]

    def render_seeds(self, seeds, moments: bool = False,
                     progress: Callable[[int, int], None] | None = None) -> list[RenderResult]:
        """One render per seed, each the image :meth:`render` gives with that seed, made
        together: each pixel holds the samples of every seed in turn, so the seeds
        share the kernels' launches, the tracing of the kernels and their chunks.

        For callers that pool seeds (the statistical verdicts' 16 seeds, an imported
        scene's 8): at 160x120 and 64 spp each render was about 30 % launch and
        read-back overhead beside its kernel. Each result's ray counts and seconds
        are those of all seeds together. A gaussian-filtered film renders seed by
        seed (its splat takes one seed's samples).

        Where a seed changes nothing but the light samples (no jitter, no light-path
        expression) and the recursion runs on the stack, the seeds share their ray
        trees: each lane traces its sample's tree once and keeps one sum of light per
        seed, sampling each sampled light once per seed (:meth:`_shade`). The seeds'
        trees are the same ray for ray, so each image is still, bit for bit, that
        seed's own render (``tests/tracer/test_schedules.py``), and the counts are the rays
        actually traced.
        """
        seeds = tuple(seed32(sd) for sd in seeds)
        if len(seeds) <= 1 or self.scene.film.filter != "box":
            return [self._render((sd,), progress, moments)[0] for sd in seeds]
        return self._render(seeds, progress, moments)

    def _shares_trees(self, seeds: tuple) -> bool:
        """Whether :meth:`render_seeds` traces each ray tree once for all ``seeds``."""
        return (len(seeds) > 1 and self.schedule == "stack" and not self.scene.film.jitter
                and self.dfa is None)

    def _camera_batch(self, first: int, count: int, seeds: tuple, shared: bool, idx,
                      width: int) -> tuple:
        """(film x, film y, the batch) of the camera rays ``idx`` (a jit.UInt32; None: all
        of them, in order) of the chunk of ``count`` pixels from pixel ``first``."""
        scene = self.scene
        W, H = scene.film.width, scene.film.height
        n = scene.film.strata
        S = len(seeds)
        if S > 1 and not shared:
            pixel, s, fx, fy, k = pixel_samples(W, n, first, count, S, idx=idx)
            seed = dr.gather(jit.UInt32, jit.UInt32(list(seeds)), k)
        else:
            pixel, s, fx, fy = pixel_samples(W, n, first, count, idx=idx)
            seed = seeds[0]
        if scene.film.jitter:  # a uniform position inside each stratum
            u = jitter_2d(pixel, s, seed)
            fx, fy = fx + (u.x - 0.5) * (1.0 / n), fy + (u.y - 0.5) * (1.0 / n)
        o, d, tmax = generate_rays(scene.camera, W, H, fx, fy)
        slot = dr.arange(jit.UInt32, width) if idx is None else idx
        state = None
        if self.dfa is not None:  # every path ends at the eye: read E first
            state = dr.full(jit.UInt32, self.dfa.step(self.dfa.start, "E"), width)
        return fx, fy, _Batch(o, d, dr.full(jit.Array3f, 1.0, width), slot, state, first,
                              n * n, tmax, seeds, shared)

    def _render(self, seeds: tuple, progress, moments: bool) -> list[RenderResult]:
        """:meth:`render` (one seed) or :meth:`render_seeds` (two or more, box filter):
        a result per seed."""
        scene = self.scene
        W, H = scene.film.width, scene.film.height
        n = scene.film.strata
        spp = n * n
        S = len(seeds)   # samples of S seeds per pixel, spp of each in turn
        shared = self._shares_trees(seeds)   # or spp samples, each carrying the S seeds
        max_depth = scene.film.max_depth
        total = W * H
        # Pixels a chunk: chunk_samples samples, a lane that carries S seeds counting as
        # ceil(S / SEEDS_PER_LANE_SAMPLE) (see there).
        per_lane = -(-S // SEEDS_PER_LANE_SAMPLE) if shared else S
        per_chunk = max(1, self.chunk_samples // (spp * per_lane))
        image = np.zeros((total * S, 3), dtype=np.float32)
        second = np.zeros((total * S, 3), dtype=np.float32) if moments else None
        splat = None if scene.film.filter == "box" else _Splat(scene.film)
        rays = [0] * max_depth
        shadow = [0] * max_depth
        significant = [0] * max_depth
        tallies: list[list] = [[] for _ in range(max_depth)]  # _level's sums, read at the end
        counts: list = []  # _render_stack's sums, read at the end
        start = time.perf_counter()
        for first, count in _chunk_spans(total, per_chunk,
                                         self.tail_samples // (spp * per_lane)):
            # Each chunk is traced in a basic block of its own, so that Dr.Jit's value
            # numbering never merges its constants with those already alive (a light's
            # position, made when the Integrator was), which it did in the first chunk
            # only: the first chunk's kernel then differed from the others' and was
            # compiled apart (issue 33; tests/tracer/test_kernel_cache.py checks it).
            backend.new_scope()
            lanes = count * spp * (1 if shared else S)

            fx, fy, camera = self._camera_batch(first, count, seeds, shared, None, lanes)
            radiance = _Radiance()
            if self.schedule == "stack":
                sums_of_light, sums = self._render_stack(camera)
                radiance.value = sums_of_light if shared else sums_of_light[0]
                counts.append(sums)
            else:
                # The camera level with K rays a lane: lane j holds samples j K to
                # j K + K - 1, of one pixel where K divides spp.
                K = self.group if lanes % self.group == 0 else 1
                cameras = [camera] if K == 1 else [
                    self._camera_batch(first, count, seeds, shared,
                                       dr.arange(jit.UInt32, lanes // K) * K + k, lanes // K)[2]
                    for k in range(K)]
                stack = [(1, cameras)]
                while stack:
                    depth, batches = stack.pop()
                    rays[depth - 1] += sum(b.size() for b in batches)
                    nxt, tally = self._level(batches, depth, radiance)
                    tallies[depth - 1].append(tally)
                    if nxt is not None and depth < max_depth:
                        for part in reversed(nxt.split(self.chunk_samples)):
                            stack.append((depth + 1, [part]))
            if splat is not None:
                splat.add(radiance.value, fx, fy, first, count, spp)
            else:
                # rows: pixel by pixel, and in a pixel seed by seed; one sum of light a
                # lane (its seed's samples in turn), or with shared trees a sum per seed
                seed_sums = radiance.value if shared else (radiance.value,)
                rows = slice(first * S, (first + count) * S)
                for out, sq in ((image, False), (second, True)):
                    if out is None:
                        continue
                    means = [dr.block_sum(L * L if sq else L, spp) * (1.0 / spp)
                             for L in seed_sums]
                    dr.eval(means)
                    view = out[rows].reshape(-1, len(means), 3)
                    for k, m in enumerate(means):
                        view[:, k] = backend.host3(m)
                    del means
                del seed_sums
            # The chunk's buffer is freed before the next chunk allocates its own, which
            # Dr.Jit's allocator then hands the same memory instead of new pages to fault
            # in: the first render of a process (three_lights, 640x480, 64 spp) spent
            # 7-87 ms in its second chunk's kernel against 4 ms, and took 0.21-0.35 s
            # against 0.18-0.19 s.
            del radiance
            if progress is not None:
                progress(first + count, total)
        if counts:  # per level: rays, significant rays, shadow rays (_render_stack)
            per_level = np.sum([x.numpy() for x in counts], axis=0).reshape(-1, 3)[:max_depth]
            rays = [int(x) for x in per_level[:, 0]]
            significant = [int(x) for x in per_level[:, 1]]
            shadow = [int(x) for x in per_level[:, 2]]
        for k, sums in enumerate(tallies):
            for v in (int(x) for x in dr.concat(sums).numpy()) if sums else ():
                shadow[k] += v >> 32
                significant[k] += v & 0xFFFFFFFF
        variance = None
        if splat is not None:
            image, variance = splat.image(moments)
        seconds = time.perf_counter() - start
        while rays and rays[-1] == 0:
            rays.pop()
        if second is not None and splat is None:
            variance = (np.maximum(second - image.astype(np.float64) ** 2, 0) / spp)
            variance = variance.astype(np.float32).reshape(H, W, S, 3)
        image = image.reshape(H, W, S, 3) if splat is None else image[:, :, None]
        return [RenderResult(np.ascontiguousarray(image[:, :, k]), spp, seconds, rays,
                             shadow[:len(rays)] if rays else [], significant[:len(rays)],
                             None if variance is None else
                             np.ascontiguousarray(variance.reshape(H, W, S, 3)[:, :, k]))
                for k in range(S)]


def gaussian_weight(d, stddev: float):
    """Mitsuba's ``gaussian`` reconstruction filter at offsets d (pixels), one axis.

    exp(-d^2 / (2 stddev^2)) - exp(-r^2 / (2 stddev^2)) for |d| < r = 4 stddev,
    else 0: the Gaussian lowered so that it reaches zero at the radius (Mitsuba 3,
    ``src/rfilters/gaussian.cpp``; pbrt-v4 8.8.3 uses the same shift). Weights of
    a pixel are the product of the two axes' weights. ``d``: a Dr.Jit array.
    """
    r = 4 * stddev
    alpha = -1 / (2 * stddev * stddev)
    w = dr.maximum(dr.exp(alpha * d * d) - float(np.exp(alpha * r * r)), 0.0)
    return dr.select(dr.abs(d) < r, w, 0.0)


def tent_weight(d, radius: float):
    """Mitsuba's ``tent`` reconstruction filter at offsets d (pixels), one axis:
    max(0, 1 - |d| / radius) (Mitsuba 3, ``src/rfilters/tent.cpp``, radius 1 by
    default). Weights of a pixel are the product of the two axes' weights."""
    return dr.maximum(1.0 - dr.abs(d) * (1.0 / radius), 0.0)


class _Splat:
    """Sums of weighted samples and of weights per pixel, for a filter wider than a pixel.

    A pixel's value is sum(w L) / sum(w) over the samples within the radius, as
    Mitsuba's ``hdrfilm`` develops its image block (samples only inside the film:
    ``sample_border = false``). Variance (``moments``) is that of a weighted mean of
    independent samples: (E_w[L^2] - E_w[L]^2) sum(w^2) / sum(w)^2.

    The sums are gathered, not scattered: per chunk, one lane per pixel the chunk's
    samples can reach loops over the (2 reach + 1)^2 neighbouring pixels and their
    samples in a fixed order, in float64, so a render is the same at every run (no
    atomic adds in a thread-dependent order).
    """

    def __init__(self, film):
        self.W, self.H, self.stddev = film.width, film.height, film.stddev
        self.filter, self.radius = film.filter, film.radius
        self.reach = int(np.ceil(film.filter_radius))
        #: per pixel: sum w, sum w^2, sum w L (3), sum w L^2 (3)
        self.sums = np.zeros((self.W * self.H, 8))

    def add(self, L, fx, fy, first: int, count: int, spp: int) -> None:
        """Splat the chunk of ``count`` pixels from ``first`` (``spp`` samples each, in
        order; ``L``, ``fx``, ``fy`` its samples' radiance and film positions)."""
        F64, I32, U32 = jit.Float64, jit.Int32, jit.UInt32
        W, H, r = self.W, self.H, self.reach
        span = r * W + r   # pixels a sample reaches before or after its own
        lo, hi = max(0, first - span), min(W * H, first + count + span)
        t = I32(dr.arange(U32, hi - lo)) + dr.opaque(I32, lo)
        tx, ty = t % W, t // W
        cx, cy = F64(tx) + 0.5, F64(ty) + 0.5
        side = 2 * r + 1
        f0, n0 = dr.opaque(I32, first), dr.opaque(I32, count)

        def weight(d):
            if self.filter == "tent":
                return tent_weight(d, self.radius)
            return gaussian_weight(d, self.stddev)

        def body(k, acc):
            o = k // spp
            s = k - o * spp
            oy, ox = o // side - r, o % side - r
            px, py = tx - ox, ty - oy
            p = py * W + px - f0
            ok = (px >= 0) & (px < W) & (py >= 0) & (py < H) & (p >= 0) & (p < n0)
            idx = U32(p * spp + s)
            w = (weight(F64(dr.gather(jit.Float, fx, idx, ok)) - cx)
                 * weight(F64(dr.gather(jit.Float, fy, idx, ok)) - cy))
            w = dr.select(ok, w, 0.0)
            rad = jit.Array3f64(dr.gather(jit.Array3f, L, idx, ok))
            wl = rad * w
            return k + 1, [acc[0] + w, acc[1] + w * w,
                           *(acc[2 + c] + wl[c] for c in range(3)),
                           *(acc[5 + c] + wl[c] * rad[c] for c in range(3))]

        acc = [dr.zeros(F64, hi - lo) for _ in range(8)]
        _, acc = dr.while_loop((I32(0), acc), lambda k, acc: k < side * side * spp, body,
                               labels=("k", "acc"))
        dr.eval(acc)   # one kernel for the eight sums (each read alone would run the loop)
        self.sums[lo:hi] += np.stack([a.numpy() for a in acc], axis=1)

    def image(self, moments: bool):
        s = self.sums
        w = np.maximum(s[:, 0], 1e-300)[:, None]
        mean = s[:, 2:5] / w
        shape = (self.H, self.W, 3)
        variance = None
        if moments:
            spread = np.maximum(s[:, 5:8] / w - mean ** 2, 0)
            variance = (spread * (s[:, 1:2] / (w * w))).astype(np.float32).reshape(shape)
        return mean.astype(np.float32).reshape(shape), variance


def material_ids(scene: Scene) -> np.ndarray:
    """H x W: the material seen through each pixel's centre, for per-material statistics.

    The value is the material's position in ``scene.materials``, ``len(materials)``
    for an emitter without a material, and -1 where the ray misses everything.
    """
    backend.use()
    geo = Geometry(scene)
    W, H = scene.film.width, scene.film.height
    idx = dr.arange(jit.UInt32, W * H)
    fx = jit.Float(idx % W) + 0.5
    fy = jit.Float(idx // W) + 0.5
    o, d, tmax = generate_rays(scene.camera, W, H, fx, fy)
    hit = geo.closest_hit(o, d, tmax)
    mid = dr.gather(jit.UInt32, geo.material_id, hit.prim, hit.valid)
    ids = np.where(hit.valid.numpy(), mid.numpy().astype(np.int64), -1)
    return ids.reshape(H, W)


def render(scene: Scene, progress: Callable[[int, int], None] | None = None,
           seed: int = 0, lpe: str | None = None) -> RenderResult:
    """Render a validated scene with the tracer (two lines from Python: load, render).

    ``lpe``: only the light on paths matching this light-path expression
    (see :mod:`tracer.lpe`), e.g. ``"LDS+E"``.
    """
    return Integrator(scene, seed=seed, lpe=lpe).render(progress)
