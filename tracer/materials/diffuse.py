"""``type = "diffuse"``: Lambertian reflection, f = reflectance / pi.

Lambert's law (lecture 1, "The illumination equation"; pbrt-v4,
``DiffuseBxDF``, section 9.2): the surface scatters the light it receives
equally in all directions, so the BRDF is a constant, and energy conservation
bounds it by 1 / pi (the integral of cos over the hemisphere is pi). The
reflectance is a colour or a checkerboard. Mitsuba's counterpart is the
``diffuse`` plugin, made two-sided (``reference/materials/diffuse.py``)
unless ``two_sided = false`` (black from behind, as Mitsuba's bare ``diffuse``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from whitted.tracer import faults
from whitted.tracer.materials import base
from whitted.tracer.materials.textures import Texture, TextureTable, parse_texture
from whitted.tracer.settings import Table


@dataclass(frozen=True)
class Diffuse(base.MaterialModel):
    reflectance: Texture = (0.5, 0.5, 0.5)
    two_sided: bool = True

    def textures(self) -> tuple:
        return (self.reflectance,)


MODEL = Diffuse


def parse(t: Table, name: str) -> Diffuse:
    return Diffuse(name, parse_texture(t, "reflectance", 0.5), base.parse_two_sided(t))


class BSDF(base.BSDF):
    smooth = True

    def __init__(self, materials: list[Diffuse]):
        super().__init__(materials)
        self.kd = TextureTable([m.reflectance for m in materials])

    def params(self, row, si, active):
        return self.kd.eval(row, si.uv, active)

    def eval(self, kd, si, wi):
        return faults.pick("lambert-no-inv-pi", lambda: kd, kd * (1 / math.pi))
