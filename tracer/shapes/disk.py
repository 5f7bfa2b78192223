"""Ray-disk intersection: Mitsuba's disk, the unit disk in local xy (normal +z), affinely mapped.

As for the rectangle (tracer/shapes/rectangle.py) the image is planar, with
centre C and the images U, V of the local x and y axes; the hit's local
coordinates (a, b) come from the dual basis, and it is inside when
a^2 + b^2 <= 1 (an ellipse in world space under a non-uniform scale).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

from whitted.tracer import faults
from whitted.tracer.backend import deferred
from whitted.tracer.settings import Table, as_tuple
from whitted.tracer.shapes import rectangle
from whitted.tracer.shapes.rectangle import plane_t

dr = deferred("drjit")
lights = deferred("whitted.tracer.lights")


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


# --------------------------------------------------------------------------- the kind


@dataclass(frozen=True)
class Disk(rectangle.Planar):
    """Mitsuba's disk: the unit disk in local xy, normal +z, placed by ``to_world``."""
    shape_type: ClassVar[str] = "disk"


MODEL = Disk


def parse(t: Table, ctx) -> Disk:
    return Disk(as_tuple(ctx.to_world()), ctx.material, ctx.emitter, ctx.placement())


bounds = rectangle.bounds


class Block(rectangle.Block):
    """Disks: a rectangle's table, the unit disk's inside test and coordinates."""
    hit_formula = staticmethod(intersect)
    uv_formula = staticmethod(uv)


class Sampler(rectangle.Sampler):
    """Mitsuba's unit disk under to_world: an ellipse of area pi |u x v|."""

    @staticmethod
    def local_area() -> float:
        """Area of the local shape: the unit disk."""
        if faults.on("area-pdf-disk"):
            return 4.0   # the disk's bounding square
        return math.pi

    def point(self, u):
        return lights.sample_ellipse(u, self.center, self.u, self.v)
