"""Mitsuba conversion of ``phong`` (tracer/materials/phong.py), and its BSDF ``whitted_phong``.

Mitsuba 3 has no Phong BSDF, so the harness renders the tracer's ``phong``
material with this one, written in Python on Mitsuba's API and wrapped in
``twosided``. The ambient term is tracer-only (Mitsuba has no counterpart):
the conversion leaves it out (see :meth:`Phong.comparable`). The BSDF is written
from the formulas, in Mitsuba's local shading frame (normal +z), and does not
call :mod:`tracer.phong`, so that the two implementations check each other::

    f(wi, wo) = kd / pi + ks N(p) cos^p(alpha)          (zero below the surface)

* ``model = "phong"``: alpha is the angle between wo and the mirror direction
  of wi, N = (p + 2) / (2 pi) (Phong 1975, in the modified, reciprocal form of
  Lafortune and Willems, "Using the modified Phong reflectance model for
  physically based rendering", 1994);
* ``model = "blinn-phong"``: alpha is the angle between the normal and the half
  vector (Blinn 1977), N = (p + 2)(p + 4) / (8 pi (2^(-p/2) + p)) (Giesen,
  "The Blinn-Phong Normalization Zoo", 2009); see :mod:`tracer.phong` for why
  the two factors differ.

Parameters: ``diffuse`` (kd) and ``specular`` (ks), each an RGB triple, a float
or a Mitsuba texture; ``exponent`` (p >= 0); ``model``. The material conserves
energy while kd + ks <= 1.

Sampling picks the diffuse lobe or the glossy one with probabilities in
proportion to the means of kd and ks at the shading point, then draws

* diffuse: a cosine-weighted direction, pdf cos(theta_o) / pi;
* Phong: cos(alpha) = u^(1 / (p + 1)) around the mirror direction of wi, i.e.
  pdf (p + 1) / (2 pi) cos^p(alpha) in solid angle (Lafortune and Willems 1994,
  section 4);
* Blinn-Phong: a half vector h with cos(theta_h) = u^(1 / (p + 1)), then
  wo = 2 (wi . h) h - wi; pdf (p + 1) / (2 pi) cos^p(theta_h) / (4 wo . h), the
  last factor the Jacobian d(omega_h) / d(omega_o) of reflection about h
  (Walter et al., "Microfacet Models for Refraction", EGSR 2007, eq. 14).

``pdf`` is the mixture of both densities, so the sample weight eval / pdf stays
bounded. Directions that fall below the surface get weight 0 (they keep their
share of probability: the sampled density integrates to less than 1).

Mitsuba's conventions (as in its ``diffuse`` plugin): ``si.wi`` points towards
where the light goes (the camera side), ``wo`` towards where it comes from,
both away from the surface in local coordinates; ``eval`` returns f cos(theta_o).
The BSDF is one-sided (FrontSide): the harness wraps it in ``twosided``.

:func:`register` defines the class and registers it once Mitsuba's variant is
set (:func:`reference.mitsuba` does both): it derives from the variant's
``mi.BSDF``.
"""

from __future__ import annotations

import math

import drjit as dr

from whitted.reference.materials.textures import texture_tree
from whitted.reference.renderers.mitsuba.tree import per_variant, rgb
from whitted.tracer.materials.phong import Phong

MODELS = ("phong", "blinn-phong")
#: the Mitsuba plugins this module registers
PLUGINS = ("whitted_phong",)


def mitsuba(m: Phong) -> dict:
    return {"type": "twosided",
            "material": {"type": "whitted_phong", "diffuse": texture_tree(m.diffuse),
                         "specular": rgb(m.specular), "exponent": ("float", m.exponent),
                         "model": ("string", m.model)}}


def register(mi) -> None:
    """Register ``whitted_phong`` with Mitsuba, whose variant must be set."""
    cls = plugin_class(mi)
    mi.register_bsdf("whitted_phong", lambda props: cls(props))


def _color_texture(mi, props, name: str, default: float):
    """``props[name]`` as a texture; a plain list [r, g, b] arrives as a vector, not a colour."""
    if name in props and props.type(name) == mi.Properties.Type.Vector:
        return mi.load_dict({"type": "rgb", "value": mi.ScalarColor3f(props.get(name))})
    return props.get_texture(name, default)


def _mean(c):
    """Mean of the three channels of a colour."""
    return (c[0] + c[1] + c[2]) * (1 / 3)


def _cos_power(c, p):
    """max(c, 0)^p; the power is only taken of positive c (pow(0, 0) goes through log2(0))."""
    return dr.select(c > 0, dr.power(dr.maximum(c, 1e-30), p), 0.0)


#: The ``whitted_phong`` BSDF class for Mitsuba's current variant.
plugin_class = per_variant(lambda mi: _define(mi))


def _define(mi):
    class PhongBSDF(mi.BSDF):
        """Diffuse plus a normalised Phong or Blinn-Phong lobe (see the module docstring)."""

        def __init__(self, props: mi.Properties):
            super().__init__(props)
            self.kd = _color_texture(mi, props, "diffuse", 0.5)
            self.ks = _color_texture(mi, props, "specular", 0.2)
            p = float(props.get("exponent", 30.0))
            if not p >= 0:
                raise ValueError(f"whitted_phong: exponent must be >= 0, got {p}")
            # A Float rather than a Python float, so that traverse() can expose it and
            # a changed exponent does not compile new kernels.
            self.exponent = dr.opaque(mi.Float, p)
            self.model = str(props.get("model", "phong"))
            if self.model not in MODELS:
                raise ValueError(f"whitted_phong: unknown model {self.model!r} "
                                 f"(expected one of: {', '.join(MODELS)})")
            diffuse = mi.BSDFFlags.DiffuseReflection | mi.BSDFFlags.FrontSide
            glossy = mi.BSDFFlags.GlossyReflection | mi.BSDFFlags.FrontSide
            # Component 0 is the Lambertian lobe, component 1 the glossy one.
            self.m_components = [diffuse, glossy]
            self.m_flags = diffuse | glossy

        # ----------------------------------------------------------------------------------
        # The formulas, in the local frame (n = +z)
        # ----------------------------------------------------------------------------------

        def _normalization(self):
            """N(p) of the chosen model."""
            p = self.exponent
            if self.model == "phong":
                return (p + 2) / (2 * math.pi)
            return (p + 2) * (p + 4) / (8 * math.pi * (dr.exp2(-0.5 * p) + p))

        def _cos_lobe(self, wi, wo):
            """cos(alpha): wo against the mirror direction of wi, or n against the half vector."""
            if self.model == "phong":
                mirror = mi.Vector3f(-wi.x, -wi.y, wi.z)
                return dr.dot(mirror, wo)
            h = dr.normalize(wi + wo)
            return h.z

        def _lobe_pdf(self, wi, wo):
            """Solid-angle density of the glossy lobe's sampling at wo (both above the surface)."""
            p = self.exponent
            c = self._cos_lobe(wi, wo)
            pdf = (p + 1) / (2 * math.pi) * _cos_power(c, p)
            if self.model == "blinn-phong":
                h = dr.normalize(wi + wo)
                pdf = pdf / (4 * dr.dot(wo, h))
            return pdf

        def _sample_lobe(self, wi, u):
            """A direction from the glossy lobe's sampling (possibly below the surface)."""
            cos_a = dr.power(u.x, dr.rcp(self.exponent + 1))
            sin_a = dr.safe_sqrt(1 - cos_a * cos_a)
            s, c = dr.sincos(2 * math.pi * u.y)
            local = mi.Vector3f(c * sin_a, s * sin_a, cos_a)
            if self.model == "phong":
                return mi.Frame3f(mi.Vector3f(-wi.x, -wi.y, wi.z)).to_world(local)
            h = local  # the half vector, around the normal
            return 2 * dr.dot(wi, h) * h - wi

        def _lobes(self, ctx: mi.BSDFContext):
            """Whether the diffuse and the glossy lobes are enabled in this context."""
            return (ctx.is_enabled(mi.BSDFFlags.DiffuseReflection, 0),
                    ctx.is_enabled(mi.BSDFFlags.GlossyReflection, 1))

        def _prob_glossy(self, ctx, kd, ks):
            """Probability of sampling the glossy lobe: mean(ks) / (mean(kd) + mean(ks))."""
            has_diffuse, has_glossy = self._lobes(ctx)
            if has_diffuse != has_glossy:
                return mi.Float(1.0 if has_glossy else 0.0)
            md, ms = _mean(kd), _mean(ks)
            total = md + ms
            return dr.select(total > 0, ms / total, 0.0)

        def _eval_pdf(self, ctx, si, wo, active):
            """(f cos(theta_o), pdf) with the lobes that ``ctx`` enables."""
            has_diffuse, has_glossy = self._lobes(ctx)
            wi = si.wi
            active = active & (mi.Frame3f.cos_theta(wi) > 0) & (mi.Frame3f.cos_theta(wo) > 0)
            kd = self.kd.eval(si, active)
            ks = self.ks.eval(si, active)
            cos_o = mi.Frame3f.cos_theta(wo)
            prob_glossy = self._prob_glossy(ctx, kd, ks)

            value = mi.Color3f(0.0)
            pdf = mi.Float(0.0)
            if has_diffuse:
                value += kd * (cos_o / math.pi)
                pdf += (1 - prob_glossy) * cos_o / math.pi
            if has_glossy:
                lobe = self._normalization() * _cos_power(self._cos_lobe(wi, wo), self.exponent)
                value += ks * (lobe * cos_o)
                pdf += prob_glossy * self._lobe_pdf(wi, wo)
            return dr.select(active, value, 0.0), dr.select(active, pdf, 0.0)

        # ----------------------------------------------------------------------------------
        # Mitsuba's BSDF interface
        # ----------------------------------------------------------------------------------

        def sample(self, ctx, si, sample1, sample2, active=True):
            """(BSDFSample3f, f cos(theta_o) / pdf) for one direction from the lobe mixture."""
            has_diffuse, has_glossy = self._lobes(ctx)
            active = mi.Bool(active) & (mi.Frame3f.cos_theta(si.wi) > 0)
            bs = dr.zeros(mi.BSDFSample3f)
            if not (has_diffuse or has_glossy):
                return bs, mi.Color3f(0.0)

            kd = self.kd.eval(si, active)
            ks = self.ks.eval(si, active)
            glossy = sample1 < self._prob_glossy(ctx, kd, ks)
            wo_glossy = self._sample_lobe(si.wi, sample2)
            wo_diffuse = mi.warp.square_to_cosine_hemisphere(sample2)
            bs.wo = dr.select(glossy, wo_glossy, wo_diffuse)
            bs.eta = 1.0
            bs.sampled_type = dr.select(glossy, mi.UInt32(+mi.BSDFFlags.GlossyReflection),
                                        mi.UInt32(+mi.BSDFFlags.DiffuseReflection))
            bs.sampled_component = dr.select(glossy, mi.UInt32(1), mi.UInt32(0))

            value, pdf = self._eval_pdf(ctx, si, bs.wo, active)
            bs.pdf = pdf
            ok = active & (pdf > 0)
            return bs, dr.select(ok, value / pdf, 0.0)

        def eval(self, ctx, si, wo, active=True):
            """f(si.wi, wo) cos(theta_o)."""
            return self._eval_pdf(ctx, si, wo, mi.Bool(active))[0]

        def pdf(self, ctx, si, wo, active=True):
            """Solid-angle density with which :meth:`sample` returns wo."""
            return self._eval_pdf(ctx, si, wo, mi.Bool(active))[1]

        def eval_pdf(self, ctx, si, wo, active=True):
            """(eval, pdf) at once."""
            return self._eval_pdf(ctx, si, wo, mi.Bool(active))

        def eval_diffuse_reflectance(self, si, active=True):
            """kd: the albedo of the Lambertian part (used by denoisers' albedo AOVs)."""
            return self.kd.eval(si, active)

        def traverse(self, cb):
            cb.put("diffuse", self.kd, mi.ParamFlags.Differentiable)
            cb.put("specular", self.ks, mi.ParamFlags.Differentiable)
            cb.put("exponent", self.exponent, mi.ParamFlags.NonDifferentiable)

        def parameters_changed(self, keys):
            # Nothing is precomputed from the parameters: the formulas read them directly.
            pass

        def to_string(self):
            return (f"PhongBSDF[\n  model = {self.model!r},\n  diffuse = {self.kd},\n"
                    f"  specular = {self.ks},\n  exponent = {self.exponent}\n]")

    return PhongBSDF
