"""``type = "classic"``: the illumination model of Whitted (1980) and Heckbert's minray (1987).

Whitted, "An Improved Illumination Model for Shaded Display" (CACM 23(6),
1980), writes the light leaving a surface towards the eye as

    I = Ia + kd sum_j (N . L_j) + ks S + kt T,

and lecture 1 ("The illumination equation with recursion") writes the same
sum with the recursion spelled out: S and T are what the reflected and the
refracted rays bring back, computed by the same equation at their hits.
Heckbert's business-card ray tracer (minray, 1987), the program of the first
assignment, implements it per sphere {colour, kd, ks, kt, kl, ir} as

    I = kd colour (Ia + sum_j kl_j (N . L_j) colour_j) + ks S + kt T + kl colour,

and this kind is that model, term by term:

* **ambient** (``ambient``, Ia): a constant light added to the direct light
  *before* the multiplication by kd x colour, so it is reflected as
  kd colour Ia, everywhere, without a shadow test. minray's Ia is 0.02; a ray
  that hits nothing returns it too, which here is a separate backdrop light,
  ``[[lights]] type = "background"`` (:mod:`tracer.emitters.background`).
* **diffuse** (``kd``, ``color``): the smooth part, f = kd x colour without
  the 1/pi of a Lambertian BRDF (the classic model is not radiometric: the
  light's value times N . L times kd colour is the reflected intensity).
* **lights** (``kl``): every sphere with kl > 0 is a light, Heckbert's light
  sphere (:mod:`tracer.emitters.heckbert`): it adds kl colour_j (N . L_j)
  from the direction of its centre with **no falloff**, seen when the first
  surface towards the centre is that sphere; and a ray that hits it brings
  back its glow kl x colour (a hit term, below).
* **reflection and transmission** (``ks``, ``kt``): two delta lobes, the
  mirror direction with the fixed weight ks and the refracted one with the
  fixed weight kt; no Fresnel term, no (n1 / n2)^2 radiance scale, and
  **not tinted by the colour**. Under total internal reflection there is no
  refracted ray (its weight is 0) and the reflection keeps ks.
* **refraction index** (``ir``): Snell's law with the index ``ir`` inside the
  surface (the side its normal points away from) and 1 outside, which is
  what minray does. Its normal is the centre minus the hit point, pointing
  *inwards*, so a ray arriving from outside is the case that flips the
  normal outwards and refracts with n1 / n2 = 1 / ir, and a ray leaving
  refracts with ir. (Read with an outward normal, the code would seem to
  enter with n1 / n2 = ir and reflect totally beyond 36 degrees for ir 1.7;
  an instrumented build of minray traces the refracted ray at 65 degrees of
  incidence, and its stored images of tests/data/minray/ at DEPTH 3 and more
  are reproduced only this way.) Under total internal reflection,
  1 - (n1/n2)^2 (1 - cos^2) <= 0, there is no refracted ray.
* **emission** is a hit term (:mod:`tracer.emitters.base`): counted with the
  shading of the hit, for rays of depth < max_depth, so max_depth = DEPTH + 1
  counts Heckbert's DEPTH exactly (trace calls: DEPTH 1 shades the camera
  rays' hits, DEPTH 2 also the hits of their reflected and refracted rays).

In light-path expressions the diffuse part and the ambient term are a ``D``
(the ambient term: ``DL``), reflection and transmission an ``S``, the glow an
``L``. Mitsuba's counterpart is the ``whitted_classic`` BSDF written on its
API (``reference/materials/classic.py``), with Heckbert's lights and the
backdrop as emitters written on its API (``reference/emitters/``); the
ambient term has no counterpart there and is declared tracer-only
(``[compare] tracer_only = ["ambient"]``).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

from whitted.tracer import faults
from whitted.tracer.backend import deferred
from whitted.tracer.materials import base
from whitted.tracer.materials.textures import Checkerboard, Texture, TextureTable, parse_texture
from whitted.tracer.settings import Table

if TYPE_CHECKING:
    from whitted.tracer.emitters.heckbert import HeckbertSphere

dr = deferred("drjit")
fresnel = deferred("whitted.tracer.fresnel")

Color = tuple[float, float, float]


@dataclass(frozen=True)
class Classic(base.MaterialModel):
    """Whitted's and Heckbert's fixed-weight model (see the module docstring)."""
    color: Texture = (1.0, 1.0, 1.0)
    kd: float = 0.0
    ks: float = 0.0
    kt: float = 0.0
    kl: float = 0.0
    ir: float = 1.0                      # index inside; 1 outside
    ambient: Color = (0.0, 0.0, 0.0)     # Ia: reflected as kd colour Ia (tracer-only)

    tracer_only_parts = ("ambient",)

    def tracer_only_used(self) -> frozenset[str]:
        return frozenset({"ambient"}) if self.kd > 0 and any(self.ambient) else frozenset()

    def comparable(self, declared: tuple[str, ...]) -> Classic:
        return replace(self, ambient=(0.0, 0.0, 0.0)) if "ambient" in declared else self

    def textures(self) -> tuple:
        return (self.color,)

    def light_of(self, shape) -> HeckbertSphere | None:
        """Heckbert's light sphere for a sphere with kl > 0 (:mod:`tracer.emitters.heckbert`)."""
        if self.kl <= 0:
            return None
        from whitted.tracer.emitters.heckbert import HeckbertSphere

        if shape.shape_type != "sphere":
            raise ValueError(f'material "{self.name}" has kl > 0, which makes a light of a '
                             "sphere (lit from its centre), not of a "
                             f"{type(shape).__name__.lower()}")
        if isinstance(self.color, Checkerboard):
            raise ValueError(f'material "{self.name}" has kl > 0: a light needs a plain '
                             "colour, not a texture")
        value = tuple(self.kl * c for c in self.color)
        return HeckbertSphere(shape.center, shape.radius, value)


MODEL = Classic


def parse(t: Table, name: str) -> Classic:
    weight = {"lo": 0.0}
    return Classic(name, color=parse_texture(t, "color", 1.0, hi=None),
                   kd=t.number("kd", 0.0, **weight), ks=t.number("ks", 0.0, **weight),
                   kt=t.number("kt", 0.0, **weight), kl=t.number("kl", 0.0, **weight),
                   ir=t.number("ir", 1.0, lo=0, lo_open=True),
                   ambient=t.color("ambient", 0.0))


class BSDF(base.BSDF):
    smooth = True
    lobes = (base.REFLECT, base.TRANSMIT)

    def __init__(self, materials: list[Classic]):
        super().__init__(materials)
        self.color = TextureTable([m.color for m in materials])
        self.kd = base.floats([m.kd for m in materials])
        self.ks = base.floats([m.ks for m in materials])
        self.kt = base.floats([m.kt for m in materials])
        self.kl = base.floats([m.kl for m in materials])
        self.ambient = base.colors([m.ambient for m in materials])
        self.eta = base.floats([m.ir for m in materials])
        self.has_ambient = any(m.kd > 0 and any(m.ambient) for m in materials)
        self.has_glow = any(m.kl > 0 for m in materials)
        self.emits = self.has_ambient or self.has_glow

    def params(self, row, si, active):
        g = base.gather
        # eta = 1 off this kind's lanes keeps their (unused) arithmetic finite.
        eta = dr.select(active, g(self.eta, row, active), 1.0)
        return (self.color.eval(row, si.uv, active), g(self.kd, row, active),
                g(self.ks, row, active), g(self.kt, row, active), g(self.kl, row, active),
                g(self.ambient, row, active) if self.has_ambient else None, eta)

    def eval(self, prm, si, wi):
        color, kd = prm[0], prm[1]
        return kd * color   # Heckbert: kd colour (kl_j colour_j (N . L_j)), no 1 / pi

    def delta_lobes(self, prm, si):
        color, _, ks, kt, _, _, eta = prm
        t_dir, tir = fresnel.refract(si.d, si.ns, eta)
        ks = faults.pick("classic-reflection-tinted", lambda: ks * color, ks)
        return [(fresnel.reflect(si.d, si.ns), ks), (t_dir, dr.select(tir, 0.0, kt))]

    def emission_terms(self, prm, si):
        color, kd, _, _, kl, ambient, _ = prm
        out = []
        if self.has_ambient:
            out.append((kd * color * ambient, "DL"))   # Ia before the colour multiply
        if self.has_glow:
            out.append((kl * color, "L"))              # a light sphere's glow
        return out
