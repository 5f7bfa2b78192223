"""Mitsuba conversion of Heckbert's light spheres (tracer/emitters/heckbert.py).

Mitsuba has no light that delivers a fixed value from the direction of a
sphere's centre at any distance, so this emitter, ``whitted_heckbert``, is
written on Mitsuba's API and attached to the light sphere's shape (the
harness attaches it where the tracer's material makes the light, :meth:`Classic.light_of
<tracer.materials.classic.Classic.light_of>`). It plays both parts of a
minray light:

* **lighting** (``sample_direction``): for a shading point p, a delta
  sample (``ds.delta``, ``pdf`` 1) in the direction L = (c - p) / |c - p|
  of the centre, at the point where the ray from p towards the centre meets
  the sphere, p + L (|c - p| - r), with weight kl x colour and no 1/r^2.
  Mitsuba's integrators trace the shadow ray from p to that point and stop
  just short of it, so the point is lit exactly when nothing lies between it
  and the sphere, i.e. when the first surface towards the centre is the light
  sphere, Heckbert's test; the BSDF's ``eval`` supplies kd colour (N . L).
  Derivation: minray adds kl colour (N . L) for each light that passes the
  test; a delta emitter contributes f cos(theta) x weight / pdf with pdf 1,
  which is that sum term by term;
* **glow** (``eval``): kl x colour where a ray hits the sphere, on either
  side, as minray's trace returns kl colour for a hit on it.

Both are hit terms in the classic model (:mod:`tracer.emitters.base`): both
of the harness's references count the glow of an emitter that has
``hit_term = True`` only where they would still shade the hit (depth <
max_depth; :mod:`reference.renderers.mitsuba.shading`), as the tracer counts the classic
material's emission. Mitsuba's ``path`` integrator does not know hit terms
(it counts the glow at the last segment too) and also reaches the glow
through diffuse bounces.
"""

from __future__ import annotations

import drjit as dr

from whitted.reference.renderers.mitsuba.tree import per_variant, rgb
from whitted.tracer.emitters.heckbert import HeckbertSphere

#: the Mitsuba plugins this module registers
PLUGINS = ("whitted_heckbert",)


def mitsuba(light: HeckbertSphere) -> dict:
    return {"type": "whitted_heckbert", "center": ("point", light.center),
            "radius": ("float", light.radius), "radiance": rgb(light.value)}


def register(mi) -> None:
    """Register ``whitted_heckbert`` with Mitsuba, whose variant must be set."""
    cls = plugin_class(mi)
    mi.register_emitter("whitted_heckbert", lambda props: cls(props))


def constant_color(mi, props, name: str):
    """A constant colour parameter (an ``rgb`` texture or a list) as a Color3f."""
    from whitted.reference.materials.phong import _color_texture

    tex = _color_texture(mi, props, name, 1.0)
    return mi.Color3f(tex.eval(dr.zeros(mi.SurfaceInteraction3f)))


plugin_class = per_variant(lambda mi: _define(mi))


def _define(mi):
    class HeckbertSphereLight(mi.Emitter):
        """minray's light sphere: lit towards its centre, no falloff; glows (module docstring)."""

        #: the glow is a hit term (reference/renderers/mitsuba/onelobe.py)
        hit_term = True

        def __init__(self, props: mi.Properties):
            super().__init__(props)
            self.center = mi.Point3f(props.get("center"))
            self.radius = float(props.get("radius"))
            self.value = constant_color(mi, props, "radiance")
            self.m_flags = mi.EmitterFlags.DeltaPosition | mi.EmitterFlags.Surface

        def sample_direction(self, it, sample, active=True):
            to_c = self.center - it.p
            dc = dr.norm(to_c)
            d = to_c / dc
            ds = dr.zeros(mi.DirectionSample3f)
            ds.d = d
            ds.dist = dc - self.radius
            ds.p = it.p + d * ds.dist
            ds.n = -d
            ds.pdf = 1.0
            ds.delta = True
            ds.emitter = mi.EmitterPtr(self)
            outside = mi.Bool(active) & (dc > self.radius)
            return ds, dr.select(outside, self.value, 0.0)

        def eval(self, si, active=True):
            return dr.select(mi.Bool(active), self.value, 0.0)

        def pdf_direction(self, it, ds, active=True):
            return mi.Float(0.0)

        def eval_direction(self, it, ds, active=True):
            return mi.Color3f(0.0)

        def traverse(self, cb):
            pass

        def to_string(self):
            return f"HeckbertSphereLight[center = {self.center}, radius = {self.radius}]"

    return HeckbertSphereLight
