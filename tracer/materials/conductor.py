"""``type = "conductor"``: a smooth metal, one delta lobe weighted by the conductor's Fresnel term.

The law of reflection (lecture 1, "Reflection") with the weight
``specular_reflectance`` x R(theta_i), R the Fresnel reflectance of a
conductor of complex index eta + i k (pbrt-v4, section 9.3 and
``ConductorBxDF`` in its smooth limit; Mitsuba 3's ``conductor``):
:func:`tracer.fresnel.fresnel_conductor`: R = (R_s + R_p) / 2, the
reflectances of the two polarisations for cos_t = sqrt(1 - sin^2(theta_i) /
(eta + i k)^2), in Born and Wolf's real arithmetic ("Principles of Optics",
7th ed., section 14.2); k = 0 gives a dielectric's R, and eta = 0, k = 1
gives R = 1 at every angle. The index is Mitsuba's named
conductor (``material = "Au"``, the RGB values of :mod:`tracer.ior`) or given
as ``eta`` and ``k``. ``two_sided = false`` makes it black from behind, as
Mitsuba's bare ``conductor`` is. Mitsuba's counterpart is ``conductor``
(``reference/materials/conductor.py``).
"""

from __future__ import annotations

from dataclasses import dataclass

from whitted.tracer.backend import deferred
from whitted.tracer.materials import base
from whitted.tracer.materials.textures import Texture, TextureTable, parse_texture
from whitted.tracer.settings import Table

fresnel = deferred("whitted.tracer.fresnel")

Color = tuple[float, float, float]


@dataclass(frozen=True)
class Conductor(base.MaterialModel):
    eta: Color = (0.0, 0.0, 0.0)
    k: Color = (1.0, 1.0, 1.0)
    specular_reflectance: Texture = (1.0, 1.0, 1.0)
    two_sided: bool = True
    #: Mitsuba's name of the conductor the indices come from ("" if given as eta and k)
    material: str = ""

    def textures(self) -> tuple:
        return (self.specular_reflectance,)


MODEL = Conductor


def parse(t: Table, name: str) -> Conductor:
    from whitted.tracer.ior import CONDUCTORS

    if t.has("material") and (t.has("eta") or t.has("k")):
        t.fail("material", "give either material or eta and k, not both")
    if t.has("eta") or t.has("k"):
        eta, k, named = t.color("eta"), t.color("k"), ""
    else:
        named = t.string("material", "none")
        if named not in CONDUCTORS:
            t.fail("material", f"unknown conductor {named!r} (one of {', '.join(CONDUCTORS)})")
        eta, k = CONDUCTORS[named]
    return Conductor(name, eta, k, parse_texture(t, "specular_reflectance", 1.0, hi=None),
                     base.parse_two_sided(t), named)


class BSDF(base.BSDF):
    lobes = (base.REFLECT,)

    def __init__(self, materials: list[Conductor]):
        super().__init__(materials)
        self.eta = base.colors([m.eta for m in materials])
        self.k = base.colors([m.k for m in materials])
        self.ks = TextureTable([m.specular_reflectance for m in materials])

    def params(self, row, si, active):
        return (base.gather(self.eta, row, active), base.gather(self.k, row, active),
                self.ks.eval(row, si.uv, active))

    def delta_lobes(self, prm, si):
        eta, k, ks = prm
        r = fresnel.fresnel_conductor(si.cos_i, eta, k)
        return [(fresnel.reflect(si.d, si.ns), ks * r)]
