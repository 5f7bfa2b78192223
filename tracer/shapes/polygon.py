"""Ray-polygon intersection: the plane, then a point-in-polygon test (lecture 2).

A planar polygon with vertices v_0 .. v_{n-1} lies in the plane through v_0
with normal n (Newell's method: n = sum_i v_i x v_{i+1}, robust for
non-convex polygons). A ray meets the plane at t = n.(v_0 - o) / n.d; the
hit is inside when it is inside the polygon in the plane's 2D coordinates,
decided by the crossing-number (even-odd) rule: a half-line from the point
crosses the boundary an odd number of times exactly when the point is
inside (Haines, "Point in Polygon Strategies", Graphics Gems IV, 1994). It
holds for convex and non-convex simple polygons alike.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from whitted.tracer.backend import deferred, jit
from whitted.tracer.settings import Table, Vec3, read_local_points
from whitted.tracer.shapes import base, mesh

dr = deferred("drjit")


def newell_normal(pts: np.ndarray) -> np.ndarray:
    """Area-weighted normal of a polygon: sum of v_i x v_{i+1} (length = twice the area)."""
    return np.sum(np.cross(pts, np.roll(pts, -1, axis=0)), axis=0)


def plane_frame(pts: np.ndarray):
    """(origin, u, v, n): an orthonormal frame of the polygon's plane, or None if degenerate."""
    n = newell_normal(pts)
    length = np.linalg.norm(n)
    size = np.max(np.linalg.norm(pts - pts[0], axis=1))
    if length <= 1e-12 * max(size, 1e-30) ** 2:
        return None
    n = n / length
    e = pts[1] - pts[0]
    k = 1
    while np.linalg.norm(e) == 0 and k + 1 < len(pts):
        k += 1
        e = pts[k] - pts[0]
    u = e - np.dot(e, n) * n
    u /= np.linalg.norm(u)
    return pts[0], u, np.cross(n, u), n


def _segments_cross(a, b, c, d) -> bool:
    def orient(p, q, r):
        return (q[0] - p[0]) * (r[1] - p[1]) - (q[1] - p[1]) * (r[0] - p[0])

    o1, o2, o3, o4 = orient(a, b, c), orient(a, b, d), orient(c, d, a), orient(c, d, b)
    return (o1 * o2 < 0) and (o3 * o4 < 0)


def self_intersects(pts2: np.ndarray) -> bool:
    """Whether two non-adjacent edges of a 2D polygon cross (O(n^2); polygons are small)."""
    n = len(pts2)
    for i in range(n):
        a, b = pts2[i], pts2[(i + 1) % n]
        for j in range(i + 2, n):
            if i == 0 and j == n - 1:
                continue  # adjacent through the closing edge
            if _segments_cross(a, b, pts2[j], pts2[(j + 1) % n]):
                return True
    return False


def inside(px, py, xs: list[float], ys: list[float]):
    """Crossing-number test of points (px, py) against one polygon given as constants.

    For each edge (x_i, y_i) - (x_j, y_j) that straddles the horizontal line
    through the point, count a crossing when the edge passes to the right of it.
    """
    odd = dr.zeros(type(px >= 0), dr.width(px)) if dr.width(px) > 1 else (px != px)
    n = len(xs)
    for i in range(n):
        j = (i + 1) % n
        xi, yi, xj, yj = xs[i], ys[i], xs[j], ys[j]
        if yi == yj:
            continue  # a horizontal edge never straddles
        straddles = (yi > py) != (yj > py)
        x_cross = xi + (py - yi) * ((xj - xi) / (yj - yi))
        odd = odd ^ (straddles & (px < x_cross))
    return odd


def intersect(o, d, origin, n, u, v, xs, ys, tmax):
    """(t, hit, a, b): plane parameter, inside test, and the hit's 2D plane coordinates."""
    t = dr.dot(origin - o, n) / dr.dot(d, n)
    rel = dr.fma(d, t, o) - origin
    a, b = dr.dot(rel, u), dr.dot(rel, v)
    hit = (t > 0) & (t < tmax) & inside(a, b, xs, ys)
    return t, hit, a, b


def ear_clip(pts2: np.ndarray) -> list[tuple[int, int, int]]:
    """Triangles of a simple polygon by ear clipping (for the Mitsuba conversion).

    Counter-clockwise order is assumed (the caller orients the 2D coordinates by
    the polygon's own normal, so the triangles face the same way).
    """
    idx = list(range(len(pts2)))

    def area2(a, b, c):
        return (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])

    def in_tri(p, a, b, c):
        return area2(a, b, p) >= 0 and area2(b, c, p) >= 0 and area2(c, a, p) >= 0

    tris = []
    guard = 0
    while len(idx) > 3 and guard < 10_000:
        guard += 1
        for k in range(len(idx)):
            i0, i1, i2 = idx[k - 1], idx[k], idx[(k + 1) % len(idx)]
            a, b, c = pts2[i0], pts2[i1], pts2[i2]
            if area2(a, b, c) <= 0:
                continue  # reflex corner: not an ear
            if any(in_tri(pts2[m], a, b, c) for m in idx if m not in (i0, i1, i2)):
                continue
            tris.append((i0, i1, i2))
            idx.pop(k)
            break
        else:
            break
    if len(idx) == 3:
        tris.append((idx[0], idx[1], idx[2]))
    return tris


# --------------------------------------------------------------------------- the kind


@dataclass(frozen=True)
class Polygon(base.ShapeModel):
    """A planar polygon (convex or not), vertices in world space after ``to_world``."""
    shape_type: ClassVar[str] = "polygon"
    vertices: tuple[Vec3, ...]
    material: str | None
    emitter: Any = None   # an AreaEmitter (tracer.emitters.area) or None
    placement: base.Placement | None = base.placement_field()


MODEL = Polygon


def parse(t: Table, ctx: base.Context) -> Polygon:
    local, verts = read_local_points(t, "vertices", ctx.to_world())
    _check_polygon(t, verts)
    return Polygon(tuple(tuple(float(x) for x in p) for p in verts), ctx.material,
                   ctx.emitter, ctx.placement(points=local))


def _check_polygon(t: Table, verts: list) -> None:
    """Planar, not degenerate and simple (no edge crosses another)."""
    pts = np.asarray(verts)
    frame = plane_frame(pts)
    if frame is None:
        t.fail("vertices", "expected a polygon with non-zero area")
    origin, u, v, n = frame
    size = float(np.max(np.linalg.norm(pts - pts.mean(axis=0), axis=1)))
    off = np.abs((pts - origin) @ n)
    if off.max() > 1e-6 * size:
        t.fail("vertices", f"expected a planar polygon (a vertex lies {off.max():.3g} "
                           "off the plane of the others)")
    if self_intersects((pts - origin) @ np.stack([u, v], axis=1)):
        t.fail("vertices", "expected a simple polygon (two of its edges cross)")


def bounds(shape) -> tuple[np.ndarray, np.ndarray]:
    return base.box_of(shape.vertices)


class Block(base.Block):
    """Each polygon unrolled: its plane and its 2D outline as kernel constants."""

    def __init__(self, polys: list[Polygon]):
        self.count = len(polys)
        self.items = []
        for poly in polys:
            pts = np.asarray(poly.vertices, dtype=np.float64)
            origin, u, v, n = plane_frame(pts)
            xy = (pts - origin) @ np.stack([u, v], axis=1)
            self.items.append((origin, u, v, n, [float(x) for x in xy[:, 0]],
                               [float(y) for y in xy[:, 1]]))

    def test(self, o, d, t, i):
        origin, u, v, n, xs, ys = self.items[i]
        c3 = base.const3
        ti, hit, _, _ = intersect(o, d, c3(origin), c3(n), c3(u), c3(v), xs, ys, t)
        return ti, hit

    def intersect(self, o, d, t, prim, active):
        return self._unrolled(o, d, t, prim)

    def surface(self, k, o, d, t, mask):
        c3 = base.const3
        p = dr.fma(d, t, o)
        n = dr.zeros(jit.Array3f, dr.width(p))
        uv = dr.zeros(jit.Array2f, dr.width(p))
        for i, (origin, u, v, nn, _, _) in enumerate(self.items):
            sel = mask & (k == i)
            rel = p - c3(origin)
            n = dr.select(sel, c3(nn), n)
            # The plane's own 2D coordinates (the conversion gives Mitsuba the same uvs).
            uv = dr.select(sel, jit.Array2f(dr.dot(rel, c3(u)), dr.dot(rel, c3(v))), uv)
        return p, n, n, uv


class Sampler(mesh.Sampler):
    """A polygon, by the ear-clipped triangles the Mitsuba conversion gives Mitsuba too."""

    @staticmethod
    def triangles(shape):
        pts = np.asarray(shape.vertices, dtype=np.float64)
        origin, u, v, _ = plane_frame(pts)
        xy = (pts - origin) @ np.stack([u, v], axis=1)
        return pts, np.asarray(ear_clip(xy))
