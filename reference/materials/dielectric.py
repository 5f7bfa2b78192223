"""Mitsuba conversion of ``dielectric`` (tracer/materials/dielectric.py), and ``whitted_schlick``.

Mitsuba's ``dielectric`` with both indices set (its default ``ext_ior`` is
air, 1.000277, not 1). It is always exact Fresnel: Schlick's approximation is
tracer-only (``[compare] tracer_only = ["schlick"]``, see
:meth:`Dielectric.comparable`), and the conversion leaves it out.

Mitsuba has no Schlick dielectric, so for a declared ``"schlick"`` the
harness also has a model of its own, ``whitted_schlick``
(:func:`mitsuba_model`): a BSDF written in Python on Mitsuba's API from the
formulas, not from :mod:`tracer.fresnel`, against which the tracer's
Schlick renders are judged as they are (``reference.verdicts.compare``). In
Mitsuba's local frame (normal +z, ``si.wi`` towards the viewer, pointing
away from the surface) it has two delta components, on both sides:

0. **reflection**: wo = (-wi.x, -wi.y, wi.z), weight R;
1. **transmission**: Snell's law n_i sin(theta_i) = n_t sin(theta_t), with
   n_t / n_i = eta = int_ior / ext_ior entering (cos theta_i > 0) and 1 / eta
   leaving; for the travel direction d = -wi and the normal n' on wi's side,
   t = d / rel + (cos_i / rel - cos_t) n' (rel = n_t / n_i); weight
   (1 - R) (n_i / n_t)^2, the radiance scale of a boundary crossing (Veach's
   thesis, section 5.2); none under total internal reflection.

R is Schlick's approximation (Schlick, "An Inexpensive BRDF Model for
Physically-based Rendering", Computer Graphics Forum 13(3), 1994; lecture 1,
"The Fresnel equation (simplified)"): R = R0 + (1 - R0)(1 - cos theta)^5 with
R0 = ((eta - 1) / (eta + 1))^2 and theta the angle on the less dense side
(theta_i entering the denser medium, theta_t leaving it). Fresnel reflectance
is the same either way along a path (Stokes' relations; Hecht, "Optics",
section 4.10), so the reflectance seen from the dense side at theta_i is the
one seen from the rare side at theta_t, which is the angle Schlick's fit is
made for; R = 1 beyond the critical angle.

Sampling, as Mitsuba's ``dielectric``: with both components enabled,
reflection with probability R (weight 1) or transmission with 1 - R (weight
(n_i / n_t)^2); a ``BSDFContext`` that keeps one component returns that one
with probability 1 and its whole weight, which is what the deterministic
reference asks for.

LuxCore (:func:`luxcore`): ``glass`` with ``kr = kt = 1``, ``interiorior`` =
``ior`` (behind the normal) and ``exteriorior`` = ``ext_ior``: exact Fresnel
reflectance R, transmission 1 - R, total internal reflection; the
transmitted radiance is scaled per crossing (measured: glass_sphere,
tir_prisms, whitted_mix and schlick_diamond agree three ways, and swapping
the two indices makes LuxCore the odd one out). Schlick's approximation has
no LuxCore equivalent: a declared ``"schlick"`` is compared exact, as with
Mitsuba; an undeclared one is refused.
"""

from __future__ import annotations

import drjit as dr

from whitted.reference.renderers.mitsuba.tree import per_variant
from whitted.tracer.errors import UserError
from whitted.tracer.materials.dielectric import Dielectric

#: the Mitsuba plugins this module registers
PLUGINS = ("whitted_schlick",)


def mitsuba(m: Dielectric) -> dict:
    return {"type": "dielectric", "int_ior": ("float", m.ior), "ext_ior": ("float", m.ext_ior)}


def luxcore(m: Dielectric) -> dict:
    if m.fresnel != "exact":
        raise UserError(f"material {m.name!r}: Schlick's Fresnel has no LuxCore equivalent "
                        "(declare it in [compare] tracer_only to compare it exact)")
    return {"type": "glass", "kr": (1.0, 1.0, 1.0), "kt": (1.0, 1.0, 1.0),
            "interiorior": m.ior, "exteriorior": m.ext_ior}


def mitsuba_model(m: Dielectric) -> dict | None:
    """The harness's own model of the material's tracer-only part: Schlick's dielectric."""
    if m.fresnel != "schlick":
        return None
    return {"type": "whitted_schlick", "int_ior": ("float", m.ior),
            "ext_ior": ("float", m.ext_ior)}


def register(mi) -> None:
    """Register ``whitted_schlick`` with Mitsuba, whose variant must be set."""
    cls = plugin_class(mi)
    mi.register_bsdf("whitted_schlick", lambda props: cls(props))


#: The ``whitted_schlick`` BSDF class for Mitsuba's current variant.
plugin_class = per_variant(lambda mi: _define(mi))


def _define(mi):
    class SchlickDielectric(mi.BSDF):
        """A smooth dielectric boundary with Schlick's reflectance (module docstring)."""

        def __init__(self, props: mi.Properties):
            super().__init__(props)
            self.eta = float(props.get("int_ior", 1.5)) / float(props.get("ext_ior", 1.0))
            if not self.eta > 0:
                raise ValueError("whitted_schlick: the indices must be positive")
            self.r0 = ((self.eta - 1) / (self.eta + 1)) ** 2
            both = mi.BSDFFlags.FrontSide | mi.BSDFFlags.BackSide
            self.m_components = [mi.BSDFFlags.DeltaReflection | both,
                                 mi.BSDFFlags.DeltaTransmission | both |
                                 mi.BSDFFlags.NonSymmetric]
            self.m_flags = self.m_components[0] | self.m_components[1]

        def lobes(self, wi):
            """(R, transmitted direction, rel = n_t / n_i, total internal reflection)."""
            cos_i = mi.Frame3f.cos_theta(wi)
            c = dr.abs(cos_i)
            rel = dr.select(cos_i > 0, self.eta, 1.0 / self.eta)
            sin2_t = (1 - c * c) / (rel * rel)
            tir = sin2_t > 1
            cos_t = dr.safe_sqrt(1 - sin2_t)
            # Schlick's cosine: the angle on the less dense side.
            cos_rare = dr.select(rel >= 1, c, cos_t)
            r = self.r0 + (1 - self.r0) * dr.power(1 - cos_rare, 5)
            r = dr.select(tir, 1.0, r)
            n = mi.Vector3f(0, 0, dr.sign(cos_i))     # the normal on wi's side
            t = -wi / rel + (c / rel - cos_t) * n
            return r, t, rel, tir

        def sample(self, ctx, si, sample1, sample2, active=True):
            active = mi.Bool(active)
            r, t_dir, rel, tir = self.lobes(si.wi)
            has_r = ctx.is_enabled(mi.BSDFFlags.DeltaReflection, 0)
            has_t = ctx.is_enabled(mi.BSDFFlags.DeltaTransmission, 1)
            t = dr.select(tir, 0.0, 1 - r)
            n = dr.width(r)
            if has_r and has_t:
                reflect = sample1 <= r
                pdf = dr.select(reflect, r, t)
            elif has_r or has_t:
                reflect, pdf = dr.full(mi.Bool, has_r, n), dr.full(mi.Float, 1.0, n)
            else:
                return dr.zeros(mi.BSDFSample3f, n), dr.zeros(mi.Color3f, n)
            bs = dr.zeros(mi.BSDFSample3f)
            bs.wo = dr.select(reflect, mi.Vector3f(-si.wi.x, -si.wi.y, si.wi.z), t_dir)
            bs.eta = dr.select(reflect, 1.0, rel)
            bs.sampled_component = dr.select(reflect, mi.UInt32(0), mi.UInt32(1))
            bs.sampled_type = dr.select(reflect, mi.UInt32(+mi.BSDFFlags.DeltaReflection),
                                        mi.UInt32(+mi.BSDFFlags.DeltaTransmission))
            value = dr.select(reflect, r, t / (rel * rel))
            ok = active & (pdf > 0)
            bs.pdf = dr.select(ok, pdf, 0.0)
            return bs, mi.Color3f(dr.select(ok, value / dr.select(ok, pdf, 1.0), 0.0))

        def eval(self, ctx, si, wo, active=True):
            return mi.Color3f(0.0)     # delta components only

        def pdf(self, ctx, si, wo, active=True):
            return mi.Float(0.0)

        def eval_pdf(self, ctx, si, wo, active=True):
            return mi.Color3f(0.0), mi.Float(0.0)

        def traverse(self, cb):
            pass

        def parameters_changed(self, keys):
            pass

        def to_string(self):
            return f"SchlickDielectric[eta = {self.eta}]"

    return SchlickDielectric
