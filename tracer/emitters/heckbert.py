"""Heckbert's light spheres: a sphere whose classic material has kl > 0 is a light.

In Heckbert's business-card ray tracer (minray, 1987) every sphere with an
emission coefficient kl > 0 lights the scene: a point with normal N receives
kl (N . L) colour from the unit direction L towards the sphere's centre, at
any distance (no falloff), when the first surface on the way to the centre
is that sphere (:func:`tracer.lights.sphere_centre`). The glow kl x colour
that such a sphere shows where a ray hits it is the classic material's own
emission (a hit term, :mod:`tracer.materials.classic`), not this emitter's.

This light is made by the material (:meth:`Classic.light_of
<tracer.materials.classic.Classic.light_of>`), not written as ``[[lights]]``;
its Mitsuba counterpart is ``reference/emitters/heckbert.py``.
"""

from __future__ import annotations

from dataclasses import dataclass

from whitted.tracer.backend import deferred
from whitted.tracer.emitters import base

lights = deferred("whitted.tracer.lights")

Vec3 = tuple[float, float, float]
Color = tuple[float, float, float]


@dataclass(frozen=True)
class HeckbertSphere(base.LightModel):
    center: Vec3
    radius: float
    value: Color      # kl x colour: what multiplies f (N . L), at every distance


MODEL = HeckbertSphere


class Emitter(base.Emitter):
    def __init__(self, light: HeckbertSphere):
        self.center = base.vec(light.center)
        self.radius = float(light.radius)
        self.value = base.color(light.value)

    def sample(self, p, origin, u):
        return lights.sphere_centre(p, origin, self.center, self.radius, self.value)
