"""``type = "directional"``: light arriving from one direction, irradiance E (W/m^2).

E is measured on a plane normal to the light, so the incident factor is E,
constant, and the shadow ray is unbounded (lecture 2, "Point and directional
lights"; :func:`tracer.lights.directional`). Mitsuba's ``directional``
emitter is the same (``reference/emitters/directional.py``).
"""

from __future__ import annotations

from dataclasses import dataclass

from whitted.tracer.backend import deferred
from whitted.tracer.emitters import base
from whitted.tracer.settings import Table

lights = deferred("whitted.tracer.lights")

Vec3 = tuple[float, float, float]
Color = tuple[float, float, float]


@dataclass(frozen=True)
class DirectionalLight(base.LightModel):
    direction: Vec3   # unit vector, the direction the light travels
    irradiance: Color  # W/m^2, measured normal to the direction


MODEL = DirectionalLight


def parse(t: Table) -> DirectionalLight:
    return DirectionalLight(t.direction("direction"), t.color("irradiance"))


class Emitter(base.Emitter):
    def __init__(self, light: DirectionalLight):
        self.direction = base.vec(light.direction)
        self.irradiance = base.color(light.irradiance)

    def sample(self, p, origin, u):
        return lights.directional(p, self.direction, self.irradiance)
