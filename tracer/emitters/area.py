"""Area emitters on shapes: ``emitter = { radiance = [...] }``.

A shape with an emitter emits radiance L (W/(m^2 sr)) from its front side,
the side its normal points to (Mitsuba's ``area`` emitter). The tracer uses
it twice:

* a ray that hits the front side brings L back (:func:`emitted`);
* at a shading point it is one light, sampled once per sample
  (:class:`Emitter`), by the sampler of its shape kind (``Sampler`` in
  ``tracer/shapes/<kind>.py``): uniform by area
  (rectangle, disk, triangle), estimating integral L cos(theta_l) / r^2 dA
  as L cos(theta_l) A / r^2, or, for a sphere, uniform in the cone of
  directions it subtends, estimating integral L d(omega) as L / pdf (the two
  estimators of :mod:`tracer.lights`, which holds the sampling maps).

A shape kind carries emitters when its module has a ``Sampler``
(:mod:`tracer.shapes.base`); nothing else asks which shape it holds.
"""

from __future__ import annotations

from dataclasses import dataclass

from whitted.tracer import shapes
from whitted.tracer.backend import deferred, jit
from whitted.tracer.emitters import base
from whitted.tracer.settings import Table

dr = deferred("drjit")

Color = tuple[float, float, float]


@dataclass(frozen=True)
class AreaEmitter:
    radiance: Color  # W/(m^2 sr), emitted from the front side


def parse(t: Table) -> AreaEmitter:
    return AreaEmitter(t.color("radiance"))


def emitted(radiance_table, prim, cos_o, valid):
    """(L, lanes) of rays that hit an emitting primitive on its front side (cos_o > 0).

    ``radiance_table`` holds each primitive's radiance (zero for shapes that do
    not emit), ``cos_o`` = -d . n is positive where the ray arrives on the side
    the geometric normal points to.
    """
    return dr.gather(jit.Array3f, radiance_table, prim, valid), valid & (cos_o > 0)


#: Shape ``type`` -> how an emitter on it is sampled: each kind's ``Sampler``
#: (``tracer/shapes/<kind>.py``), in the order of the scene format's error message.
SAMPLERS: dict[str, type] = {kind: shapes.REGISTRY[kind].Sampler for kind in shapes.emitting()}


class Emitter(base.Emitter):
    """The area emitter of one shape, as a light sampled once per shading point."""
    delta = False

    def __init__(self, shape, index: int = 0):
        #: the emitter's place among the sampled lights (it chooses the random stream)
        self.index = index
        self.radiance = base.color(shape.emitter.radiance)
        self.sampler = shapes.module_of(shape).Sampler(shape)
        self.aim = self.sampler.aim

    def sample(self, p, origin, u):
        """(wi, distance, L cos / r^2 / pdf) from one light sample ``u`` per shading point."""
        return self.sampler.sample(self.radiance, p, origin, u)

    def shadow_ray(self, p, origin, wi, dist):
        """The sampler's shadow ray, if it has its own (flat shapes aim at the point)."""
        if hasattr(self.sampler, "shadow_ray"):
            return self.sampler.shadow_ray(p, origin, wi, dist)
        return wi, dist
