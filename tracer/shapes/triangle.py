"""Ray-triangle intersection by Cramer's rule, with barycentric coordinates.

A point of the triangle (p0, p1, p2) is p0 + beta (p1 - p0) + gamma (p2 - p0)
with beta, gamma >= 0 and beta + gamma <= 1 (lecture 2, "Ray-triangle
intersection"). Equating it with the ray o + t d gives the 3x3 linear system

    [e1  e2  -d] (beta, gamma, t)^T = o - p0,   e1 = p1 - p0, e2 = p2 - p0,

solved by Cramer's rule (Shirley, "Fundamentals of Computer Graphics", 4.4.2):
each unknown is a ratio of determinants, and each determinant is a scalar
triple product, det[a b c] = a . (b x c). This is the arithmetic of Moller and
Trumbore's algorithm (1997). The barycentrics of the hit are
(1 - beta - gamma, beta, gamma) for (p0, p1, p2).
"""

import drjit as dr


def intersect(o, d, p0, e1, e2, tmax):
    """(t, hit, beta, gamma) for rays (o, d) against triangles (p0, e1 = p1 - p0, e2 = p2 - p0)."""
    s = o - p0
    # det[e1 e2 -d] = e1 . (e2 x -d) = d . (e1 x e2)  (triple product identities)
    d_x_e2 = dr.cross(d, e2)
    det = dr.dot(e1, d_x_e2)
    inv = dr.rcp(det)
    # beta = det[s e2 -d] / det = s . (d x e2) / det
    beta = dr.dot(s, d_x_e2) * inv
    s_x_e1 = dr.cross(s, e1)
    # gamma = det[e1 s -d] / det = d . (s x e1) / det
    gamma = dr.dot(d, s_x_e1) * inv
    # t = det[e1 e2 s] / det = e2 . (s x e1) / det
    t = dr.dot(e2, s_x_e1) * inv
    hit = ((det != 0) & (beta >= 0) & (gamma >= 0) & (beta + gamma <= 1)
           & (t > 0) & (t < tmax))
    return t, hit, beta, gamma


def normal(e1, e2):
    """Face normal of a counter-clockwise triangle: normalize(e1 x e2)."""
    return dr.normalize(dr.cross(e1, e2))


def interpolate(beta, gamma, a0, a1, a2):
    """A vertex attribute at barycentrics (1 - beta - gamma, beta, gamma)."""
    return a0 * (1 - beta - gamma) + a1 * beta + a2 * gamma
