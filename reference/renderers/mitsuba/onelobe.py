"""A Whitted integrator on Mitsuba 3's Python API: the reference for our tracer.

Mitsuba has no Whitted integrator, and its ``direct`` and ``path``
integrators pick one emitter at random per sample, which makes a scene with
several lights noisy. This integrator uses Mitsuba's own emitters, BSDFs and
ray casts; only the loop is ours:

* every emitter is sampled once per sample and shading point
  (``Emitter.sample_direction``, then ``Scene.ray_test`` for its shadow ray);
* at a surface whose BSDF has a smooth (non-delta) lobe, direct light is
  gathered there and the smooth lobe is never followed: no indirect diffuse
  light, as in Whitted's model;
* at a surface with delta lobes (``dielectric``, ``conductor``, and the
  delta part of a BSDF that also has a smooth one, such as the classic
  model's), the path continues with one delta lobe drawn by ``BSDF.sample``
  in a context that enables the delta lobes only (Mitsuba picks reflection
  with probability R and refraction with 1 - R, so the weight stays 1 up to
  the (n1/n2)^2 radiance scale); our tracer follows every lobe instead, so
  the two agree in expectation;
* emitters met by a camera or specular ray (an area light's front side, the
  environment where a ray misses) add their radiance; an emitter whose
  Python object says ``hit_term = True`` (the classic model's light spheres
  and backdrop, ``reference/emitters/``) only where the hit would still be
  shaded (depth < max_depth), as the tracer counts hit terms
  (``tracer/emitters/base.py``);
* ``max_depth`` counts path segments as Mitsuba's other integrators do.

These terms are :mod:`reference.renderers.mitsuba.shading`, the same code as the deterministic
reference's (:mod:`reference.renderers.mitsuba.deterministic`): the two differ only in how
they choose lobes and light samples.

With ``moments = true`` it also returns the per-sample second moment of each
RGB channel as AOVs ``m2.R``, ``m2.G``, ``m2.B``, from which the harness gets
the per-pixel variance for its z-test, and an AOV ``random``: 1 for a sample
that drew a random number which could have changed its value (a lobe chosen
where both had non-zero probability, or an area light sampled), else 0. Its
pixel mean tells the harness which pixels are random at all, and over how
many samples (see the zero-variance rule in :mod:`reference.verdicts.compare`).

This integrator is the harness's second, independent opinion: the default
reference, :mod:`reference.renderers.mitsuba.deterministic`, follows both lobes and shares the
tracer's light samples, so it carries no noise; this one samples as Mitsuba's
own integrators do, so it also checks that the tracer's light samples are
unbiased.

Random numbers. The harness renders with Mitsuba's ``stratified`` sampler at
strata centres (``jitter = false``) so that pixel positions are exactly the
tracer's. That sampler quantises every other dimension to strata centres
too: a lobe chosen with probability R from its 1D sample is taken in
round(R spp + 1/2) of spp samples instead of R spp on average, in every pass
and with every seed (with R = 0.0083 and 64 spp: in 1 of 64, 1.9 times too
often). So the Mitsuba sampler places the pixel sample only; the lobe choices
and light samples of this integrator come from a PCG32 stream per sample,
seeded by a hash of the sample's camera ray, of one value of the sampler
(which tells a pixel's samples apart even where their rays coincide) and of
``pass_seed``, which the harness sets to each pass's seed: without it a
sample position would see only as many distinct streams as the sampler has
strata, whatever the seed, and pooled passes would not be independent.
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi

from whitted.reference.renderers.mitsuba.shading import Terms


class WhittedIntegrator(mi.SamplingIntegrator):
    """Whitted light transport with every emitter sampled once per sample."""

    def __init__(self, props: mi.Properties):
        super().__init__(props)
        self.max_depth = int(props.get("max_depth", 6))
        self.moments = bool(props.get("moments", False))
        self.pass_seed = int(props.get("seed", 0))
        if self.max_depth < 1:
            raise ValueError("whitted: max_depth must be >= 1")

    def aov_names(self):
        return ["m2.R", "m2.G", "m2.B", "random"] if self.moments else []

    def _stream(self, sampler, ray):
        """A PCG32 stream per sample (see the module docstring)."""
        def bits(x):
            return dr.reinterpret_array(mi.UInt32, x)

        # Opaque, so that every pass reuses the same compiled kernel.
        seed = dr.opaque(mi.UInt32, _mix_int(self.pass_seed))
        key = _mix(bits(sampler.next_1d()) ^ seed)
        for c in (ray.o.x, ray.o.y, ray.o.z, ray.d.x, ray.d.y, ray.d.z):
            key = _mix(key ^ bits(c))
        width = dr.width(key)
        return mi.PCG32(width, mi.UInt64(key), mi.UInt64(_mix(key + 0x9E3779B9)))

    def sample(self, scene, sampler, ray, medium=None, active=True):
        terms = Terms(mi, scene, self.max_depth)   # what a hit adds (shading.py beside this)
        emitters = terms.emitters
        rng = self._stream(sampler, ray)

        area = [not mi.has_flag(e.flags(), mi.EmitterFlags.Delta) for e in emitters]

        def body(ray, L, beta, depth, active, valid, rng, rand):
            si = scene.ray_intersect(ray, active)
            valid |= active & si.is_valid() & (depth == 0)
            L += beta * terms.emitted(si, active, depth + 1)   # depth + 1: this segment
            depth += 1
            active &= si.is_valid() & terms.shaded(depth)

            bsdf = si.bsdf(ray)
            smooth, delta = terms.follows(bsdf.flags(), active)
            for emitter, sampled in zip(emitters, area, strict=True):
                if sampled:
                    rand |= smooth
                u = mi.Point2f(rng.next_float32(smooth), rng.next_float32(smooth))
                L += terms.direct(si, bsdf, emitter, u, beta, smooth)

            u1 = rng.next_float32(delta)
            u2 = mi.Point2f(rng.next_float32(delta), rng.next_float32(delta))
            bs, bsdf_weight = bsdf.sample(terms.delta, si, u1, u2, delta)
            beta = dr.select(delta, beta * bsdf_weight, beta)
            # A lobe chosen with probability below 1: the other one was possible.
            rand |= delta & (bs.pdf > 0) & (bs.pdf < 1)
            active = delta & (bs.pdf > 0) & (dr.max(beta) > 0)
            ray = dr.select(active, si.spawn_ray(si.to_world(bs.wo)), ray)
            return ray, L, beta, depth, active, valid, rng, rand

        # The random stream is part of the loop state: each iteration draws new numbers.
        state = (mi.Ray3f(ray), mi.Spectrum(0), mi.Spectrum(1), mi.UInt32(0),
                 mi.Bool(active), mi.Bool(False), rng, mi.Bool(False))
        ray, L, beta, depth, active, valid, rng, rand = dr.while_loop(
            state, lambda *s: s[4], body, labels=("ray", "L", "beta", "depth", "active",
                                                  "valid", "rng", "rand"),
            label="whitted")
        aovs = ([L[0] * L[0], L[1] * L[1], L[2] * L[2], dr.select(rand, 1.0, 0.0)]
                if self.moments else [])
        return L, valid, aovs

    def to_string(self):
        return f"WhittedIntegrator[max_depth={self.max_depth}]"


def _mix_int(x: int) -> int:
    """The same hash on a Python integer (32 bits)."""
    x &= 0xFFFFFFFF
    for shift, mul in ((16, 0x85EBCA6B), (13, 0xC2B2AE35)):
        x ^= x >> shift
        x = (x * mul) & 0xFFFFFFFF
    return x ^ (x >> 16)


def _mix(x):
    """A 32-bit integer hash (the finaliser of MurmurHash3) of UInt32 arrays."""
    x ^= x >> 16
    x *= 0x85EBCA6B
    x ^= x >> 13
    x *= 0xC2B2AE35
    x ^= x >> 16
    return x


mi.register_integrator("whitted", lambda props: WhittedIntegrator(props))
