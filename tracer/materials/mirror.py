"""``type = "mirror"``: a perfect mirror, one delta lobe in the mirror direction.

The law of reflection (lecture 1, "Reflection"): r = d - 2 (d . n) n, the
angle of incidence equal to the angle of reflection, with the weight
``reflectance`` per channel (a conductor whose Fresnel reflectance is that
constant; pbrt-v4, ``ConductorBxDF`` in its smooth limit). Mitsuba's
counterpart is a two-sided ``conductor`` with ``material = "none"``
(``reference/materials/mirror.py``).
"""

from __future__ import annotations

from dataclasses import dataclass

from whitted.tracer.backend import deferred
from whitted.tracer.materials import base
from whitted.tracer.settings import Table

fresnel = deferred("whitted.tracer.fresnel")

Color = tuple[float, float, float]


@dataclass(frozen=True)
class Mirror(base.MaterialModel):
    reflectance: Color = (1.0, 1.0, 1.0)
    two_sided: bool = True


MODEL = Mirror


def parse(t: Table, name: str) -> Mirror:
    return Mirror(name, t.color("reflectance", 1.0, hi=1.0), base.parse_two_sided(t))


class BSDF(base.BSDF):
    lobes = (base.REFLECT,)

    def __init__(self, materials: list[Mirror]):
        super().__init__(materials)
        self.reflectance = base.colors([m.reflectance for m in materials])

    def params(self, row, si, active):
        return base.gather(self.reflectance, row, active)

    def delta_lobes(self, reflectance, si):
        return [(fresnel.reflect(si.d, si.ns), reflectance)]
