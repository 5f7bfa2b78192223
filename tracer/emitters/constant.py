"""``type = "constant"``: the same radiance from every direction (Mitsuba's ``constant``).

An environment at infinity, L(d) = ``radiance`` for every direction d
(pbrt-v4, section 12.5.1, ``UniformInfiniteLight``; Mitsuba 3's plugin
reference, ``constant``, its counterpart,
``reference/emitters/constant.py``): a ray that hits nothing brings its
radiance back (not a hit term: seen by rays of every segment, as Mitsuba's
environment emitters are), and shading points sample it as a light, one
direction uniform on the sphere per sample (pdf 1 / (4 pi), so the estimate
of the integral of L d(omega) is 4 pi L;
:func:`tracer.lights.sample_uniform_direction`), the shadow ray reaching to
infinity. Directions below the surface get cos <= 0 and add nothing.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from whitted.tracer.backend import deferred, jit
from whitted.tracer.emitters import base
from whitted.tracer.settings import Table

dr = deferred("drjit")
lights = deferred("whitted.tracer.lights")

Color = tuple[float, float, float]


@dataclass(frozen=True)
class ConstantLight(base.LightModel):
    radiance: Color


MODEL = ConstantLight


def parse(t: Table) -> ConstantLight:
    return ConstantLight(t.color("radiance"))


class Emitter(base.Emitter):
    delta = False
    infinite = True
    aim = (0.5, 0.5)

    def __init__(self, light: ConstantLight):
        self.radiance = base.color(light.radiance)

    def sample(self, p, origin, u):
        x, y, z = lights.sample_uniform_direction(u)
        wi = jit.Array3f(x, y, z)
        return wi, dr.full(jit.Float, dr.inf, dr.width(p)), self.radiance * (4 * math.pi)

    def background(self, d):
        return self.radiance
