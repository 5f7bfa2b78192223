"""Mitsuba conversion of ``classic`` (tracer/materials/classic.py): its BSDF ``whitted_classic``.

Mitsuba 3 has no BSDF for the fixed-weight model of Whitted (1980) and
Heckbert's minray (1987), so the harness renders the tracer's ``classic``
material with this one, written in Python on Mitsuba's API from the
formulas (it does not call the tracer's code, so that the two check each
other). In Mitsuba's local shading frame (normal +z; ``si.wi`` towards the
camera side, ``wo`` towards the light, both away from the surface) it has
three components, each on both sides of the surface:

0. **diffuse** (smooth): eval = kd colour |cos theta_o| where wi and wo lie
   on the same side, 0 across: f = kd colour without 1/pi, the classic
   model's I = kd sum_j kl_j (N . L_j) colour_j (Mitsuba's ``eval`` includes
   the cosine);
1. **reflection** (delta): wo = (-wi.x, -wi.y, wi.z) with the fixed weight ks;
2. **transmission** (delta): Snell's law with n1 / n2 = 1 / ir entering from
   the side the normal points to (cos theta_i > 0) and ir leaving, t =
   eta d + (eta cos_i - sqrt(1 - eta^2 (1 - cos_i^2))) n' for the incident
   travel direction d = -wi and the normal n' on the incident side, with
   the fixed weight kt, and no ray where the root is not positive (total
   internal reflection).

Neither delta weight is tinted by the colour, scaled by (n1 / n2)^2 or by a
Fresnel term. The weights are not normalised: kd + ks + kt may exceed 1, as
in minray's glass (0.05 + 0.2 + 0.85).

Sampling picks an enabled component with probability proportional to its
weight at the hit (kd x mean colour, ks, and kt unless totally reflected),
then a cosine-weighted direction on the side of wi for the diffuse part;
the returned weight is the component's value over its probability (for the
delta components ks / p and kt / p), so the expectation over the components
is the sum the tracer computes by following both delta lobes. A
``BSDFContext`` whose type or component mask keeps one component returns
that component alone, with its weight.

The ambient term (kd colour Ia, added at every hit without a shadow test) is
not part of this BSDF: Mitsuba's BSDFs do not emit and its lights are
shadowed, so a scene declares it tracer-only. Heckbert's light spheres and
the backdrop are emitters written on Mitsuba's API beside those of the
tracer (``reference/emitters/heckbert.py``, ``reference/emitters/background.py``).

:func:`register` defines the class and registers it once Mitsuba's variant
is set (:func:`reference.mitsuba` does both).
"""

from __future__ import annotations

import math

import drjit as dr

from whitted.reference.materials.phong import _color_texture
from whitted.reference.materials.textures import texture_tree
from whitted.reference.renderers.mitsuba.tree import per_variant
from whitted.tracer.materials.classic import Classic

#: the Mitsuba plugins this module registers
PLUGINS = ("whitted_classic",)


def mitsuba(m: Classic) -> dict:
    return {"type": "whitted_classic", "color": texture_tree(m.color),
            "kd": ("float", m.kd), "ks": ("float", m.ks), "kt": ("float", m.kt),
            "ir": ("float", m.ir)}


def register(mi) -> None:
    """Register ``whitted_classic`` with Mitsuba, whose variant must be set."""
    cls = plugin_class(mi)
    mi.register_bsdf("whitted_classic", lambda props: cls(props))


#: The ``whitted_classic`` BSDF class for Mitsuba's current variant.
plugin_class = per_variant(lambda mi: _define(mi))


def _define(mi):
    class ClassicBSDF(mi.BSDF):
        """Whitted's and Heckbert's fixed-weight model (see the module docstring)."""

        def __init__(self, props: mi.Properties):
            super().__init__(props)
            self.color = _color_texture(mi, props, "color", 1.0)
            self.kd = float(props.get("kd", 0.0))
            self.ks = float(props.get("ks", 0.0))
            self.kt = float(props.get("kt", 0.0))
            self.ir = float(props.get("ir", 1.0))
            if min(self.kd, self.ks, self.kt) < 0 or not self.ir > 0:
                raise ValueError("whitted_classic: kd, ks, kt must be >= 0 and ir > 0")
            both = mi.BSDFFlags.FrontSide | mi.BSDFFlags.BackSide
            self.m_components = [mi.BSDFFlags.DiffuseReflection | both,
                                 mi.BSDFFlags.DeltaReflection | both,
                                 mi.BSDFFlags.DeltaTransmission | both]
            self.m_flags = (self.m_components[0] | self.m_components[1] |
                            self.m_components[2])

        # ----------------------------------------------------------------------------------
        # The formulas, in the local frame (n = +z)
        # ----------------------------------------------------------------------------------

        def _refract(self, wi):
            """(direction, exists) of the refracted ray for the incident wi."""
            cos_i = mi.Frame3f.cos_theta(wi)
            eta = dr.select(cos_i > 0, 1.0 / self.ir, self.ir)   # n1 / n2
            c = dr.abs(cos_i)
            root = 1 - eta * eta * (1 - c * c)
            n = mi.Vector3f(0, 0, dr.sign(cos_i))               # the normal on wi's side
            t = -eta * wi + (eta * c - dr.safe_sqrt(root)) * n
            return t, root > 0

        def _weights(self, ctx, si, active):
            """(kd colour, diffuse weight, ks, kt) with the components ``ctx`` enables."""
            color = self.color.eval(si, active)
            kd_c = self.kd * color
            w_d = kd_c.x * 0
            if ctx.is_enabled(mi.BSDFFlags.DiffuseReflection, 0):
                w_d = (kd_c.x + kd_c.y + kd_c.z) / 3
            w_r = mi.Float(self.ks if ctx.is_enabled(mi.BSDFFlags.DeltaReflection, 1) else 0.0)
            w_t = mi.Float(self.kt if ctx.is_enabled(mi.BSDFFlags.DeltaTransmission, 2)
                           else 0.0)
            return kd_c, w_d, w_r, w_t

        # ----------------------------------------------------------------------------------
        # Mitsuba's BSDF interface
        # ----------------------------------------------------------------------------------

        def sample(self, ctx, si, sample1, sample2, active=True):
            """(BSDFSample3f, value / pdf) of one component chosen by its weight."""
            active = mi.Bool(active)
            wi = si.wi
            kd_c, w_d, w_r, w_t = self._weights(ctx, si, active)
            t_dir, t_ok = self._refract(wi)
            w_t = dr.select(t_ok, w_t, 0.0)
            total = w_d + w_r + w_t
            active &= total > 0
            p_d = w_d / dr.select(total > 0, total, 1.0)
            p_r = w_r / dr.select(total > 0, total, 1.0)
            p_t = 1 - p_d - p_r
            diffuse = sample1 < p_d
            reflect = ~diffuse & (sample1 < p_d + p_r)

            side = dr.sign(mi.Frame3f.cos_theta(wi))
            cosine = mi.warp.square_to_cosine_hemisphere(sample2)
            wo_d = mi.Vector3f(cosine.x, cosine.y, cosine.z * side)
            wo_r = mi.Vector3f(-wi.x, -wi.y, wi.z)

            bs = dr.zeros(mi.BSDFSample3f)
            bs.wo = dr.select(diffuse, wo_d, dr.select(reflect, wo_r, t_dir))
            bs.eta = 1.0   # fixed weights: no radiance scale across the boundary
            bs.sampled_component = dr.select(diffuse, mi.UInt32(0),
                                             dr.select(reflect, mi.UInt32(1), mi.UInt32(2)))
            bs.sampled_type = dr.select(
                diffuse, mi.UInt32(+mi.BSDFFlags.DiffuseReflection),
                dr.select(reflect, mi.UInt32(+mi.BSDFFlags.DeltaReflection),
                          mi.UInt32(+mi.BSDFFlags.DeltaTransmission)))
            cos_o = dr.abs(mi.Frame3f.cos_theta(wo_d))
            bs.pdf = dr.select(diffuse, p_d * cos_o / math.pi, dr.select(reflect, p_r, p_t))
            weight = dr.select(diffuse, kd_c * (math.pi / dr.maximum(p_d, 1e-30)),
                               mi.Color3f(dr.select(reflect, self.ks / dr.maximum(p_r, 1e-30),
                                                    self.kt / dr.maximum(p_t, 1e-30))))
            ok = active & (bs.pdf > 0)
            bs.pdf = dr.select(ok, bs.pdf, 0.0)
            return bs, dr.select(ok, weight, 0.0)

        def eval(self, ctx, si, wo, active=True):
            """kd colour |cos theta_o| on wi's side (the delta components evaluate to 0)."""
            active = mi.Bool(active)
            if not ctx.is_enabled(mi.BSDFFlags.DiffuseReflection, 0):
                return mi.Color3f(0.0)
            same = mi.Frame3f.cos_theta(si.wi) * mi.Frame3f.cos_theta(wo) > 0
            value = self.kd * self.color.eval(si, active) * dr.abs(mi.Frame3f.cos_theta(wo))
            return dr.select(active & same, value, 0.0)

        def pdf(self, ctx, si, wo, active=True):
            """Density of the diffuse component's directions, times its probability."""
            active = mi.Bool(active)
            _, w_d, w_r, w_t = self._weights(ctx, si, active)
            _, t_ok = self._refract(si.wi)
            total = w_d + w_r + dr.select(t_ok, w_t, 0.0)
            same = mi.Frame3f.cos_theta(si.wi) * mi.Frame3f.cos_theta(wo) > 0
            pdf = (w_d / dr.select(total > 0, total, 1.0) *
                   dr.abs(mi.Frame3f.cos_theta(wo)) / math.pi)
            return dr.select(active & same & (total > 0), pdf, 0.0)

        def eval_pdf(self, ctx, si, wo, active=True):
            return self.eval(ctx, si, wo, active), self.pdf(ctx, si, wo, active)

        def eval_diffuse_reflectance(self, si, active=True):
            return self.kd * self.color.eval(si, active)

        def traverse(self, cb):
            cb.put("color", self.color, mi.ParamFlags.Differentiable)

        def parameters_changed(self, keys):
            pass

        def to_string(self):
            return (f"ClassicBSDF[kd = {self.kd}, ks = {self.ks}, kt = {self.kt}, "
                    f"ir = {self.ir}, color = {self.color}]")

    return ClassicBSDF
