"""Area emitters on shapes: ``emitter = { radiance = [...] }``.

A shape with an emitter emits radiance L (W/(m^2 sr)) from its front side,
the side its normal points to (Mitsuba's ``area`` emitter). The tracer uses
it twice:

* a ray that hits the front side brings L back (:func:`emitted`);
* at a shading point it is one light, sampled once per sample
  (:class:`Emitter`), by the sampler of its shape kind: uniform by area
  (rectangle, disk, triangle), estimating integral L cos(theta_l) / r^2 dA
  as L cos(theta_l) A / r^2, or, for a sphere, uniform in the cone of
  directions it subtends, estimating integral L d(omega) as L / pdf (the two
  estimators of :mod:`tracer.lights`, which holds the sampling maps).

Each emitting shape kind has one sampler class below and one line in
:data:`SAMPLERS`; nothing else asks which shape it holds.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from whitted.tracer import faults
from whitted.tracer.backend import deferred, jit, upload, upload_rows
from whitted.tracer.emitters import base
from whitted.tracer.settings import Table

dr = deferred("drjit")
lights = deferred("whitted.tracer.lights")
sphere_f = deferred("whitted.tracer.shapes.sphere")

Color = tuple[float, float, float]


@dataclass(frozen=True)
class AreaEmitter:
    radiance: Color  # W/(m^2 sr), emitted from the front side


def parse(t: Table) -> AreaEmitter:
    return AreaEmitter(t.color("radiance"))


def emitted(radiance_table, prim, cos_o, valid):
    """(L, lanes) of rays that hit an emitting primitive on its front side (cos_o > 0).

    ``radiance_table`` holds each primitive's radiance (zero for shapes that do
    not emit), ``cos_o`` = -d . n is positive where the ray arrives on the side
    the geometric normal points to.
    """
    return dr.gather(jit.Array3f, radiance_table, prim, valid), valid & (cos_o > 0)


# ----------------------------------------------------------------------------- samplers


class _SphereCone:
    """A sphere sampled uniformly in the cone of directions it subtends (solid angle)."""
    aim = (0.0, 0.0)  # the cone's axis: towards the centre

    def __init__(self, shape):
        self.center, self.radius = base.vec(shape.center), float(shape.radius)

    def sample(self, radiance, p, origin, u):
        to_c = self.center - p
        dc = dr.norm(to_c)
        outside = dc > self.radius
        sin2_max = dr.minimum((self.radius * self.radius) / (dc * dc), 1)
        cos_max = dr.sqrt(1 - sin2_max)
        # 1 - cos_max without cancellation, for small and distant spheres
        x, y, z, pdf = lights.sample_cone(u, cos_max, sin2_max / (1 + cos_max))
        w = to_c / dc
        t1, t2 = lights.coordinate_system(w)
        wi = dr.normalize(x * t1 + y * t2 + z * w)
        t0, _, real = sphere_f.roots(origin, wi, self.center, self.radius)
        # A grazing sample can miss by rounding: take the tangent distance then.
        dist = dr.select(real & (t0 > 0), t0, dr.dot(self.center - origin, wi))
        return wi, dist, dr.select(outside, radiance / pdf, 0)


class _Flat:
    """A flat shape sampled uniformly by area: L cos(theta_l) A / r^2 from its front side.

    The sample's distance is measured from p (the point is p + dist wi), and
    the shadow ray is aimed at the point from its origin (:meth:`shadow_ray`).
    """
    aim = (0.5, 0.5)

    def point(self, u):
        raise NotImplementedError

    def sample(self, radiance, p, origin, u):
        y = self.point(u)
        to_y = y - p
        dist = dr.norm(to_y)
        wi = to_y / dist
        cos_l = -dr.dot(self.n, wi)  # front side emits: the light's normal faces p
        value = dr.select(cos_l > 0, radiance * (cos_l * self.area / (dist * dist)), 0)
        return wi, dist, value

    @staticmethod
    def shadow_ray(p, origin, wi, dist):
        """From ``origin`` straight to the sampled point p + dist wi (Mitsuba's spawn_ray_to).

        Along wi from the origin, which sits off the surface, the ray would
        cross the light's own plane short of the point, and where that plane
        meets the shading point's at a grazing angle, that crossing lies on the
        light itself, which then shadows its own light (a shift of the offset
        over the distance to the light's plane, beyond the shadow ray's
        1e-3 margin).
        """
        to = dr.fma(wi, dist, p) - origin
        length = dr.norm(to)
        return to / length, length


class _Parallelogram(_Flat):
    """Mitsuba's rectangle [-1, 1]^2 under to_world: a parallelogram of area 4 |u x v|."""

    def __init__(self, shape):
        c, u, v = shape.corners()
        self.center, self.u, self.v = base.vec(c), base.vec(u), base.vec(v)
        self.n = base.vec(shape.normal())
        self.area = self.local_area() * float(np.linalg.norm(np.cross(u, v)))

    @staticmethod
    def local_area() -> float:
        """Area of the local shape: the square [-1, 1]^2."""
        if faults.on("area-pdf-rectangle"):
            return 1.0   # the unit square taken for Mitsuba's [-1, 1]^2
        return 4.0

    def point(self, u):
        return lights.sample_parallelogram(u, self.center, self.u, self.v)


class _Ellipse(_Parallelogram):
    """Mitsuba's unit disk under to_world: an ellipse of area pi |u x v|."""

    @staticmethod
    def local_area() -> float:
        """Area of the local shape: the unit disk."""
        if faults.on("area-pdf-disk"):
            return 4.0   # the disk's bounding square
        return math.pi

    def point(self, u):
        return lights.sample_ellipse(u, self.center, self.u, self.v)


class _Triangle(_Flat):
    """A triangle of area |e1 x e2| / 2, sampled by the square-root warp."""
    aim = (4 / 9, 0.5)  # barycentrics (1/3, 1/3): the centroid

    def __init__(self, shape):
        p = np.asarray(shape.vertices)
        self.p0, self.e1, self.e2 = base.vec(p[0]), base.vec(p[1] - p[0]), base.vec(p[2] - p[0])
        n = np.cross(p[1] - p[0], p[2] - p[0])
        self.n = base.vec(n / np.linalg.norm(n))
        self.area = 0.5 * float(np.linalg.norm(n))

    def point(self, u):
        return lights.sample_triangle(u, self.p0, self.e1, self.e2)


class _Triangles(_Flat):
    """A set of triangles (a mesh, a polygon), sampled uniformly by total area.

    A triangle is chosen with probability area_i / A from ``u.x`` (the first
    index whose cumulative area exceeds u.x A, by binary search), u.x is
    stretched back to [0, 1) within that triangle's share and the point placed
    by the square-root warp; the density is 1 / A over the whole set, so the
    estimate is L cos(theta_l) A / r^2 as for one flat shape, with theta_l
    measured against the chosen triangle's normal (its winding's, as the
    tracer's hits see it).
    """
    aim = (0.5, 0.5)

    def __init__(self, shape):
        v, f = self.triangles(shape)
        p0, p1, p2 = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
        cross = np.cross(p1 - p0, p2 - p0)
        twice = np.linalg.norm(cross, axis=1)
        keep = twice > 0
        p0, p1, p2, cross, twice = p0[keep], p1[keep], p2[keep], cross[keep], twice[keep]
        areas = 0.5 * twice
        self.area = float(areas.sum())
        cdf = np.cumsum(areas) / self.area
        cdf[-1] = 1.0
        self.count = len(areas)
        self.cdf = upload(jit.Float, cdf, np.float32)
        self.lo = upload(jit.Float, np.concatenate([[0.0], cdf[:-1]]), np.float32)
        self.p0 = _table(p0)
        self.e1 = _table(p1 - p0)
        self.e2 = _table(p2 - p0)
        self.normals = _table(cross / twice[:, None])

    @staticmethod
    def triangles(shape):
        """(vertices, faces) in world space."""
        return np.asarray(shape.vertices, dtype=np.float64), np.asarray(shape.faces)

    def sample(self, radiance, p, origin, u):
        ux = u.x
        i = dr.binary_search(0, self.count - 1,
                             lambda k: dr.gather(jit.Float, self.cdf, k) <= ux)
        lo = dr.gather(jit.Float, self.lo, i)
        share = dr.gather(jit.Float, self.cdf, i) - lo
        ux = dr.clip((ux - lo) / dr.maximum(share, 1e-30), 0, 0.99999994)
        self.n = dr.gather(jit.Array3f, self.normals, i)
        self._tri = (dr.gather(jit.Array3f, self.p0, i), dr.gather(jit.Array3f, self.e1, i),
                     dr.gather(jit.Array3f, self.e2, i))
        return super().sample(radiance, p, origin, jit.Array2f(ux, u.y))

    def point(self, u):
        p0, e1, e2 = self._tri
        return lights.sample_triangle(u, p0, e1, e2)


class _PolygonTriangles(_Triangles):
    """A polygon, by the ear-clipped triangles the Mitsuba conversion gives Mitsuba too."""

    @staticmethod
    def triangles(shape):
        from whitted.tracer.shapes.polygon import ear_clip, plane_frame

        pts = np.asarray(shape.vertices, dtype=np.float64)
        origin, u, v, _ = plane_frame(pts)
        xy = (pts - origin) @ np.stack([u, v], axis=1)
        return pts, np.asarray(ear_clip(xy))


class _CylinderSide:
    """Mitsuba's open cylinder, sampled uniformly by area on its side.

    In the local unit cylinder (x^2 + y^2 = 1, 0 <= z <= 1) the point
    (cos phi, sin phi, z), phi = 2 pi u.y, z = u.x, is uniform by area, and
    stays so under a to_world that scales x and y alike (Mitsuba's cylinder
    assumes the same); the area is 2 pi r l, the normal the radial direction.
    Emitting from the front side, the outside.
    """
    aim = (0.5, 0.5)

    def __init__(self, shape):
        m = shape.local_to_world()
        a = m[:3, :3]
        r, length = float(np.linalg.norm(a[:, 0])), float(np.linalg.norm(a[:, 2]))
        self.area = 2 * math.pi * r * length
        self.m = a
        self.t = m[:3, 3]
        self.nm = np.linalg.inv(a).T

    def sample(self, radiance, p, origin, u):
        s, c = dr.sincos(2 * math.pi * u.y)
        z = u.x
        m, t, nm = self.m, self.t, self.nm
        y = jit.Array3f(m[0, 0] * c + m[0, 1] * s + m[0, 2] * z + t[0],
                        m[1, 0] * c + m[1, 1] * s + m[1, 2] * z + t[1],
                        m[2, 0] * c + m[2, 1] * s + m[2, 2] * z + t[2])
        n = dr.normalize(jit.Array3f(nm[0, 0] * c + nm[0, 1] * s, nm[1, 0] * c + nm[1, 1] * s,
                                     nm[2, 0] * c + nm[2, 1] * s))
        to_y = y - p
        dist = dr.norm(to_y)
        wi = to_y / dist
        cos_l = -dr.dot(n, wi)
        return wi, dist, dr.select(cos_l > 0, radiance * (cos_l * self.area / (dist * dist)), 0)

    shadow_ray = staticmethod(_Flat.shadow_ray)


def _table(a: np.ndarray):
    return upload_rows(jit.Array3f, a)


#: Shape ``type`` -> how an emitter on it is sampled (one line per emitting shape kind).
#: The order is that of the scene format's error message.
SAMPLERS: dict[str, type] = {
    "sphere": _SphereCone,
    "rectangle": _Parallelogram,
    "triangle": _Triangle,
    "disk": _Ellipse,
    "mesh": _Triangles,
    "cube": _Triangles,           # Mitsuba's cube: a mesh of 12 triangles
    "polygon": _PolygonTriangles,
    "cylinder": _CylinderSide,
}


def shape_type(shape) -> str:
    """The TOML ``type`` of a shape model: its class name in lower case (``Sphere``: sphere)."""
    return type(shape).__name__.lower()


class Emitter(base.Emitter):
    """The area emitter of one shape, as a light sampled once per shading point."""
    delta = False

    def __init__(self, shape, index: int = 0):
        #: the emitter's place among the sampled lights (it chooses the random stream)
        self.index = index
        self.radiance = base.color(shape.emitter.radiance)
        self.sampler = SAMPLERS[shape_type(shape)](shape)
        self.aim = self.sampler.aim

    def sample(self, p, origin, u):
        """(wi, distance, L cos / r^2 / pdf) from one light sample ``u`` per shading point."""
        return self.sampler.sample(self.radiance, p, origin, u)

    def shadow_ray(self, p, origin, wi, dist):
        """The sampler's shadow ray, if it has its own (flat shapes aim at the point)."""
        if hasattr(self.sampler, "shadow_ray"):
            return self.sampler.shadow_ray(p, origin, wi, dist)
        return wi, dist
