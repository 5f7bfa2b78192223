"""``type = "plastic"``: a smooth plastic, a diffuse base under a smooth dielectric coating.

Mitsuba 3's smooth ``plastic`` (Weidlich and Wilkie 2007 in the smooth
limit): two lobes at once,

* the coating's mirror reflection, a delta lobe of weight
  ``specular_reflectance`` x F(theta_i), F the exact Fresnel reflectance of
  the coating (lecture 1, "The Fresnel equation"; :func:`tracer.fresnel.fresnel_exact`);
* the base's diffuse light seen through the coating, a smooth part
  f = kd' (1 - F_i)(1 - F_o) / (eta^2 pi) with the internal-scattering
  normalisation kd' = kd / (1 - F_dr) (or kd / (1 - kd F_dr) with
  ``nonlinear = true``): :func:`tracer.fresnel.plastic_diffuse`.

``ior`` (1.49, polypropylene) and ``ext_ior`` (1.000277, air) are Mitsuba's
defaults and may be its names. ``two_sided = false`` makes it black from behind,
as Mitsuba's bare ``plastic`` is.
"""

from __future__ import annotations

from dataclasses import dataclass

from whitted.tracer.backend import deferred
from whitted.tracer.materials import base
from whitted.tracer.materials.textures import Texture, TextureTable, parse_texture
from whitted.tracer.settings import Table

dr = deferred("drjit")
fresnel = deferred("whitted.tracer.fresnel")


@dataclass(frozen=True)
class Plastic(base.MaterialModel):
    diffuse_reflectance: Texture = (0.5, 0.5, 0.5)
    specular_reflectance: Texture = (1.0, 1.0, 1.0)
    ior: float = 1.49
    ext_ior: float = 1.000277
    nonlinear: bool = False
    two_sided: bool = True

    @property
    def eta(self) -> float:
        return self.ior / self.ext_ior

    def textures(self) -> tuple:
        return (self.diffuse_reflectance, self.specular_reflectance)


MODEL = Plastic


def parse(t: Table, name: str) -> Plastic:
    nonlinear = t.boolean("nonlinear", False)
    return Plastic(name, parse_texture(t, "diffuse_reflectance", 0.5),
                   parse_texture(t, "specular_reflectance", 1.0, hi=None),
                   base.parse_ior(t, "ior", 1.49), base.parse_ior(t, "ext_ior", 1.000277),
                   nonlinear, base.parse_two_sided(t))


class BSDF(base.BSDF):
    smooth = True
    lobes = (base.REFLECT,)

    def __init__(self, materials: list[Plastic]):
        super().__init__(materials)
        self.kd = TextureTable([m.diffuse_reflectance for m in materials])
        self.ks = TextureTable([m.specular_reflectance for m in materials])
        self.eta = base.floats([m.eta for m in materials])
        # F_dr seen from inside the coating: its relative index is 1 / eta there.
        self.fdr_int = fresnel.fresnel_diffuse_reflectance(dr.rcp(self.eta))
        self.nonlinear = base.flags([m.nonlinear for m in materials])

    def params(self, row, si, active):
        eta = dr.select(active, base.gather(self.eta, row, active), 1.0)
        return (self.kd.eval(row, si.uv, active), self.ks.eval(row, si.uv, active), eta,
                base.gather(self.fdr_int, row, active), base.gather(self.nonlinear, row, active))

    def eval(self, prm, si, wi):
        kd, _, eta, fdr_int, nonlinear = prm
        f_i = fresnel.fresnel_exact(dr.abs(si.cos_i), eta)
        f_o = fresnel.fresnel_exact(dr.maximum(dr.dot(si.nl, wi), 0), eta)
        return fresnel.plastic_diffuse(kd, f_i, f_o, eta, fdr_int, nonlinear)

    def delta_lobes(self, prm, si):
        _, ks, eta, _, _ = prm
        return [(fresnel.reflect(si.d, si.ns), ks * fresnel.fresnel_exact(dr.abs(si.cos_i), eta))]
