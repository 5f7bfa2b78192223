"""``type = "thindielectric"``: a thin sheet of glass (Mitsuba 3's ``thindielectric``).

A sheet so thin that a ray leaves it where it entered: reflection by the law
of reflection with the slab's reflectance

    R' = R + T^2 R (1 + R^2 + R^4 + ...) = R + T^2 R / (1 - R^2) = 2R / (1 + R),

T = 1 - R, summed over all inner reflections
(:func:`tracer.fresnel.thin_slab_reflectance`, R the exact Fresnel reflectance
of one face: lecture 1, "The Fresnel equation"), and the rest,
1 - R' = (1 - R) / (1 + R), passing straight through without bending (no
scattering event: the letter "" in light-path expressions, Mitsuba's null
lobe). Sources: pbrt-v4, section 9.5 (``ThinDielectricBxDF``, the same
geometric series); Mitsuba 3's plugin reference, ``thindielectric``, its
counterpart (``reference/materials/thindielectric.py``). ``ior`` and
``ext_ior`` may be Mitsuba's names (``"bk7"``).
"""

from __future__ import annotations

from dataclasses import dataclass

from whitted.tracer.backend import deferred
from whitted.tracer.materials import base
from whitted.tracer.settings import Table

dr = deferred("drjit")
fresnel = deferred("whitted.tracer.fresnel")


@dataclass(frozen=True)
class ThinDielectric(base.MaterialModel):
    ior: float = 1.5
    ext_ior: float = 1.0


MODEL = ThinDielectric


def parse(t: Table, name: str) -> ThinDielectric:
    return ThinDielectric(name, ior=base.parse_ior(t, "ior", 1.5),
                          ext_ior=base.parse_ior(t, "ext_ior", 1.0))


class BSDF(base.BSDF):
    lobes = (base.REFLECT, base.Lobe("transmit", ""))

    def __init__(self, materials: list[ThinDielectric]):
        super().__init__(materials)
        self.eta = base.floats([m.ior / m.ext_ior for m in materials])

    def params(self, row, si, active):
        return dr.select(active, base.gather(self.eta, row, active), 1.0)

    def delta_lobes(self, eta, si):
        # The same R from either face: the slab is symmetric.
        r = fresnel.thin_slab_reflectance(fresnel.fresnel_exact(dr.abs(si.cos_i), eta))
        return [(fresnel.reflect(si.d, si.ns), r), (si.d, 1 - r)]
