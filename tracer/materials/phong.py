"""``type = "phong"``: a Lambertian part plus a normalised Phong or Blinn-Phong lobe.

    f(wi, wo) = kd / pi + ks N(p) cos^p(alpha),

both parts smooth (summed over the lights; lecture 2, "Specular highlights":
the Phong exponent p, the reflected light direction, the halfway vector),
with ``model`` choosing the angle alpha and N(p) the normalisation that makes
the lobe conserve energy (kd + ks <= 1 in every channel):

* ``"phong"``: alpha between wo and the mirror image of wi, N = (p + 2) / (2 pi)
  (Phong, CACM 18(6), 1975, in the reciprocal form of Lafortune and Willems,
  KU Leuven CW 197, 1994);
* ``"blinn-phong"``: alpha between the normal and the half vector
  h = (wi + wo) / |wi + wo|, N = (p + 2)(p + 4) / (8 pi (2^(-p/2) + p))
  (Blinn, SIGGRAPH 1977; Giesen, "The Blinn-Phong Normalization Zoo", 2009).

The derivations are in :mod:`tracer.phong`. ``ambient`` is the lecture's
constant ambient term (lecture 2, "Ambient term": "the cheapest of all
hacks"), added at every hit as light arriving through the diffuse part;
Mitsuba has none, so a scene declares it tracer-only. Mitsuba's counterpart
is the ``whitted_phong`` BSDF written in ``reference/materials/phong.py``.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

from whitted.tracer.backend import deferred
from whitted.tracer.materials import base
from whitted.tracer.materials.textures import Checkerboard, Texture, TextureTable, parse_texture
from whitted.tracer.settings import Table

dr = deferred("drjit")
phong = deferred("whitted.tracer.phong")

Color = tuple[float, float, float]
#: The lobe's models (those of tracer.phong, which is imported only when rendering).
MODELS = ("phong", "blinn-phong")


@dataclass(frozen=True)
class Phong(base.MaterialModel):
    """kd / pi + ks N(p) cos^p: Phong (reflected direction) or Blinn-Phong (half vector)."""
    diffuse: Texture = (0.5, 0.5, 0.5)
    specular: Color = (0.2, 0.2, 0.2)
    exponent: float = 32.0
    model: str = "phong"               # or "blinn-phong"
    ambient: Color = (0.0, 0.0, 0.0)   # tracer-only: radiance added at every hit

    tracer_only_parts = ("ambient",)

    def tracer_only_used(self) -> frozenset[str]:
        return frozenset({"ambient"}) if any(self.ambient) else frozenset()

    def comparable(self, declared: tuple[str, ...]) -> Phong:
        return replace(self, ambient=(0.0, 0.0, 0.0)) if "ambient" in declared else self

    def textures(self) -> tuple:
        return (self.diffuse,)


MODEL = Phong


def parse(t: Table, name: str) -> Phong:
    diffuse = parse_texture(t, "diffuse", 0.5)
    specular = t.color("specular", 0.2, hi=1.0)
    m = Phong(name, diffuse, specular,
              exponent=t.number("exponent", 32.0, lo=0, lo_open=True, hi=1e4),
              model=t.string("model", "phong", MODELS),
              ambient=t.color("ambient", 0.0))
    kds = [diffuse.color0, diffuse.color1] if isinstance(diffuse, Checkerboard) else [diffuse]
    for k in kds:
        if any(a + b > 1 + 1e-9 for a, b in zip(k, specular, strict=True)):
            t.fail("specular", "expected diffuse + specular <= 1 in every channel "
                               "(beyond that the BRDF creates energy)")
    return m


class BSDF(base.BSDF):
    smooth = True

    def __init__(self, materials: list[Phong]):
        super().__init__(materials)
        self.kd = TextureTable([m.diffuse for m in materials])
        self.ks = base.colors([m.specular for m in materials])
        self.exponent = base.floats([m.exponent for m in materials])
        self.blinn = base.flags([m.model == "blinn-phong" for m in materials])
        self.ambient = base.colors([m.ambient for m in materials])
        self.models = [name for name in MODELS if any(m.model == name for m in materials)]
        self.emits = any(any(m.ambient) for m in materials)

    def params(self, row, si, active):
        ambient = base.gather(self.ambient, row, active) if self.emits else None
        return (self.kd.eval(row, si.uv, active), base.gather(self.ks, row, active),
                base.gather(self.exponent, row, active), base.gather(self.blinn, row, active),
                ambient)

    def eval(self, prm, si, wi):
        kd, ks, exponent, blinn, _ = prm
        f = [phong.phong_brdf(si.nl, wi, si.wo, kd, ks, exponent, model)
             for model in self.models]
        return f[0] if len(f) == 1 else dr.select(blinn, f[1], f[0])

    def emission(self, prm, si):
        return prm[4]
