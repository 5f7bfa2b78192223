"""Ray-disk intersection: Mitsuba's disk, the unit disk in local xy (normal +z), affinely mapped.

As for the rectangle (tracer/shapes/rectangle.py) the image is planar, with
centre C and the images U, V of the local x and y axes; the hit's local
coordinates (a, b) come from the dual basis, and it is inside when
a^2 + b^2 <= 1 (an ellipse in world space under a non-uniform scale).
"""

import drjit as dr

from whitted.tracer.shapes.rectangle import plane_t


def intersect(o, d, center, n, u_dual, v_dual, tmax):
    """(t, hit, a, b): ray parameter, inside test, local coordinates."""
    t = plane_t(o, d, center, n)
    rel = dr.fma(d, t, o) - center
    a = dr.dot(rel, u_dual)
    b = dr.dot(rel, v_dual)
    hit = (t > 0) & (t < tmax) & (dr.fma(a, a, b * b) <= 1)
    return t, hit, a, b


def uv(a, b):
    """Mitsuba's disk coordinates: (r, phi / 2 pi) with phi in [0, 2 pi)."""
    r = dr.sqrt(dr.fma(a, a, b * b))
    phi = dr.atan2(b, a)
    phi = dr.select(phi < 0, phi + 2 * dr.pi, phi)
    return r, phi * (0.5 / dr.pi)
