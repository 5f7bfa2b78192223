"""Ray-cylinder intersection: Mitsuba's open cylinder, x^2 + y^2 = 1 for 0 <= z <= 1 locally.

The ray is taken into the cylinder's local space (o' = M^-1 o, d' = M^-1 d,
which keeps the ray parameter t), where the implicit surface
F(x, y, z) = x^2 + y^2 - 1 = 0 gives the quadratic
(d'x^2 + d'y^2) t^2 + 2 (o'x d'x + o'y d'y) t + (o'x^2 + o'y^2 - 1) = 0
(lecture 1, implicit surfaces). A root counts when its z lies in [0, 1]; the
nearer such root is the hit, so the inside of the open tube is visible. The
normal is grad F = (2x, 2y, 0), taken to world space by the inverse transpose
of M.
"""

import drjit as dr


def intersect(o_local, d_local, tmax):
    """(t, hit) for rays already in the cylinder's local space (d not necessarily unit)."""
    a = d_local.x * d_local.x + d_local.y * d_local.y
    b = o_local.x * d_local.x + o_local.y * d_local.y            # half of the linear term
    c = o_local.x * o_local.x + o_local.y * o_local.y - 1
    disc = b * b - a * c
    real = (disc >= 0) & (a > 0)
    q = -(b + dr.copysign(dr.sqrt(dr.maximum(disc, 0)), b))
    r0 = c / q
    r1 = q / a
    t0 = dr.minimum(r0, r1)
    t1 = dr.maximum(r0, r1)
    z0 = dr.fma(d_local.z, t0, o_local.z)
    z1 = dr.fma(d_local.z, t1, o_local.z)
    ok0 = real & (t0 > 0) & (t0 < tmax) & (z0 >= 0) & (z0 <= 1)
    ok1 = real & (t1 > 0) & (t1 < tmax) & (z1 >= 0) & (z1 <= 1)
    t = dr.select(ok0, t0, t1)
    return t, ok0 | ok1


def local_normal(p_local):
    """The gradient of x^2 + y^2 - 1 at a local point, (x, y, 0), unnormalised."""
    return type(p_local)(p_local.x, p_local.y, 0)


def uv(p_local):
    """Mitsuba's cylinder coordinates: (phi / 2 pi, z)."""
    phi = dr.atan2(p_local.y, p_local.x)
    phi = dr.select(phi < 0, phi + 2 * dr.pi, phi)
    return phi * (0.5 / dr.pi), p_local.z
