"""Light sources: the radiance each one delivers to a point, as pure functions.

Units are Mitsuba 3's (see the scene format): point and spot ``intensity`` I in
W/sr, directional ``irradiance`` E in W/m^2 normal to the light, area
``radiance`` L in W/(m^2 sr). Each function returns, for shading points p, the
unit direction wi towards the light, the distance to it (inf for a
directional light) and the incident quantity that multiplies BRDF x cos:

* point: I / r^2 (inverse-square law; lecture 1, "Light attenuation");
* spot: I falloff(theta) / r^2, where falloff is Mitsuba's: 1 inside
  ``beam_width``, linear in the angle down to 0 at ``cutoff_angle``, 0 beyond;
* directional: E, constant;
* Heckbert's light sphere (the classic model): the value kl x colour from the
  direction of the sphere's centre, the same at every distance (no falloff);
* area lights: L cos(theta_l) / r^2 / pdf_area (a rectangle or triangle sampled
  uniformly by area), or L / pdf_solid_angle (a sphere sampled uniformly in
  the cone of directions it subtends), the two estimators of
  integral L cos(theta_l) / r^2 dA = integral L d(omega) over the light.
"""

import math

import drjit as dr

from whitted.tracer import faults


def inverse_square(intensity, dist):
    """Irradiance-like factor I / r^2 of a point source at distance r (W/sr / m^2)."""
    value = faults.pick("point-light-linear-falloff", lambda: intensity / dist,
                        intensity / (dist * dist))
    return faults.pick("point-light-no-falloff", lambda: intensity + 0 * dist, value)


def point(p, position, intensity):
    """(wi, dist, I / r^2) for a point light."""
    to_light = position - p
    dist = dr.norm(to_light)
    return to_light / dist, dist, inverse_square(intensity, dist)


def spot_falloff(cos_theta, cutoff_deg: float, beam_deg: float):
    """Mitsuba's spot profile for the angle theta between the spot axis and a direction."""
    cutoff = math.radians(cutoff_deg)
    beam = math.radians(beam_deg)
    inside = cos_theta >= math.cos(beam)
    if cutoff > beam:
        ramp = (cutoff - dr.acos(dr.clip(cos_theta, -1, 1))) / (cutoff - beam)
    else:
        ramp = dr.zeros(type(cos_theta), dr.width(cos_theta))
    if faults.on("spot-linear-falloff"):
        ramp = ((cos_theta - math.cos(cutoff)) / (math.cos(beam) - math.cos(cutoff))
                if cutoff > beam else ramp)
    if faults.on("spot-smoothstep-falloff") and cutoff > beam:
        x = dr.clip((cos_theta - math.cos(cutoff)) / (math.cos(beam) - math.cos(cutoff)), 0, 1)
        ramp = x * x * (3 - 2 * x)
    value = dr.select(inside, 1.0, ramp)
    return dr.select(cos_theta > math.cos(cutoff), value, 0.0)


def spot(p, position, axis, intensity, cutoff_deg: float, beam_deg: float):
    """(wi, dist, I falloff / r^2) for a spot light pointing along the unit ``axis``."""
    wi, dist, e = point(p, position, intensity)
    falloff = spot_falloff(dr.dot(-wi, axis), cutoff_deg, beam_deg)
    return wi, dist, e * falloff


def directional(p, direction, irradiance):
    """(wi, inf, E): light travelling along the unit ``direction``."""
    direction = faults.pick("directional-light-reversed", lambda: -direction, direction)
    wi = -direction + dr.zeros(type(p), dr.width(p))
    return wi, dr.full(type(p.x), dr.inf, dr.width(p)), irradiance


def sphere_centre(p, origin, center, radius, value):
    """(wi, distance, value) of Heckbert's light sphere: towards its centre, no falloff.

    Heckbert's business-card ray tracer (minray, 1987) and Whitted's model
    (1980, I = Ia + kd sum_j (N . L_j) + ...) light a point by kl (N . L) with
    L the unit direction to the light's centre, at any distance: the light
    acts like a directional light aimed from the centre, of value kl x colour
    (irradiance normal to L). It is seen when the first surface towards the
    centre is the light sphere itself, so the shadow ray from ``origin`` ends
    where it meets the sphere (the nearer root of the ray-sphere quadratic):
    anything before that shadows the point. A point inside the sphere gets
    nothing.
    """
    to_c = center - p
    dc = dr.norm(to_c)
    wi = to_c / dc
    f = origin - center
    b = dr.dot(f, wi)
    disc = radius * radius - dr.squared_norm(f - b * wi)
    # The near root -b - sqrt(disc); where rounding leaves no root (a grazing
    # origin), the distance to the tangent point.
    dist = -b - dr.sqrt(dr.maximum(disc, 0))
    value = faults.pick("heckbert-light-inverse-square", lambda: value / (dc * dc), value)
    return wi, dist, dr.select(dc > radius, value, 0)


def lambert_cosine(n, wi):
    """Lambert's cosine law with clamping: max(n . wi, 0) for unit vectors."""
    value = faults.pick("lambert-abs-cosine", lambda: dr.abs(dr.dot(n, wi)),
                        dr.maximum(dr.dot(n, wi), 0))
    return faults.pick("lambert-no-cosine", lambda: dr.select(dr.dot(n, wi) > 0, 1.0, 0.0),
                       value)


# --------------------------------------------------------------------------------------
# Area lights: sampling and the conversion between area and solid-angle measure
# --------------------------------------------------------------------------------------


def area_to_solid_angle_pdf(pdf_area, dist, cos_light):
    """pdf w.r.t. solid angle from pdf w.r.t. area: pdf_A r^2 / |cos theta_l|."""
    return pdf_area * dist * dist / dr.abs(cos_light)


def sample_parallelogram(sample, center, u, v):
    """Uniform point on the parallelogram center + a u + b v, (a, b) in [-1, 1]^2."""
    return center + (2 * sample.x - 1) * u + (2 * sample.y - 1) * v


def sample_ellipse(sample, center, u, v):
    """Uniform point on the disk center + a u + b v, a^2 + b^2 <= 1 (an affine unit disk).

    Concentric mapping of the square onto the disk (Shirley & Chiu, "A Low
    Distortion Map Between Disk and Square", 1997): uniform in area, and
    an affine map keeps it uniform.
    """
    x = 2 * sample.x - 1
    y = 2 * sample.y - 1
    use_x = dr.abs(x) > dr.abs(y)
    r = dr.select(use_x, x, y)
    safe_x = dr.select(x == 0, 1, x)
    safe_y = dr.select(y == 0, 1, y)
    theta = dr.select(use_x, (math.pi / 4) * (y / safe_x),
                      (math.pi / 2) - (math.pi / 4) * (x / safe_y))
    s, c = dr.sincos(theta)
    return center + (r * c) * u + (r * s) * v


def sample_triangle(sample, p0, e1, e2):
    """Uniform point on a triangle by the square-root warp (Shirley's, "Realistic Ray Tracing").

    beta = 1 - sqrt(u1), gamma = u2 sqrt(u1) is uniform in area over the triangle.
    """
    su = dr.sqrt(sample.x)
    su = faults.pick("triangle-warp-no-sqrt", lambda: sample.x, su)
    return p0 + (1 - su) * e1 + (sample.y * su) * e2


def sample_sphere_uniform(sample, center, radius):
    """Uniform point on a whole sphere (pdf 1 / (4 pi r^2) by area) and its outward normal."""
    z = 1 - 2 * sample.x
    r = dr.sqrt(dr.maximum(1 - z * z, 0))
    s, c = dr.sincos(2 * math.pi * sample.y)
    n = type(center)(c * r, s * r, z)
    return center + radius * n, n


def sample_cone(sample, cos_max, one_minus_cos_max=None):
    """Local direction uniform in the cone around +z with cos(theta) >= cos_max, and its pdf.

    The pdf is 1 / (2 pi (1 - cos_max)): the cone's solid angle. For a small or
    distant light 1 - cos_max suffers cancellation in float32; pass it computed
    stably, e.g. sin^2(theta_max) / (1 + cos_max).
    """
    omc = (1 - cos_max) if one_minus_cos_max is None else one_minus_cos_max
    cos_t = 1 - sample.x * omc
    sin_t = dr.sqrt(dr.maximum((1 - cos_t) * (1 + cos_t), 0))
    phi = 2 * math.pi * sample.y
    s, c = dr.sincos(phi)
    pdf = 1 / (2 * math.pi * omc)
    pdf = faults.pick("area-pdf-sphere-cone", lambda: 1 / (math.pi * omc), pdf)
    pdf = faults.pick("sphere-cone-disk-solid-angle", lambda: 1 / (math.pi * omc * (2 - omc)),
                      pdf)
    return c * sin_t, s * sin_t, cos_t, pdf


def coordinate_system(n):
    """Two unit tangents completing the unit vector ``n`` to an orthonormal frame.

    Duff et al., "Building an Orthonormal Basis, Revisited" (JCGT 6(1), 2017).
    """
    sign = dr.copysign(1.0, n.z)
    a = -1 / (sign + n.z)
    b = n.x * n.y * a
    t = type(n)(1 + sign * n.x * n.x * a, sign * b, -sign * n.x)
    s = type(n)(b, sign + n.y * n.y * a, -n.y)
    return t, s


def sample_uniform_direction(sample):
    """A direction uniform on the unit sphere, pdf 1 / (4 pi) (Archimedes' hat-box theorem:
    z uniform in [-1, 1] is uniform by area): z = 1 - 2 u.y, phi = 2 pi u.x, as Mitsuba 3's
    ``square_to_uniform_sphere`` maps its sample (pbrt-v4, section A.5.2)."""
    z = 1 - 2 * sample.y
    z = faults.pick("sphere-direction-z-squared", lambda: 1 - 2 * sample.y * sample.y, z)
    r = dr.sqrt(dr.maximum(1 - z * z, 0))
    s, c = dr.sincos(2 * math.pi * sample.x)
    return c * r, s * r, z


def spot_uv(x, y, z_tan):
    """Texture coordinates of a textured spot for the direction (x, y, z) in its frame,
    ``z_tan`` = z tan(cutoff): (1/2 + x / (2 z tan), 1/2 + y / (2 z tan)), the cutoff cone's
    square cross-section mapped onto the unit square (Mitsuba 3's ``spot``)."""
    from whitted.tracer.backend import jit

    u, v = 0.5 * x / z_tan, 0.5 * y / z_tan
    return faults.pick("spot-uv-centred-at-zero", lambda: jit.Array2f(u, v),
                       jit.Array2f(0.5 + u, 0.5 + v))
