"""Ray-rectangle intersection: Mitsuba's rectangle, [-1, 1]^2 in local xy, under an affine map.

An affine map keeps the rectangle a planar parallelogram with centre C and
half-edge vectors U, V (the images of local +x and +y). A ray meets its plane
n.(p - C) = 0 at t = n.(C - o) / n.d (lecture 2, "infinite plane"); the hit
is inside when its local coordinates (a, b), defined by p - C = a U + b V,
satisfy |a| <= 1 and |b| <= 1. The local coordinates come from the dual basis
U* = (V x m) / |m|^2, V* = (m x U) / |m|^2 with m = U x V, for which
U*.U = V*.V = 1 and U*.V = V*.U = 0, so shear is handled too.
"""

import drjit as dr
import numpy as np

from whitted.tracer import faults


def frame(center, u, v):
    """Precomputed (numpy, float64) plane normal m/|m| and dual vectors for one rectangle."""
    m = np.cross(u, v)
    m2 = float(np.dot(m, m))
    return m / np.sqrt(m2), np.cross(v, m) / m2, np.cross(m, u) / m2


def plane_t(o, d, point, n):
    """Ray parameter of the intersection with the plane through ``point`` with normal ``n``."""
    return dr.dot(point - o, n) / dr.dot(d, n)


def intersect(o, d, center, n, u_dual, v_dual, tmax):
    """(t, hit, a, b): the hit's ray parameter, whether it is inside, and its local coordinates."""
    t = plane_t(o, d, center, n)
    rel = dr.fma(d, t, o) - center
    a = dr.dot(rel, u_dual)
    b = dr.dot(rel, v_dual)
    hit = (t > 0) & (t < tmax) & (dr.abs(a) <= 1) & (dr.abs(b) <= 1)
    if faults.on("plane-hit-behind-ray"):
        hit = (t < tmax) & (dr.abs(a) <= 1) & (dr.abs(b) <= 1)
    return t, hit, a, b


def uv(a, b):
    """Texture coordinates as Mitsuba's rectangle defines them: (a, b) mapped to [0, 1]^2."""
    return dr.fma(a, 0.5, 0.5), dr.fma(b, 0.5, 0.5)
