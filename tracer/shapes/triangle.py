"""Watertight ray-triangle intersection, with barycentric coordinates.

The test is that of Woop, Benthin and Wald, "Watertight Ray/Triangle
Intersection", Journal of Computer Graphics Techniques 2(1), 2013 (also pbrt,
3rd ed., section 3.6.2). A point of the triangle (p0, p1, p2) is
b0 p0 + b1 p1 + b2 p2 with b0 + b1 + b2 = 1 and all b_i >= 0 (lecture 2,
"Ray-triangle intersection"). The ray o + t d is taken to *ray space*: a
translation puts its origin at 0, a permutation of the axes makes kz, the
axis along which |d| is largest, the third one, and a shear (Sx, Sy) =
(d_kx, d_ky) / d_kz makes the ray the kz axis. There the question "does the
ray meet the triangle" is the 2D question "is the origin inside the
projected triangle (A, B, C)", answered by the signs of the three edge
functions

    U = e(B, C),  V = e(C, A),  W = e(A, B),  e(P, Q) = P_x Q_y - P_y Q_x,

twice the signed areas of the triangles (0, B, C), (0, C, A), (0, A, B): the
ray hits (from either side: the surfaces are two-sided) where they do not
have opposite signs, and the barycentrics are (U, V, W) / (U + V + W).

Why nothing passes between two triangles that share an edge:

1. A shared vertex is taken to ray space by the same arithmetic in both
   triangles (the ray space depends on the ray only), so both see the same
   float32 point. (So the callers pass corners, never p0 and edges: an edge
   p1 - p0 rounded in one triangle is not the other triangle's.)
2. :func:`edge` evaluates e(P, Q) as fma(P_x, Q_y, -P_y Q_x) - fma(P_y, Q_x,
   -P_x Q_y). Swapping P and Q swaps the two fused terms bit for bit (a
   product is commutative, and so is its rounding), and round(a - b) =
   -round(b - a): the triangle on the other side of an edge gets exactly the
   opposite value. A compiler that fuses a product into an add cannot break
   this, as every product already sits in an explicit fma.
3. Its sign is exact: with X = P_x Q_y and Y = P_y Q_x exact, both fused
   terms are rounded from X - round(Y) and Y - round(X), which are ordered
   as X and Y are (X > Y implies X - round(Y) > Y - round(X), and, rounding
   being monotone, the two terms cannot round to one value unless X = Y), so
   the sign of the difference is the sign of X - Y, and it is 0 only where
   X = Y. Woop et al. get exact signs by recomputing an edge function in
   double precision where its float value is 0; here the float32 value is
   exact in sign everywhere, which is the same guarantee without a second
   precision (as long as no product falls below float32's normal range,
   about 1e-38, where the fma no longer gives the product's rounding error).

With exact signs of exactly opposite values, a ray through a shared edge
(an edge function exactly 0) hits both triangles, and one beside it hits the
triangle on its side: the triangles of a mesh, projected to ray space, leave
no gap, at edges or at vertices.

t is the interpolated depth (U A_z + V B_z + W C_z) / (U + V + W), with the
depths scaled by S_z = 1 / d_kz: in units of |d|, like the other shapes' t.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar, NamedTuple

import numpy as np

from whitted.tracer import faults
from whitted.tracer.backend import deferred, jit
from whitted.tracer.settings import Table, Vec3, norm, norm_or_1, read_local_points
from whitted.tracer.shapes import base

dr = deferred("drjit")
lights = deferred("whitted.tracer.lights")


class RaySpace(NamedTuple):
    """The per-ray part of the test: the axis permutation and the shear of Woop et al."""
    o: object
    z_is_x: object    # kz = x (then kx, ky = y, z)
    z_is_y: object    # kz = y (then kx, ky = z, x); where neither: kz = z (kx, ky = x, y)
    sx: object        # d_kx / d_kz
    sy: object        # d_ky / d_kz
    sz: object        # 1 / d_kz


def ray_space(o, d) -> RaySpace:
    """The ray space of rays (o, d): computed once per ray, shared by every triangle it meets.

    kz is the axis of the largest |d_k|, and (kx, ky) follow it cyclically.
    Woop et al. swap kx and ky where d_kz < 0 to keep the triangles' winding
    for back-face culling; two-sided surfaces need no winding, so no swap.
    """
    ax, ay, az = dr.abs(d.x), dr.abs(d.y), dr.abs(d.z)
    z_is_x = (ax >= ay) & (ax >= az)
    z_is_y = ~z_is_x & (ay >= az)
    dx, dy, dz = _permute(z_is_x, z_is_y, d)
    # Divisions, not a reciprocal: each shear factor rounded once.
    return RaySpace(o, z_is_x, z_is_y, dx / dz, dy / dz, 1.0 / dz)


def _permute(z_is_x, z_is_y, v):
    """(v_kx, v_ky, v_kz): the cyclic permutation that puts kz last."""
    def pick(a, b, c):  # a where kz = x, b where kz = y, c where kz = z
        return dr.select(z_is_x, a, dr.select(z_is_y, b, c))

    return pick(v.y, v.z, v.x), pick(v.z, v.x, v.y), pick(v.x, v.y, v.z)


def to_ray_space(rs: RaySpace, p):
    """(x, y, z) of a point in ray space, z not yet scaled by S_z.

    The same arithmetic for every triangle, so a shared vertex lands on the
    same float32 point in each of them.
    """
    x, y, z = _permute(rs.z_is_x, rs.z_is_y, p - rs.o)
    return dr.fma(-rs.sx, z, x), dr.fma(-rs.sy, z, y), z


def edge(px, py, qx, qy):
    """Twice e(P, Q) = P_x Q_y - P_y Q_x, with edge(Q, P) = -edge(P, Q) bit for bit.

    The sign is exact (the module docstring says why); the value is within a
    few float32 roundings of 2 (P_x Q_y - P_y Q_x).
    """
    return dr.fma(px, qy, -(py * qx)) - dr.fma(py, qx, -(px * qy))


def intersect(o, d, p0, p1, p2, tmax, rs: RaySpace | None = None):
    """(t, hit, beta, gamma) for rays (o, d) against triangles (p0, p1, p2).

    Watertight (Woop, Benthin and Wald 2013) and two-sided. ``hit`` where the
    ray meets the triangle, edges and vertices included, at 0 < t < tmax; t
    is in units of |d|; (beta, gamma) are the barycentric weights of p1 and
    p2 (p0's is 1 - beta - gamma). ``rs`` is :func:`ray_space` of (o, d), to
    be computed once when one ray meets many triangles.
    """
    if rs is None:
        rs = ray_space(o, d)
    ax, ay, az = to_ray_space(rs, p0)
    bx, by, bz = to_ray_space(rs, p1)
    cx, cy, cz = to_ray_space(rs, p2)
    u = edge(bx, by, cx, cy)
    v = edge(cx, cy, ax, ay)
    w = edge(ax, ay, bx, by)
    # Inside (or on an edge) where no two edge functions have opposite signs.
    outside = ((u < 0) | (v < 0) | (w < 0)) & ((u > 0) | (v > 0) | (w > 0))
    det = u + v + w  # all of one sign (or 0): no cancellation, 0 only if all are
    inv = 1.0 / det
    t = dr.fma(u, az, dr.fma(v, bz, w * cz)) * rs.sz * inv
    hit = ~outside & (det != 0) & (t > 0) & (t < tmax)
    return t, hit, v * inv, w * inv


def normal(e1, e2):
    """Face normal of a counter-clockwise triangle: normalize(e1 x e2)."""
    return dr.normalize(dr.cross(e1, e2))


def interpolate(beta, gamma, a0, a1, a2):
    """A vertex attribute at barycentrics (1 - beta - gamma, beta, gamma)."""
    beta, gamma = faults.pick("barycentrics-swapped", lambda: (gamma, beta), (beta, gamma))
    return a0 * (1 - beta - gamma) + a1 * beta + a2 * gamma


# --------------------------------------------------------------------------- the kind


@dataclass(frozen=True)
class Triangle(base.ShapeModel):
    shape_type: ClassVar[str] = "triangle"
    vertices: tuple[Vec3, Vec3, Vec3]  # world space, after to_world
    material: str | None
    emitter: Any = None   # an AreaEmitter (tracer.emitters.area) or None
    placement: base.Placement | None = base.placement_field()


MODEL = Triangle


def parse(t: Table, ctx: base.Context) -> Triangle:
    local, verts = read_local_points(t, "vertices", ctx.to_world(), exactly=3)
    e1, e2 = verts[1] - verts[0], verts[2] - verts[0]
    # Relative: the sine of the angle between the edges, as float32 can resolve it.
    if not norm(np.cross(e1 / norm_or_1(e1), e2 / norm_or_1(e2))) > 2.0**-23:
        t.fail("vertices", "expected a triangle with non-zero area "
                           "(the vertices are collinear, or nearly so for float32)")
    return Triangle(tuple(tuple(float(x) for x in p) for p in verts), ctx.material,
                    ctx.emitter, ctx.placement(points=local))


def bounds(shape) -> tuple[np.ndarray, np.ndarray]:
    return base.box_of(shape.vertices)


class Block(base.TableBlock):
    # The corners themselves (not p0 and two edges): a vertex that two triangles share
    # is then the same float32 point in both, which the watertight test needs.
    fields = ("p0", "p1", "p2")

    def __init__(self, tris: list[Triangle]):
        self.count = len(tris)
        v = np.asarray([t.vertices for t in tris], dtype=np.float64)
        self.p0, self.p1, self.p2 = (base.v3(v[:, k]) for k in range(3))
        n = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
        self.n = base.v3(n / np.linalg.norm(n, axis=1, keepdims=True))
        self._constants()

    def test(self, o, d, t, i):
        ti, hit, _, _ = intersect(o, d, self.get("p0", i), self.get("p1", i),
                                  self.get("p2", i), t)
        return ti, hit

    def surface(self, k, o, d, t, mask):
        n = dr.gather(jit.Array3f, self.n, k, mask)
        p0, p1, p2 = (dr.gather(jit.Array3f, getattr(self, f), k, mask) for f in self.fields)
        _, _, beta, gamma = intersect(o, d, p0, p1, p2, dr.inf)
        # Mitsuba's mesh without texture coordinates: uv = (beta, gamma).
        return dr.fma(d, t, o), n, n, jit.Array2f(beta, gamma)


class Sampler(base.FlatSampler):
    """A triangle of area |e1 x e2| / 2, sampled by the square-root warp."""
    aim = (4 / 9, 0.5)  # barycentrics (1/3, 1/3): the centroid

    def __init__(self, shape):
        p = np.asarray(shape.vertices)
        self.p0 = base.const3(p[0])
        self.e1, self.e2 = base.const3(p[1] - p[0]), base.const3(p[2] - p[0])
        n = np.cross(p[1] - p[0], p[2] - p[0])
        self.n = base.const3(n / np.linalg.norm(n))
        self.area = 0.5 * float(np.linalg.norm(n))

    def point(self, u):
        return lights.sample_triangle(u, self.p0, self.e1, self.e2)
