"""Phong and Blinn-Phong glossy reflection, normalised to conserve energy, as pure functions.

The material ``type = "phong"`` has a Lambertian part and a glossy lobe::

    f(wi, wo) = kd / pi + ks N(p) cos^p(alpha)

with the diffuse colour ``kd``, the specular colour ``ks`` and the ``exponent``
p >= 0. ``model`` chooses the angle alpha of the lobe:

* ``"phong"``: the angle between wo and the mirror image of wi about the normal
  (Phong, "Illumination for Computer Generated Pictures", CACM 18(6), 1975),
  in the *modified* form of Lafortune and Willems, "Using the modified Phong
  reflectance model for physically based rendering", KU Leuven CW 197, 1994:
  no division by cos(theta_i), so that f is reciprocal, and N = (p + 2) / (2 pi);
* ``"blinn-phong"``: the angle between the normal and the half vector
  h = (wi + wo) / |wi + wo| (Blinn, "Models of light reflection for computer
  synthesized pictures", SIGGRAPH 1977), with
  N = (p + 2)(p + 4) / (8 pi (2^(-p/2) + p)) (Giesen, "The Blinn-Phong
  Normalization Zoo", 2009).

Both factors make the directional albedo integral f cos(theta_i) d(wi) exactly 1
for ks = 1 at normal incidence, and less at every other outgoing direction
(the lobe leans towards and is cut off by the horizon), so the material
conserves energy while kd + ks <= 1 in every channel. Why the two factors
differ is told at :func:`blinn_phong_normalization`.

f is zero when either direction is below the surface. Directions are unit
vectors pointing away from the surface: ``wi`` towards the light, ``wo``
towards the viewer. f is symmetric in them (Helmholtz reciprocity), so the
names only matter for the reader. The functions take Dr.Jit arrays of either
backend; the exponent may be a Python float or a Float array.
"""

import math

import drjit as dr

from whitted.tracer import faults

MODELS = ("phong", "blinn-phong")


def phong_normalization(exponent):
    """N(p) = (p + 2) / (2 pi), which makes the modified Phong lobe's albedo 1 at normal incidence.

    With wo = n the mirror direction of wi is n itself, alpha = theta_i, and
    integral over the hemisphere of N cos^p(theta) cos(theta) d(omega)
    = 2 pi N integral_0^1 mu^(p+1) d(mu) = 2 pi N / (p + 2) = 1
    (Lafortune and Willems 1994, section 3).
    """
    return (exponent + 2) / (2 * math.pi)


def blinn_phong_normalization(exponent):
    """N(p) = (p + 2)(p + 4) / (8 pi (2^(-p/2) + p)): the Blinn-Phong lobe's albedo is 1 at wo = n.

    Giesen, "The Blinn-Phong Normalization Zoo" (2009). With wo = n the half
    vector makes the angle theta_i / 2 with the normal; substituting
    c = cos(theta_i / 2), cos(theta_i) = 2 c^2 - 1, d(cos theta_i) = 4 c dc:
    integral of cos^p(theta_i / 2) cos(theta_i) d(omega_i)
    = 8 pi integral_{1/sqrt 2}^1 c^(p+1) (2 c^2 - 1) dc
    = 8 pi (2^(-p/2) + p) / ((p + 2)(p + 4)).

    Why not Phong's (p + 2) / (2 pi): a lobe of width delta in the half vector
    is a lobe of width about 2 delta in wi (reflecting about h doubles angles:
    d(omega_i) = 4 (wo . h) d(omega_h)), so the same cos^p covers up to four
    times the solid angle, and Phong's factor would reflect 4 (2^(-p/2) + p) /
    (p + 4) times the incident energy at normal incidence (1.37 for p = 1,
    2.9 for p = 10, tending to 4). p = 0 gives 1 / pi: Lambert.
    """
    return (exponent + 2) * (exponent + 4) / (8 * math.pi * (2.0 ** (-exponent / 2) + exponent))


def reflect_about(n, w):
    """Mirror image of the unit ``w`` (pointing away from the surface) about the unit ``n``.

    r = 2 (n . w) n - w: the direction a ray arriving along -w leaves in
    (``tracer.fresnel.reflect(-w, n)``), written for directions that point away.
    """
    return 2 * dr.dot(n, w) * n - w


def _cos_power(c, exponent):
    """max(c, 0)^p, with no power taken of non-positive c (log2(0) in pow gives NaN for p = 0)."""
    return dr.select(c > 0, dr.power(dr.maximum(c, 1e-30), exponent), 0.0)


def phong_lobe(n, wi, wo, exponent):
    """N(p) cos^p(alpha), alpha the angle between wo and the mirror direction of wi (no ks)."""
    cos_alpha = dr.dot(reflect_about(n, wi), wo)
    return faults.pick("phong-no-normalization", lambda: _cos_power(cos_alpha, exponent),
                       phong_normalization(exponent) * _cos_power(cos_alpha, exponent))


def blinn_phong_lobe(n, wi, wo, exponent):
    """N(p) cos^p(theta_h), theta_h the angle between n and the half vector of wi and wo (no ks).

    Only called with both directions above the surface, where wi + wo != 0.
    """
    h = dr.normalize(wi + wo)
    h = faults.pick("half-vector-unnormalized", lambda: wi + wo, h)
    return faults.pick(
        "blinn-phong-with-phong-normalization",
        lambda: phong_normalization(exponent) * _cos_power(dr.dot(n, h), exponent),
        blinn_phong_normalization(exponent) * _cos_power(dr.dot(n, h), exponent))


def phong_brdf(n, wi, wo, kd, ks, exponent, model: str):
    """The BRDF kd / pi + ks N(p) cos^p(alpha) (no cosine factor), zero below the surface.

    ``n``: unit normal; ``wi``, ``wo``: unit directions towards the light and
    the viewer; ``kd``, ``ks``: Array3f colours; ``exponent``: p, a Python float
    or a Float; ``model``: ``"phong"`` or ``"blinn-phong"`` (see the module
    docstring). Returns an Array3f.
    """
    if model == "phong":
        lobe = phong_lobe(n, wi, wo, exponent)
    elif model == "blinn-phong":
        lobe = blinn_phong_lobe(n, wi, wo, exponent)
    else:
        raise ValueError(f"unknown Phong model {model!r} (expected one of: {', '.join(MODELS)})")
    above = (dr.dot(n, wi) > 0) & (dr.dot(n, wo) > 0)
    f = kd * (1 / math.pi) + ks * lobe
    return dr.select(above, f, 0.0)
