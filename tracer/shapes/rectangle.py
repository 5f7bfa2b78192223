"""Ray-rectangle intersection: Mitsuba's rectangle, [-1, 1]^2 in local xy, under an affine map.

An affine map keeps the rectangle a planar parallelogram with centre C and
half-edge vectors U, V (the images of local +x and +y). A ray meets its plane
n.(p - C) = 0 at t = n.(C - o) / n.d (lecture 2, "infinite plane"); the hit
is inside when its local coordinates (a, b), defined by p - C = a U + b V,
satisfy |a| <= 1 and |b| <= 1. The local coordinates come from the dual basis
U* = (V x m) / |m|^2, V* = (m x U) / |m|^2 with m = U x V, for which
U*.U = V*.V = 1 and U*.V = V*.U = 0, so shear is handled too.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from whitted.tracer import faults
from whitted.tracer import transform as tf
from whitted.tracer.backend import deferred, jit
from whitted.tracer.settings import Matrix, Table, as_tuple
from whitted.tracer.shapes import base

dr = deferred("drjit")
lights = deferred("whitted.tracer.lights")


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
    hit = faults.pick("plane-hit-behind-ray",
                      lambda: (t < tmax) & (dr.abs(a) <= 1) & (dr.abs(b) <= 1), hit)
    return t, hit, a, b


def uv(a, b):
    """Texture coordinates as Mitsuba's rectangle defines them: (a, b) mapped to [0, 1]^2."""
    return dr.fma(a, 0.5, 0.5), dr.fma(b, 0.5, 0.5)


# --------------------------------------------------------------------------- the kind


@dataclass(frozen=True)
class Planar(base.ShapeModel):
    """A flat shape in local xy (normal +z) placed by ``to_world``."""
    to_world: Matrix
    material: str | None
    emitter: Any = None   # an AreaEmitter (tracer.emitters.area) or None
    placement: base.Placement | None = base.placement_field()

    def corners(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Centre and the images of local +x and +y (half-edges, or radii) in world space."""
        m = np.asarray(self.to_world)
        c = tf.apply_point(m, (0, 0, 0))
        return c, tf.apply_point(m, (1, 0, 0)) - c, tf.apply_point(m, (0, 1, 0)) - c

    def normal(self) -> np.ndarray:
        """Mitsuba's orientation: the inverse transpose of to_world applied to +z."""
        n = tf.apply_normal(np.asarray(self.to_world), (0, 0, 1))
        return n / np.linalg.norm(n)


@dataclass(frozen=True)
class Rectangle(Planar):
    """Mitsuba's rectangle: [-1, 1]^2 in local xy, normal +z, placed by ``to_world``."""
    shape_type: ClassVar[str] = "rectangle"


MODEL = Rectangle


def parse(t: Table, ctx: base.Context) -> Rectangle:
    return Rectangle(as_tuple(ctx.to_world()), ctx.material, ctx.emitter, ctx.placement())


def bounds(shape: Planar) -> tuple[np.ndarray, np.ndarray]:
    return base.box_corners(shape.to_world, (-1, -1, 0), (1, 1, 0))


class Block(base.TableBlock):
    """Rectangles (or disks, :class:`tracer.shapes.disk.Block`): a centre, two axes (as a
    dual basis) and a normal."""
    fields = ("c", "n", "ud", "vd")
    #: the inside test and the texture coordinates of the kind
    hit_formula = staticmethod(intersect)
    uv_formula = staticmethod(uv)

    def __init__(self, shapes):
        self.count = len(shapes)
        frames = [s.corners() for s in shapes]
        duals = [frame(c, u, v) for c, u, v in frames]
        self.c = base.v3([c for c, _, _ in frames])
        self.n = base.v3([s.normal() for s in shapes])  # Mitsuba's: inverse transpose of +z
        self.ud = base.v3([ud for _, ud, _ in duals])
        self.vd = base.v3([vd for _, _, vd in duals])
        self._constants()

    def test(self, o, d, t, i):
        ti, hit, _, _ = self.hit_formula(o, d, self.get("c", i), self.get("n", i),
                                         self.get("ud", i), self.get("vd", i), t)
        return ti, hit

    def surface(self, k, o, d, t, mask):
        c, n = self.get("c", k, mask), self.get("n", k, mask)
        p = dr.fma(d, t, o)
        p = p - dr.dot(p - c, n) * n  # re-project onto the plane
        rel = p - c
        a = dr.dot(rel, self.get("ud", k, mask))
        b = dr.dot(rel, self.get("vd", k, mask))
        uv = jit.Array2f(*self.uv_formula(a, b))
        return p, n, n, uv


class Sampler(base.FlatSampler):
    """Mitsuba's rectangle [-1, 1]^2 under to_world: a parallelogram of area 4 |u x v|."""

    def __init__(self, shape):
        c, u, v = shape.corners()
        self.center, self.u, self.v = base.const3(c), base.const3(u), base.const3(v)
        self.n = base.const3(shape.normal())
        self.area = self.local_area() * float(np.linalg.norm(np.cross(u, v)))

    @staticmethod
    def local_area() -> float:
        """Area of the local shape: the square [-1, 1]^2."""
        if faults.on("area-pdf-rectangle"):
            return 1.0   # the unit square taken for Mitsuba's [-1, 1]^2
        return 4.0

    def point(self, u):
        return lights.sample_parallelogram(u, self.center, self.u, self.v)
