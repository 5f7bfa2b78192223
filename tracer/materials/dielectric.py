"""``type = "dielectric"``: a smooth boundary between two dielectrics (glass, water, diamond).

Two delta lobes (lecture 1, "The Fresnel equation", "Snell's law", "Total
internal reflection"; pbrt-v4, ``DielectricBxDF``, section 9.5): the mirror
reflection with weight R, and the refraction by Snell's law with weight
(1 - R)(n1 / n2)^2, where R comes from the exact Fresnel equations or, with
``fresnel = "schlick"``, Schlick's approximation (tracer-only: Mitsuba's
``dielectric`` is always exact, so a scene declares it in ``[compare]``).
Radiance crossing from index n1 into n2 is scaled by (n1 / n2)^2 because the
same flux passes through a solid angle compressed by (n1 / n2)^2 (Veach's
thesis, section 5.2; pbrt-v4, section 9.5.2). Under total internal
reflection R = 1 and the refraction carries nothing. ``ior`` is the index
on the side the normal points away from, ``ext_ior`` the outside.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

from whitted.tracer import faults
from whitted.tracer.backend import deferred
from whitted.tracer.materials import base
from whitted.tracer.settings import Table

dr = deferred("drjit")
fresnel = deferred("whitted.tracer.fresnel")


@dataclass(frozen=True)
class Dielectric(base.MaterialModel):
    ior: float = 1.5
    ext_ior: float = 1.0
    fresnel: str = "exact"  # or "schlick" (tracer only; Mitsuba is always exact)

    tracer_only_parts = ("schlick",)

    @property
    def eta(self) -> float:
        return self.ior / self.ext_ior

    def tracer_only_used(self) -> frozenset[str]:
        return frozenset({"schlick"}) if self.fresnel == "schlick" else frozenset()

    def comparable(self, declared: tuple[str, ...]) -> Dielectric:
        return replace(self, fresnel="exact") if "schlick" in declared else self


MODEL = Dielectric


def parse(t: Table, name: str) -> Dielectric:
    return Dielectric(name, ior=base.parse_ior(t, "ior", 1.5),
                      ext_ior=base.parse_ior(t, "ext_ior", 1.0),
                      fresnel=t.string("fresnel", "exact", ("exact", "schlick")))


class BSDF(base.BSDF):
    lobes = (base.REFLECT, base.TRANSMIT)

    def __init__(self, materials: list[Dielectric]):
        super().__init__(materials)
        self.eta = base.floats([m.eta for m in materials])
        self.schlick = base.flags([m.fresnel == "schlick" for m in materials])
        self.has_schlick = any(m.fresnel == "schlick" for m in materials)

    def params(self, row, si, active):
        # eta = 1 off this kind's lanes keeps their (unused) arithmetic finite.
        eta = dr.select(active, base.gather(self.eta, row, active), 1.0)
        schlick = base.gather(self.schlick, row, active) if self.has_schlick else None
        return eta, schlick

    def delta_lobes(self, prm, si):
        eta, schlick = prm
        r = fresnel.fresnel_exact(si.cos_i, eta)
        if schlick is not None:
            r = dr.select(schlick, fresnel.fresnel_schlick(si.cos_i, eta), r)
        t_dir, tir = fresnel.refract(si.d, si.ns, eta)
        # Radiance crossing from n_i into n_t is scaled by (n_i / n_t)^2.
        n_ratio = dr.select(si.cos_i >= 0, dr.rcp(eta), eta)
        n_ratio = faults.pick("inverted-eta2", lambda: dr.rcp(n_ratio), n_ratio)
        n_ratio = faults.pick("no-eta2-scaling",
                              lambda: dr.ones(type(n_ratio), dr.width(n_ratio)), n_ratio)
        t = faults.pick("no-fresnel-on-transmission", lambda: dr.ones(type(r), dr.width(r)),
                        1 - r)
        transmitted = dr.select(tir, 0, t * n_ratio * n_ratio)
        return [(fresnel.reflect(si.d, si.ns), r), (t_dir, transmitted)]
