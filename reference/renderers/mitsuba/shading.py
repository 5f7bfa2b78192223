"""What both Mitsuba-side references do at one hit of Whitted's ray tree.

The deterministic reference (:mod:`reference.renderers.mitsuba.deterministic`, both lobes of
every delta BSDF, the tracer's light samples) and the one-lobe integrator
(:mod:`reference.renderers.mitsuba.onelobe`, one lobe and its own light samples per
sample) differ only in how they choose; what a hit adds and where rays go
next is this one piece of code, so that the two honour the hooks of the
scene model alike (``docs/extending.md``). Everything is a call into
Mitsuba 3's API, and nothing asks which plugin it holds:

* **light seen** (:meth:`Terms.emitted`): ``SurfaceInteraction3f.emitter``
  and ``Emitter.eval`` for every ray, hit or not (Mitsuba returns the
  scene's environment emitter where a ray misses, and an area emitter
  evaluates to zero on its back side). An emitter whose Python object says
  ``hit_term = True`` (the classic model's light-sphere glow and its
  backdrop, ``reference/emitters/``) is a *hit term*: counted only where the
  hit is still shaded, i.e. for a ray of path segment k < max_depth, as the
  tracer counts hit terms (:mod:`tracer.emitters.base`; with them
  max_depth = DEPTH + 1 is Heckbert's DEPTH exactly);
* **direct light** (:meth:`Terms.direct`), at a BSDF with a smooth lobe
  (``BSDFFlags.Smooth``): one ``Emitter.sample_direction`` per emitter, a
  shadow ray (``Scene.ray_test`` of ``spawn_ray_to``) and ``BSDF.eval``;
  an emitter that lights nothing returns a zero weight (``whitted_background``);
* **delta lobes**, at a BSDF with any delta lobe, smooth part or not
  (``whitted_classic`` has a diffuse part and fixed-weight reflection and
  transmission): ``BSDF.sample`` in a context whose type mask keeps the
  delta lobes only (:attr:`Terms.delta`: Mitsuba then picks one of them, and
  never the smooth lobe, which Whitted's model does not follow) or one lobe
  alone (:attr:`Terms.lobes`: that lobe with its own weight, e.g. R or
  (1 - R)(n1/n2)^2 from ``dielectric``, ks or kt from ``whitted_classic``);
* **the last segment** (:attr:`Terms.last_segment_sees`): a ray of path
  segment max_depth is never shaded, so it can add light only by meeting an
  emitter that is not a hit term: one on a shape (an area light) or an
  environment that is not a delta direction (Mitsuba's ``directional`` is
  flagged ``Infinite`` too, but no ray meets it). Where there is none, such
  rays are not traced at all, the rule the tracer follows
  (``Integrator.last_level_sees``), so both sides trace the same rays.
"""

from __future__ import annotations

import drjit as dr


def is_hit_term(emitter) -> bool:
    """Whether an emitter's radiance where a ray meets it is a hit term (module docstring)."""
    return bool(getattr(emitter, "hit_term", False))


def seen_by_rays(emitter, mi) -> bool:
    """Whether a ray can meet the emitter: one on a shape, or at infinity but not a delta
    direction."""
    flags = emitter.flags()
    return emitter.get_shape() is not None or (
        mi.has_flag(flags, mi.EmitterFlags.Infinite) and
        not mi.has_flag(flags, mi.EmitterFlags.DeltaDirection))


class Terms:
    """The terms of one Mitsuba scene at a hit, for a given ``max_depth`` (module docstring)."""

    def __init__(self, mi, scene, max_depth: int):
        self.mi = mi
        self.scene = scene
        self.max_depth = int(max_depth)
        self.emitters = list(scene.emitters())
        #: hit-term emitters, compared by pointer with the emitter a ray meets
        self.hit_terms = [mi.EmitterPtr(e) for e in self.emitters if is_hit_term(e)]
        self.last_segment_sees = any(seen_by_rays(e, mi) and not is_hit_term(e)
                                     for e in self.emitters)
        self.ctx = mi.BSDFContext()
        #: the delta lobes only, and the null lobe (a ray passing straight through:
        #: ``thindielectric``'s transmission, ``mask``'s 1 - opacity): BSDF.sample picks
        #: one of them, never a smooth lobe
        self.delta = mi.BSDFContext()
        self.delta.type_mask = mi.BSDFFlags.Delta | mi.BSDFFlags.Null
        #: the lobes followed one by one: both delta lobes and the null lobe
        self.lobes = (mi.BSDFFlags.DeltaReflection, mi.BSDFFlags.DeltaTransmission,
                      mi.BSDFFlags.Null)
        #: some BSDF of the scene has a null lobe
        self.has_null = any(mi.has_flag(shape.bsdf().flags(), mi.BSDFFlags.Null)
                            for shape in scene.shapes() if shape.bsdf() is not None)
        self._alone = {}
        self._with_null = {}
        for flag in self.lobes:
            self._alone[flag] = mi.BSDFContext()
            self._alone[flag].type_mask = flag
            self._with_null[flag] = mi.BSDFContext()
            self._with_null[flag].type_mask = flag | mi.BSDFFlags.Null

    def shaded(self, segment):
        """Whether the hit of a ray of path segment ``segment`` (1 = camera ray) is shaded."""
        return segment < self.max_depth

    def emitted(self, si, active, segment):
        """Radiance seen by rays of path segment ``segment`` (int or UInt32) at ``si``:
        the emitter they meet, hit terms only where :meth:`shaded`."""
        mi = self.mi
        emitter = si.emitter(self.scene)
        seen = mi.Bool(active)
        if self.hit_terms:
            term = emitter == self.hit_terms[0]
            for ptr in self.hit_terms[1:]:
                term |= emitter == ptr
            seen &= ~term | mi.Bool(self.shaded(segment))
        return dr.select(seen, emitter.eval(si, seen), 0)

    def follows(self, flags, active):
        """(smooth, delta): lanes whose BSDF gathers direct light, and those with delta lobes."""
        mi = self.mi
        return (active & mi.has_flag(flags, mi.BSDFFlags.Smooth),
                active & (mi.has_flag(flags, mi.BSDFFlags.Delta) |
                          mi.has_flag(flags, mi.BSDFFlags.Null)))

    def lobe(self, bsdf, si, flag, active):
        """(direction in world space, weight, lanes that follow it) of one lobe alone.

        A BSDF without a null lobe is sampled in a context that enables ``flag``
        only; it then returns that lobe with its own weight (R or
        (1 - R)(n1/n2)^2 from ``dielectric``). A BSDF with a null lobe
        (``thindielectric``, ``mask``) weighs its lobes by the probabilities with
        which it picks them, so it is sampled in a context that enables ``flag``
        and the null lobe, at the end of the sample range where ``flag`` is picked
        (0 for a delta lobe, just below 1 for the null lobe), and the lobe's weight
        is the sample's weight times its probability (value / pdf x pdf). (Mitsuba
        3.9.1's ``mask`` needs the null lobe enabled: asked for its nested lobes
        alone, it inverts its choice and returns the null lobe.)
        """
        mi = self.mi
        flags = bsdf.flags()
        follow = active & mi.has_flag(flags, flag)
        null = mi.has_flag(flags, mi.BSDFFlags.Null)
        half = mi.Point2f(0.5, 0.5)
        plain = follow & ~null
        bs, weight = bsdf.sample(self._alone[flag], si, 0.5, half, plain)
        wo, keep = bs.wo, plain & (bs.pdf > 0)
        with_null = follow & null
        if self.has_null:
            u1 = 1 - 2.0 ** -24 if flag == mi.BSDFFlags.Null else 0.0
            bn, wn = bsdf.sample(self._with_null[flag], si, u1, half, with_null)
            picked = with_null & (bn.pdf > 0) & mi.has_flag(bn.sampled_type, flag)
            wo = dr.select(with_null, bn.wo, wo)
            weight = dr.select(with_null, wn * bn.pdf, weight)
            keep = dr.select(with_null, picked, keep)
        return si.to_world(wo), weight, keep & (dr.max(weight) > 0)

    def direct(self, si, bsdf, emitter, u, beta, active, sampler=None):
        """beta f cos x (the emitter's weight) for one light sample ``u``, where not shadowed.

        ``sampler(emitter, si, u, mi) -> (direction, weight)``: a light at infinity
        sampled another way than by the emitter's own ``sample_direction`` (an
        environment map at the tracer's directions, ``reference/emitters/envmap.py``).
        """
        if sampler is None:
            ds, weight = emitter.sample_direction(si, u, active)
            lit = active & (ds.pdf != 0) & (dr.max(weight) > 0)
            lit &= ~self.scene.ray_test(si.spawn_ray_to(ds.p), lit)
            d = ds.d
        else:
            d, weight = sampler(emitter, si, u, self.mi)
            lit = active & (dr.max(weight) > 0)
            lit &= ~self.scene.ray_test(si.spawn_ray(d), lit)
        f = bsdf.eval(self.ctx, si, si.to_local(d), lit)
        return dr.select(lit, beta * f * weight, 0)

    def spawns_children(self, segment: int) -> bool:
        """Whether rays of the next segment are worth tracing after segment ``segment``."""
        return segment + 1 < self.max_depth or self.last_segment_sees
