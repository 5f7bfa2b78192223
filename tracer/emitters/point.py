"""``type = "point"``: an isotropic point light of intensity I (W/sr).

Incident factor I / r^2, the inverse-square law (lecture 1, "Light
attenuation"; :func:`tracer.lights.point`). Mitsuba's ``point`` emitter is
the same (``reference/emitters/point.py``).
"""

from __future__ import annotations

from dataclasses import dataclass

from whitted.tracer.backend import deferred
from whitted.tracer.emitters import base
from whitted.tracer.settings import Table

dr = deferred("drjit")
lights = deferred("whitted.tracer.lights")

Vec3 = tuple[float, float, float]
Color = tuple[float, float, float]


@dataclass(frozen=True)
class PointLight(base.LightModel):
    position: Vec3
    intensity: Color  # W/sr


MODEL = PointLight


def parse(t: Table) -> PointLight:
    return PointLight(t.vec3("position"), t.color("intensity"))


class Emitter(base.Emitter):
    def __init__(self, light: PointLight):
        self.position = base.vec(light.position)
        self.intensity = base.color(light.intensity)

    def sample(self, p, origin, u):
        wi, _, e = lights.point(p, self.position, self.intensity)
        return wi, dr.norm(self.position - origin), e
