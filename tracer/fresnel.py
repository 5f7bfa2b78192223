"""Reflection, refraction and the Fresnel equations for smooth dielectrics.

Conventions: ``cos_i`` is the cosine between the incident direction (pointing
away from the surface, towards where the light goes back to) and the surface
normal; positive when the ray arrives from outside (the side the normal points
to), negative from inside. ``eta = n_inside / n_outside`` (``ior / ext_ior``).

Sources: lecture 1, "The Fresnel equation", "Snell's law", "Total internal
reflection"; Hecht, "Optics", 5th ed., section 4.6.2 (Fresnel equations);
Schlick, "An Inexpensive BRDF Model for Physically-based Rendering",
Computer Graphics Forum 13(3), 1994; Pharr, Jakob, Humphreys, "Physically Based
Rendering", 4th ed., section 9.5 (dielectric BSDF).
"""

import math

import drjit as dr

from whitted.tracer import faults


def _sides(cos_i, eta):
    """(|cos_i|, n_t / n_i) for a ray arriving on the side given by the sign of cos_i."""
    outside = cos_i >= 0
    return dr.abs(cos_i), dr.select(outside, eta, dr.rcp(eta))


def snell_cos_t(cos_i, eta):
    """|cos theta_t| from Snell's law n_i sin(theta_i) = n_t sin(theta_t), and a TIR mask.

    sin^2(theta_t) = sin^2(theta_i) / (n_t / n_i)^2; total internal reflection
    where that exceeds 1, i.e. beyond the critical angle asin(n_t / n_i).
    """
    c, rel = _sides(cos_i, eta)
    return _snell(c, rel)


def _snell(c, rel):
    """(|cos theta_t|, TIR mask) for |cos theta_i| = c and rel = n_t / n_i."""
    sin2_t = (1 - c * c) / (rel * rel)
    tir = sin2_t > 1
    return faults.pick("tir-ignored", lambda: (dr.sqrt(dr.abs(1 - sin2_t)), sin2_t != sin2_t),
                       (dr.sqrt(dr.maximum(1 - sin2_t, 0)), tir))


def fresnel_exact(cos_i, eta):
    """Fresnel reflectance of unpolarised light at a smooth dielectric boundary.

    R = (r_s^2 + r_p^2) / 2 with
    r_s = (n_i cos_i - n_t cos_t) / (n_i cos_i + n_t cos_t) and
    r_p = (n_t cos_i - n_i cos_t) / (n_t cos_i + n_i cos_t), R = 1 under total
    internal reflection. R + T = 1. Equal indices give R = 0 at every angle
    (no boundary at all, which also settles the 0/0 of grazing incidence).
    """
    c, rel = _sides(cos_i, eta)
    cos_t, tir = snell_cos_t(cos_i, eta)
    r_s = (c - rel * cos_t) / (c + rel * cos_t)
    r_p = (rel * c - cos_t) / (rel * c + cos_t)
    r = faults.pick("fresnel-average-amplitudes", lambda: dr.square(0.5 * (r_s + r_p)),
                    0.5 * (r_s * r_s + r_p * r_p))
    r = dr.select(tir, 1.0, r)
    return faults.pick("schlick-for-exact", lambda: fresnel_schlick(cos_i, eta),
                       dr.select(rel == 1, 0.0, r))


def schlick_r0(eta):
    """Reflectance at normal incidence, R0 = ((n1 - n2) / (n1 + n2))^2 = ((eta - 1) / (eta + 1))^2.

    Symmetric in n1 and n2: the same from either side.
    """
    return dr.square((eta - 1) / (eta + 1))


def fresnel_schlick(cos_i, eta):
    """Schlick's approximation R0 + (1 - R0) (1 - cos)^5.

    The cosine is taken on the less dense side: the incident angle when the
    ray goes into the denser medium, the transmitted angle when it leaves it.
    With the incident angle on the dense side the curve would not reach 1 at
    the critical angle; this way it is continuous there, and total internal
    reflection gives R = 1.
    """
    c, rel = _sides(cos_i, eta)
    cos_t, tir = snell_cos_t(cos_i, eta)
    cos_light = dr.select(rel >= 1, c, cos_t)
    cos_light = faults.pick("schlick-dense-side-cosine", lambda: c, cos_light)
    r0 = schlick_r0(eta)
    r = r0 + (1 - r0) * (1 - cos_light) ** 5
    return dr.select(tir, 1.0, r)


def reflect(d, n):
    """Mirror direction of ``d`` (travelling towards the surface) about unit normal ``n``.

    Law of reflection: angle of incidence equals angle of reflection, in the
    plane of d and n: r = d - 2 (d . n) n.
    """
    return faults.pick("reflect-sign", lambda: d + 2 * dr.dot(d, n) * n,
                       d - 2 * dr.dot(d, n) * n)


def refract(d, n, eta):
    """Refracted direction of the unit ``d`` (travelling towards the surface) and a TIR mask.

    ``n`` is the surface normal pointing outside (towards ext_ior), ``eta`` =
    ior / ext_ior. With cos_i = -d . n and rel = n_t / n_i (as Snell's law is
    written above), t = d / rel + (cos_i / rel - cos_t) n', where n' is n
    flipped to the side the ray comes from. |t| = 1, and
    n_i sin(theta_i) = n_t sin(theta_t).
    """
    cos_i = -dr.dot(d, n)
    c, rel = _sides(cos_i, eta)
    cos_t, tir = snell_cos_t(cos_i, eta)
    rel, cos_t, tir = faults.pick("snell-eta-inverted",
                                  lambda: (dr.rcp(rel), *_snell(c, dr.rcp(rel))),
                                  (rel, cos_t, tir))
    n_facing = faults.pick("normal-not-flipped-inside", lambda: n,
                           dr.select(cos_i >= 0, n, -n))
    inv = dr.rcp(rel)
    t = inv * d + (inv * c - cos_t) * n_facing
    return t, tir


def fresnel_conductor(cos_i, eta, k):
    """Fresnel reflectance of unpolarised light at a smooth conductor, per channel.

    The conductor's complex index eta + i k relative to the outside (pbrt-v4,
    section 9.3, ``FrComplex``: the dielectric equations with a complex n_t and
    cos_t = sqrt(1 - sin^2(theta_i) / (eta + i k)^2)). Written in real
    arithmetic (Born and Wolf, "Principles of Optics", 7th ed., section 14.2;
    Mitsuba 3's ``fresnel_conductor``): with s2 = sin^2(theta_i), c = |cos_i|,

        a^2 + b^2 = sqrt((eta^2 - k^2 - s2)^2 + 4 eta^2 k^2),
        a = sqrt((a^2 + b^2 + eta^2 - k^2 - s2) / 2),
        R_s = (a^2 + b^2 + c^2 - 2 a c) / (a^2 + b^2 + c^2 + 2 a c),
        R_p = R_s (c^2 (a^2 + b^2) + s2^2 - 2 a c s2) / (c^2 (a^2 + b^2) + s2^2 + 2 a c s2),
        R = (R_s + R_p) / 2.

    k = 0 gives the dielectric's R (below its critical angle); eta = 0, k = 1
    gives R = 1 at every angle (Mitsuba's ``material = "none"``).
    """
    k = faults.pick("conductor-k-ignored", lambda: k * 0, k)
    c = dr.minimum(dr.abs(cos_i), 1)
    c2 = c * c
    s2 = 1 - c2
    s4 = s2 * s2
    t1 = eta * eta - k * k - s2
    a2b2 = dr.safe_sqrt(t1 * t1 + 4 * eta * eta * k * k)
    a = dr.safe_sqrt(0.5 * (a2b2 + t1))
    t2 = 2 * c * a
    r_s = (a2b2 + c2 - t2) / (a2b2 + c2 + t2)
    t3 = a2b2 * c2 + s4
    t4 = t2 * s2
    r_p = r_s * (t3 - t4) / (t3 + t4)
    return 0.5 * (r_s + r_p)


def thin_slab_reflectance(r):
    """Reflectance of a thin slab from its single-boundary R: R + T^2 R / (1 - R^2) = 2R / (1 + R).

    A ray entering the slab (T = 1 - R) bounces between its two faces; every
    odd number of inner reflections leaves it on the side it came from, so
    R' = R + T^2 R (1 + R^2 + R^4 + ...) = R + T^2 R / (1 - R^2), which is
    2R / (1 + R) (the geometric series of inner reflections; pbrt-v4,
    section 9.5.4 ``ThinDielectricBxDF``; Mitsuba 3's ``thindielectric``). The
    transmittance is 1 - R' = (1 - R) / (1 + R); the ray leaves the slab along its
    own direction, the slab being thin.
    """
    return faults.pick("thin-slab-single-reflection", lambda: r, 2 * r / (1 + r))


def fresnel_diffuse_reflectance(eta):
    """The hemispherical average of the Fresnel reflectance for diffuse light, F_dr(eta).

    Light arriving from all directions of a hemisphere (cosine-weighted) at a
    boundary with relative index eta (n_t / n_i) is reflected with
    F_dr = 2 * integral of R(cos) cos dcos. Fitted rather than integrated, as
    Mitsuba 3 does (``fresnel_diffuse_reflectance``), so that both agree to
    float precision: for eta < 1 the fit of Egan and Hilgeman ("Optical
    Properties of Inhomogeneous Materials", 1979; the form in Jensen et al.,
    "A Practical Model for Subsurface Light Transport", SIGGRAPH 2001, eq. 9,
    written there for 1 / eta)
    -1.4399 eta^2 + 0.7099 eta + 0.6681 + 0.0636 / eta; for eta >= 1 the
    polynomial in 1 / eta of d'Eon and Irving ("A Quantized-Diffusion Model
    for Rendering Translucent Materials", SIGGRAPH 2011, section 5.1)
    0.919317 - 3.4793 x + 6.75335 x^2 - 7.80989 x^3 + 4.98554 x^4 - 1.36881 x^5.
    """
    x = dr.rcp(eta)
    low = dr.fma(0.0636, x, dr.fma(eta, dr.fma(eta, -1.4399, 0.7099), 0.6681))
    high = dr.fma(x, dr.fma(x, dr.fma(x, dr.fma(x, dr.fma(x, -1.36881, 4.98554), -7.80989),
                                         6.75335), -3.4793), 0.919317)
    return dr.select(eta < 1, low, high)


def plastic_diffuse(kd, f_i, f_o, eta, fdr_int, nonlinear):
    """The diffuse part of a smooth plastic, without the cosine (Mitsuba 3's ``plastic``).

    A Lambertian base under a smooth dielectric coating of relative index
    eta (Weidlich and Wilkie, "Arbitrarily Layered Micro-Facet Surfaces",
    GRAPHITE 2007, in the smooth limit): light enters through the coating
    with (1 - F_i), is scattered by the base, and leaves with (1 - F_o), the
    radiance scaled by 1 / eta^2 as it leaves the denser medium (Veach's
    thesis, section 5.2). Light the coating reflects back inside (F_dr, the
    internal diffuse Fresnel reflectance, :func:`fresnel_diffuse_reflectance`
    of 1 / eta) is scattered again: the geometric series gives
    kd / (1 - F_dr) when that light is taken as leaving with the base's own
    spectrum (linear), kd / (1 - kd F_dr) when each bounce takes the base's
    colour again (``nonlinear``, the saturating of wet or varnished
    surfaces). f = kd' (1 - F_i)(1 - F_o) / (eta^2 pi).
    """
    kd_eff = faults.pick("plastic-no-internal-scattering", lambda: kd,
                         kd / (1 - dr.select(nonlinear, kd, 1.0) * fdr_int))
    return kd_eff * ((1 - f_i) * (1 - f_o) / (eta * eta * math.pi))
