"""The deterministic reference: Whitted's ray tree evaluated with Mitsuba's own plugins.

The harness's second integrator (``whitted`` in :mod:`reference.renderers.mitsuba.onelobe`)
follows one lobe per sample and samples lights from its own random stream, so
its images carry noise that hides small biases. This one has none. It is a
wavefront over recursion levels, like the tracer, in which every step is a
call into Mitsuba 3's Python API and nothing is the tracer's code:

* camera rays: ``Sensor.sample_ray`` at exactly the tracer's film positions
  (the centres of an n x n grid of strata in each pixel);
* hits: ``Scene.ray_intersect``; the light a ray sees where it meets an
  emitter (an area light's front side, the environment where it misses),
  ``SurfaceInteraction3f.emitter(scene).eval``, hit terms (the classic
  model's glow and backdrop) only where the hit is still shaded;
* at a hit whose BSDF has a smooth lobe (Mitsuba's ``BSDFFlags.Smooth``), direct
  light from every emitter: ``Emitter.sample_direction``, ``Scene.ray_test``
  for the shadow ray, ``BSDF.eval``; the smooth lobe is never followed
  (Whitted's model has no indirect diffuse light);
* at a hit whose BSDF has a delta lobe, smooth part or not, each delta lobe
  is followed: for ``DeltaReflection`` and ``DeltaTransmission`` in turn,
  ``BSDF.sample`` with a ``BSDFContext`` whose ``type_mask`` keeps that lobe
  alone. Mitsuba's ``dielectric`` then returns the lobe with probability 1
  and weight R (or 1 - R times the (n1/n2)^2 radiance scale, which is 0
  under total internal reflection), and ``conductor`` its reflectance times
  its Fresnel term (src/bsdfs/dielectric.cpp and conductor.cpp, Mitsuba
  3.9.1: with one of the two lobes enabled, ``weight = has_reflection ? r_i
  : t_i``, ``pdf = 1``; ``twosided`` passes the context on to the side the
  ray arrives from); ``whitted_classic`` its fixed weight ks or kt;
* ``max_depth`` counts path segments, as in Mitsuba and the tracer, and rays
  of the last segment are traced only where they can meet an emitter that is
  not a hit term, as in the tracer.

What a hit adds and which rays it spawns is :mod:`reference.renderers.mitsuba.shading`, the
same code as the one-lobe integrator's (:mod:`reference.renderers.mitsuba.onelobe`).
Which lobes exist comes from the BSDF's flags, never from the material's kind:
a new Mitsuba BSDF with delta or smooth lobes needs no change here.

Area lights. Delta emitters (point, spot, directional, Heckbert's light
spheres) need no sample. An area
light is sampled at the tracer's own points: both sides read
:func:`tracer.sampling.light_sample` (the same pixel, sample index, level,
light and seed), and each shape's 2D sample is mapped to the sample for
which Mitsuba's warp gives the same point (:data:`SAMPLE_MAPS`, checked by
tests against the tracer's points). So an area-lit image is the tracer's
estimator computed with Mitsuba's warps, pdfs and visibility: the two agree
to float precision for every seed, and a wrong warp or pdf on either side
shows as a difference, not as noise.

Nothing here is random: one pass gives the reference, and pixels are the
mean of their samples (a box filter, as ``hdrfilm`` with ``box`` gives).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import drjit as dr
import numpy as np

from whitted.reference.renderers.mitsuba.shading import Terms
from whitted.tracer.backend import jit
from whitted.tracer.sampling import light_sample, pixel_samples
from whitted.tracer.scene import Disk, Rectangle, Scene, Sphere, Triangle

#: Samples in flight at once (whole pixels), as in the tracer on the CPU.
CHUNK_SAMPLES = 1 << 21


def _same(u, mi):
    return u


def _triangle(u, mi):
    # Mitsuba's warp.square_to_uniform_triangle takes t = sqrt(1 - u.x) and the point
    # p0 + (1 - t) e1 + t u.y e2; the tracer takes sqrt(u.x) (Shirley's form).
    return mi.Point2f(1 - u.x, u.y)


def _sphere(u, mi):
    # Both sample the cone the sphere subtends with cos(theta) = 1 - u.x (1 - cos_max),
    # but Mitsuba builds its frame around the direction from the centre to the shading
    # point, Frame3f(-w), whose second tangent is the negative of Frame3f(w)'s (Duff et
    # al.'s basis, coordinate_system): its azimuth runs the other way.
    return mi.Point2f(u.x, 1 - u.y)


#: Tracer light sample -> the sample for which Mitsuba 3.9.1's emitter gives the same
#: point: rectangles (2u - 1 in local xy) and disks (Shirley and Chiu's concentric map)
#: warp alike; triangles and spheres differ as noted in each function.
SAMPLE_MAPS: dict[type, Callable] = {Rectangle: _same, Disk: _same, Triangle: _triangle,
                                     Sphere: _sphere}


def shares_light_samples(scene: Scene) -> bool:
    """Whether every light the tracer samples can be sampled here at the tracer's points.

    Every emitting shape needs a sample map (see SAMPLE_MAPS); a ``[[lights]]`` kind
    that is not delta (a light the tracer samples, such as one at infinity) has none.
    """
    from whitted.tracer.emitters import LIGHTS, type_of

    if any(_light_sample_map(light) is None for light in scene.lights
           if not LIGHTS[type_of(light)].Emitter.delta and
           LIGHTS[type_of(light)].Emitter.illuminates):
        return False
    return all(type(s) in SAMPLE_MAPS for s in scene.shapes if s.emitter is not None)


def _light_sample_map(light) -> Callable | None:
    """The sample map of a ``[[lights]]`` kind Mitsuba samples as the tracer does (the
    ``sample_map`` of its conversion module, ``reference/emitters/``), or None."""
    from whitted.reference.emitters import REGISTRY
    from whitted.tracer.emitters import type_of

    return getattr(REGISTRY.get(type_of(light)), "sample_map", None)


@dataclass
class _Light:
    emitter: object
    index: int | None          # the tracer's area-light number; None for delta emitters
    sample_map: Callable | None
    #: samples the emitter at the tracer's sample another way than its sample_direction
    sampler: Callable | None = None


def _lights(scene: Scene, ms, mi, names: list[str] | None = None) -> list[_Light]:
    """Mitsuba's emitters, each with the tracer's area-light number and its sample map.

    ``names``: for each of ``ms.emitters()``, its name in the conversion (``light_K`` for
    the scene's K-th light, ``shape_K`` for an emitter on its K-th shape); by default the
    emitters' and their shapes' own ids, which the conversion sets. A scene Mitsuba read
    from the original XML has other ids, and its names come from matching it with the
    conversion (:func:`reference.renderers.mitsuba.original.original_reference`).

    Which emitters take a sample comes from Mitsuba's flags: a delta emitter
    (a point, spot or directional light, or Heckbert's light sphere, which is
    attached to its shape but lights towards its centre) ignores it; an
    emitter on a shape that is not delta is an area light, sampled at the
    tracer's points of the same light. Others (an environment that lights
    nothing) are handed any sample.
    """
    from whitted.tracer.emitters import LIGHTS, type_of

    emitting = [i for i, s in enumerate(scene.shapes) if s.emitter is not None]
    # The tracer numbers its sampled lights: sampled [[lights]] first, then area emitters.
    sampled = [i for i, light in enumerate(scene.lights)
               if not LIGHTS[type_of(light)].Emitter.delta]
    out = []
    for i, e in enumerate(ms.emitters()):
        shape = e.get_shape()
        if names is not None:
            name = names[i]
        else:
            name = shape.id() if shape is not None else e.id()
        if shape is None and name.startswith("light_") and not mi.has_flag(
                e.flags(), mi.EmitterFlags.Delta):
            k = int(name.removeprefix("light_"))
            sample_map = _light_sample_map(scene.lights[k])
            if sample_map is not None:  # a light at infinity sampled as the tracer does
                from whitted.reference.emitters import REGISTRY

                sampler = getattr(REGISTRY.get(type_of(scene.lights[k])), "direct_sample", None)
                out.append(_Light(e, sampled.index(k), sample_map, sampler))
                continue
        if shape is None or mi.has_flag(e.flags(), mi.EmitterFlags.Delta):
            out.append(_Light(e, None, None))
            continue
        k = int(name.removeprefix("shape_"))
        kind = type(scene.shapes[k])
        if kind not in SAMPLE_MAPS:
            raise NotImplementedError(f"no shared light samples for {kind.__name__} emitters")
        out.append(_Light(e, len(sampled) + emitting.index(k), SAMPLE_MAPS[kind]))
    return out


@dataclass
class DeterministicResult:
    image: np.ndarray          # H x W x 3 float32, linear
    seconds: float
    spp: int
    rays_per_level: list[int]


class DeterministicReference:
    """Renders one scene with Mitsuba's plugins along the whole Whitted ray tree."""

    def __init__(self, scene: Scene, seed: int = 0, models: bool = False, ms=None,
                 names: list[str] | None = None):
        """``models``: the scene's tracer-only parts as the harness models them (Schlick's
        dielectric, ``reference/materials/dielectric.py``) instead of Mitsuba's equivalent.
        ``ms``: a Mitsuba scene to evaluate instead of the conversion of ``scene`` (the
        original XML as Mitsuba reads it), with ``names`` for its emitters (:func:`_lights`);
        the tracer's film positions and light samples stay those of ``scene``."""
        from whitted.reference import mitsuba
        from whitted.reference.renderers.mitsuba.scene import load

        self.mi = mi = mitsuba()
        self.scene = scene
        self.seed = seed
        self.ms = load(scene, mi, models=models) if ms is None else ms
        self.sensor = self.ms.sensors()[0]
        self.lights = _lights(scene, self.ms, mi, names)
        self.terms = Terms(mi, self.ms, scene.film.max_depth)

    def _level(self, ray, beta, pixel, s, slot, depth: int, L):
        """Trace the rays of path segment ``depth``; add their light to L; return the
        next segment's rays."""
        mi, ms, scene, terms = self.mi, self.ms, self.scene, self.terms
        si = ms.ray_intersect(ray)
        valid = si.is_valid()
        contrib = beta * terms.emitted(si, True, depth)
        children = []
        if terms.shaded(depth):
            bsdf = si.bsdf(ray)
            smooth, delta = terms.follows(bsdf.flags(), valid)
            for light in self.lights:
                if light.index is None:
                    u = mi.Point2f(0.5, 0.5)  # a delta emitter ignores its sample
                else:
                    t = light_sample(jit.UInt32(pixel), jit.UInt32(s), scene.film.strata,
                                     self.seed, depth, light.index)
                    u = light.sample_map(mi.Point2f(t), mi)
                contrib += terms.direct(si, bsdf, light.emitter, u, beta, smooth, light.sampler)
            if terms.spawns_children(depth):
                for flag in terms.lobes:
                    wo, weight, keep = terms.lobe(bsdf, si, flag, delta)
                    w = beta * weight
                    keep &= dr.max(w) > 0
                    children.append((si.spawn_ray(wo), w, keep))
        # Direct: atomic adds, as the tracer's; the default on the CPU (Expand) adds into
        # a copy of L per thread and writes L's size into the kernel, so that each
        # film size compiled its own (issue 33)
        dr.scatter_reduce(dr.ReduceOp.Add, L, contrib, slot, mode=dr.ReduceMode.Direct)
        if not children:
            dr.eval(L)
            return None
        dr.eval(L, *[c for ch in children for c in ch])
        parts = []
        for child, w, keep in children:
            idx = dr.compress(keep)
            if dr.width(idx) == 0:
                continue
            parts.append(tuple(dr.gather(type(x), x, idx) for x in (
                child.o, child.d, w, pixel, s, slot)))
        if not parts:
            return None
        joined = []
        for k in range(6):
            vals = [p[k] for p in parts]
            t = type(vals[0])
            if dr.size_v(t) == 3:
                joined.append(t(*(dr.concat([v[i] for v in vals]) for i in range(3))))
            else:
                joined.append(dr.concat(vals))
        o, d, w, pixel, s, slot = joined
        return mi.Ray3f(o, d), w, pixel, s, slot

    def render(self, progress: Callable[[int, int], None] | None = None) -> DeterministicResult:
        """The image: each pixel the mean of its strata's ray trees."""
        mi, scene = self.mi, self.scene
        W, H = scene.film.width, scene.film.height
        n = scene.film.strata
        spp = n * n
        total = W * H
        per_chunk = max(1, CHUNK_SAMPLES // spp)
        image = np.zeros((total, 3), dtype=np.float32)
        rays = [0] * scene.film.max_depth
        start = time.perf_counter()
        # inputs of the kernel, not constants in it: one kernel at every film size
        scale = mi.Point2f(dr.opaque(mi.Float, 1 / W), dr.opaque(mi.Float, 1 / H))
        for first in range(0, total, per_chunk):
            count = min(per_chunk, total - first)
            pixel, s, fx, fy = pixel_samples(W, n, first, count)
            film = mi.Point2f(mi.Float(fx), mi.Float(fy)) * scale
            ray, weight = self.sensor.sample_ray(0.0, 0.5, film, mi.Point2f(0.5, 0.5))
            # Mitsuba's sensor writes the film's size into its kernel: evaluated apart,
            # so that the kernels of the ray trees do not, and one compile of them
            # serves every size the report renders a scene at (issue 33)
            dr.eval(ray, weight)
            L = dr.zeros(mi.Color3f, count * spp)
            slot = dr.arange(mi.UInt32, count * spp)
            beta = mi.Color3f(weight)
            stack = [(1, (mi.Ray3f(ray.o, ray.d, ray.maxt), beta, mi.UInt32(pixel),
                          mi.UInt32(s), slot))]
            while stack:
                depth, (r, b, px, sx, sl) = stack.pop()
                rays[depth - 1] += dr.width(sl)
                nxt = self._level(r, b, px, sx, sl, depth, L)
                if nxt is not None and depth < scene.film.max_depth:
                    # A level that outgrows the chunk (both lobes of every glass hit) is
                    # split and followed depth-first, as in the tracer: bounded memory.
                    for part in reversed(_split(nxt, CHUNK_SAMPLES, mi)):
                        stack.append((depth + 1, part))
            px_mean = dr.block_sum(L, spp) * (1.0 / spp)
            image[first:first + count] = np.asarray(px_mean).T
            if progress is not None:
                progress(first + count, total)
        while rays and rays[-1] == 0:
            rays.pop()
        return DeterministicResult(image.reshape(H, W, 3), time.perf_counter() - start, spp,
                                   rays)


def _split(level, cap: int, mi) -> list:
    """A level's rays (ray, weight, pixel, sample, slot) in parts of at most ``cap``."""
    n = dr.width(level[-1])
    if n <= cap:
        return [level]
    ray, *rest = level
    parts = []
    for a in range(0, n, cap):
        idx = dr.arange(mi.UInt32, a, min(a + cap, n))
        parts.append((mi.Ray3f(dr.gather(mi.Point3f, ray.o, idx),
                               dr.gather(mi.Vector3f, ray.d, idx)),
                      *(dr.gather(type(x), x, idx) for x in rest)))
    return parts


def render_deterministic(scene: Scene, seed: int = 0,
                         progress: Callable[[int, int], None] | None = None
                         ) -> DeterministicResult:
    """Render ``scene`` with the deterministic reference (area lights at the tracer's
    light samples of ``seed``)."""
    return DeterministicReference(scene, seed).render(progress)
