"""Ray-sphere intersection (implicit surface |p - c|^2 - r^2 = 0).

Substituting the ray p(t) = o + t d gives the quadratic a t^2 + 2 b' t + c = 0
with a = d.d, b' = d.(o - c), c = |o - c|^2 - r^2 (lecture 1, "Ray-sphere
intersection": two, one or no real roots by the sign of the discriminant).
Two float32 refinements keep it accurate far from the sphere, following
Haines et al., "Precision Improvements for Ray/Sphere Intersection" (Ray
Tracing Gems, ch. 7, 2019): the discriminant is computed as
a (r^2 - |f - (b'/a) d|^2), which avoids cancelling b'^2 against a c, and the
two roots as q / a and c / q with q = -(b' + sign(b') sqrt(disc)), which avoids
cancelling -b' against sqrt(disc).

The surface normal is the normalised gradient of the implicit function,
grad(|p - c|^2 - r^2) / 2 = p - c, divided by r.
"""

import drjit as dr

from tracer import faults


def roots(o, d, center, radius, unit: bool = False):
    """Both roots (t0 <= t1) of the ray-sphere quadratic and a mask of rays with real roots.

    Where the discriminant is 0 (a tangent ray) t0 == t1: one root. Roots may
    be negative: a ray starting inside the sphere has t0 < 0 < t1. ``unit``
    promises |d| = 1 (a = 1), which saves two divisions.
    """
    f = o - center
    b = dr.dot(f, d)
    c = dr.squared_norm(f) - radius * radius
    if unit:
        disc = radius * radius - dr.squared_norm(f - b * d)
        if faults.on("sphere-half-b-discriminant"):
            disc = b * b - 4 * c
    else:
        a = dr.squared_norm(d)
        disc = a * (radius * radius - dr.squared_norm(f - (b / a) * d))
    real = disc >= 0
    q = -(b + dr.copysign(dr.sqrt(dr.maximum(disc, 0)), b))
    t_a = c / q
    t_b = q if unit else q / a
    # q == 0 only when b == 0 and disc == 0 (a tangent ray through... the tangent point)
    t_a = dr.select(q == 0, 0, t_a)
    t0 = dr.minimum(t_a, t_b)
    t1 = dr.maximum(t_a, t_b)
    return t0, t1, real


def intersect(o, d, center, radius, tmax):
    """Nearest root in (0, tmax) and whether there is one (the hit record's t); |d| = 1."""
    t0, t1, real = roots(o, d, center, radius, unit=True)
    t = dr.select(t0 > 0, t0, t1)
    if faults.on("sphere-near-root-from-inside"):
        t = t0
    hit = real & (t > 0) & (t < tmax)
    return t, hit


def normal(p, center, radius):
    """Outward unit normal: the gradient of |p - c|^2 - r^2, normalised."""
    return (p - center) / radius
