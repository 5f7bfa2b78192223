"""``type = "spot"``: a point light restricted to a cone, Mitsuba's profile.

Incident factor I falloff(theta) / r^2: full intensity inside ``beam_width``,
falling linearly in the angle to zero at ``cutoff_angle`` (lecture 1, "Spot
lights"; :func:`tracer.lights.spot`). Mitsuba's ``spot`` emitter is the same
(``reference/emitters/spot.py``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from tracer.backend import deferred
from tracer.emitters import base

if TYPE_CHECKING:
    from tracer.scene import _Table

dr = deferred("drjit")
lights = deferred("tracer.lights")

Vec3 = tuple[float, float, float]
Color = tuple[float, float, float]


@dataclass(frozen=True)
class SpotLight(base.LightModel):
    position: Vec3
    target: Vec3
    intensity: Color  # W/sr on the axis
    cutoff_angle: float = 20.0
    beam_width: float = 15.0

    @property
    def axis(self) -> Vec3:
        d = np.subtract(self.target, self.position)
        return tuple(float(x) for x in d / np.linalg.norm(d))


MODEL = SpotLight


def parse(t: _Table) -> SpotLight:
    position, target = t.vec3("position"), t.vec3("target")
    t.distinct("target", position, target, "position")
    cutoff = t.number("cutoff_angle", 20.0, lo=0, hi=180, lo_open=True, hi_open=True)
    beam = t.number("beam_width", 0.75 * cutoff, lo=0, hi=cutoff)
    return SpotLight(position, target, t.color("intensity"), cutoff, beam)


class Emitter(base.Emitter):
    def __init__(self, light: SpotLight):
        self.light = light
        self.position = base.vec(light.position)
        self.axis = base.vec(light.axis)
        self.intensity = base.color(light.intensity)

    def sample(self, p, origin, u):
        L = self.light
        wi, _, e = lights.spot(p, self.position, self.axis, self.intensity, L.cutoff_angle,
                               L.beam_width)
        return wi, dr.norm(self.position - origin), e
