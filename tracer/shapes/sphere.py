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

from whitted.tracer import faults


def quadratic(o, d, center, radius, unit: bool = True):
    """(b', c, disc, a) of the ray-sphere quadratic a t^2 + 2 b' t + c = 0, with
    f = o - centre: a = d.d, b' = d.f, c = |f|^2 - r^2 and the discriminant in the
    accurate form a (r^2 - |f - (b'/a) d|^2) (module docstring). ``unit`` promises
    |d| = 1: a is then 1, returned as None, and disc = r^2 - |f - b' d|^2."""
    f = o - center
    b = dr.dot(f, d)
    c = dr.squared_norm(f) - radius * radius
    if unit:
        a = None
        disc = radius * radius - dr.squared_norm(f - b * d)
        if faults.on("sphere-half-b-discriminant"):
            disc = b * b - 4 * c
    else:
        a = dr.squared_norm(d)
        disc = a * (radius * radius - dr.squared_norm(f - (b / a) * d))
    return b, c, disc, a


def roots(o, d, center, radius, unit: bool = False):
    """Both roots (t0 <= t1) of the ray-sphere quadratic and a mask of rays with real roots.

    Where the discriminant is 0 (a tangent ray) t0 == t1: one root. Roots may
    be negative: a ray starting inside the sphere has t0 < 0 < t1. ``unit``
    promises |d| = 1 (a = 1), which saves two divisions.
    """
    b, c, disc, a = quadratic(o, d, center, radius, unit)
    real = disc >= 0
    q = -(b + dr.copysign(dr.sqrt(dr.maximum(disc, 0)), b))
    t_a = c / q
    t_b = q if unit else q / a
    # q == 0 only when b == 0 and disc == 0 (a tangent ray through... the tangent point)
    t_a = dr.select(q == 0, 0, t_a)
    t0 = dr.minimum(t_a, t_b)
    t1 = dr.maximum(t_a, t_b)
    return t0, t1, real


def nearest_fraction(o, d, center, radius):
    """The nearest root > 0 as a fraction (num, den), den > 0, and whether there is one;
    |d| = 1. A block of spheres compares its spheres' roots as fractions and divides
    once, for the nearest (``tracer.geometry._SphereBlock``); :func:`intersect` divides.

    The roots are q and c / q (:func:`roots`), |q| = |b'| + sqrt(disc), q of the
    sign opposite to b''s sign bit; their product is c. Where q > 0 the nearer
    positive root is c / q if c > 0 (c / q <= q, as c <= b'^2 <= q^2), else q; where
    q < 0 only c / q can be positive, when c < 0. So the root is |c| / |q| where c
    and q have one sign, and q / 1 where q > 0 and c <= 0; |c| / |q| is c / q to
    the bit. A vector division takes the one divider unit for many cycles (as does
    a square root), so a block of five spheres divides once instead of five times.
    """
    b, c, disc, _ = quadratic(o, d, center, radius)
    q_abs = dr.abs(b) + dr.sqrt(dr.maximum(disc, 0))        # |q|, as roots() rounds it
    q_pos = dr.copysign(1.0, b) < 0                          # q > 0 (where |q| > 0)
    frac = ((c > 0) == q_pos) & (c != 0)                     # c and q of one sign
    num = dr.select(frac, dr.abs(c), q_abs)
    den = dr.select(frac, q_abs, 1.0)
    rule = frac | q_pos   # the nearer root if it is > 0, else the farther one
    if faults.on("sphere-near-root-from-inside"):
        rule = frac & q_pos   # t = t0: only where both roots are > 0
    return num, den, (disc >= 0) & (q_abs > 0) & rule


def intersect(o, d, center, radius, tmax):
    """Nearest root in (0, tmax) and whether there is one (the hit record's t); |d| = 1.

    The hit is the nearest root in front of the ray, t0 if t0 > 0, else t1 (a ray
    from inside the sphere meets it at the far root; the roots: lecture 1,
    "Ray-sphere intersection"), picked by the roots' signs (:func:`nearest_fraction`).
    """
    num, den, found = nearest_fraction(o, d, center, radius)
    t = num / den
    return t, found & (t < tmax)


def occludes(o, d, center, radius, tmax):
    """Whether a root lies in (0, tmax), as :func:`intersect` says, without its division
    (a shadow ray needs the answer, not t): num / den < tmax is decided exactly, by the
    sign of fma(tmax, den, -num) (den > 0), so the answer differs from :func:`intersect`'s
    only where num / den rounds to tmax."""
    num, den, found = nearest_fraction(o, d, center, radius)
    return found & (dr.fma(tmax, den, -num) > 0)


def normal(p, center, radius):
    """Outward unit normal: the gradient of |p - c|^2 - r^2, normalised."""
    return (p - center) / radius
