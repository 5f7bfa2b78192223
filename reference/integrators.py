"""A Whitted integrator on Mitsuba 3's Python API: the reference for our tracer.

Mitsuba has no Whitted integrator, and its ``direct`` and ``path``
integrators pick one emitter at random per sample, which makes a scene with
several lights noisy. This integrator uses Mitsuba's own emitters, BSDFs and
ray casts; only the loop is ours:

* every emitter is sampled once per sample and shading point
  (``Emitter.sample_direction``, then ``Scene.ray_test`` for its shadow ray);
* at a surface whose BSDF has a smooth (non-delta) lobe, the path ends after
  that direct light: no indirect diffuse light, as in Whitted's model;
* at a surface with only delta lobes (``dielectric``, ``conductor``), the
  path continues with one lobe drawn by ``BSDF.sample`` (Mitsuba picks
  reflection with probability R and refraction with 1 - R, so the weight
  stays 1 up to the (n1/n2)^2 radiance scale); our tracer follows both lobes
  instead, so the two agree in expectation;
* area emitters hit by a camera or specular ray add their radiance;
* ``max_depth`` counts path segments as Mitsuba's other integrators do.

With ``moments = true`` it also returns the per-sample second moment of each
RGB channel as AOVs ``m2.R``, ``m2.G``, ``m2.B``, from which the harness gets
the per-pixel variance for its z-test.
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi


class WhittedIntegrator(mi.SamplingIntegrator):
    """Whitted light transport with every emitter sampled once per sample."""

    def __init__(self, props: mi.Properties):
        super().__init__(props)
        self.max_depth = int(props.get("max_depth", 6))
        self.moments = bool(props.get("moments", False))
        if self.max_depth < 1:
            raise ValueError("whitted: max_depth must be >= 1")

    def aov_names(self):
        return ["m2.R", "m2.G", "m2.B"] if self.moments else []

    def sample(self, scene, sampler, ray, medium=None, active=True):
        ctx = mi.BSDFContext()
        emitters = scene.emitters()
        max_depth = self.max_depth

        def body(ray, L, beta, depth, active, valid, sampler):
            si = scene.ray_intersect(ray, active)
            valid |= active & si.is_valid() & (depth == 0)
            # Emitted radiance of an area light hit on its front side.
            L += beta * si.emitter(scene).eval(si, active)
            depth += 1
            active &= si.is_valid() & (depth < max_depth)

            bsdf = si.bsdf(ray)
            flags = bsdf.flags()
            smooth = active & mi.has_flag(flags, mi.BSDFFlags.Smooth)
            for emitter in emitters:
                ds, weight = emitter.sample_direction(si, sampler.next_2d(smooth), smooth)
                lit = smooth & (ds.pdf != 0) & (dr.max(weight) > 0)
                shadow = si.spawn_ray_to(ds.p)
                lit &= ~scene.ray_test(shadow, lit)
                f = bsdf.eval(ctx, si, si.to_local(ds.d), lit)
                L += dr.select(lit, beta * f * weight, 0)

            delta = active & ~mi.has_flag(flags, mi.BSDFFlags.Smooth) & \
                mi.has_flag(flags, mi.BSDFFlags.Delta)
            bs, bsdf_weight = bsdf.sample(ctx, si, sampler.next_1d(delta),
                                          sampler.next_2d(delta), delta)
            beta = dr.select(delta, beta * bsdf_weight, beta)
            active = delta & (bs.pdf > 0) & (dr.max(beta) > 0)
            ray = dr.select(active, si.spawn_ray(si.to_world(bs.wo)), ray)
            return ray, L, beta, depth, active, valid, sampler

        state = (mi.Ray3f(ray), mi.Spectrum(0), mi.Spectrum(1), mi.UInt32(0),
                 mi.Bool(active), mi.Bool(False), sampler)
        ray, L, beta, depth, active, valid, sampler = dr.while_loop(
            state, lambda *s: s[4], body, labels=("ray", "L", "beta", "depth", "active",
                                                  "valid", "sampler"),
            label="whitted")
        aovs = [L[0] * L[0], L[1] * L[1], L[2] * L[2]] if self.moments else []
        return L, valid, aovs

    def to_string(self):
        return f"WhittedIntegrator[max_depth={self.max_depth}]"


mi.register_integrator("whitted", lambda props: WhittedIntegrator(props))
