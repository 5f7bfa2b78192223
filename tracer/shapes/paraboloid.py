"""Ray-paraboloid intersection: the elliptic paraboloid z = x^2/a^2 + y^2/b^2, 0 <= z <= height.

An implicit surface F(x, y, z) = x^2/a^2 + y^2/b^2 - z = 0 (lecture 1,
"Surface normals": the elliptic paraboloid). In the shape's local space the
ray o + t d gives A t^2 + B t + C = 0 with
A = dx^2/a^2 + dy^2/b^2, B = 2 (ox dx / a^2 + oy dy / b^2) - dz,
C = ox^2/a^2 + oy^2/b^2 - oz; where A = 0 (a ray parallel to the axis) the
equation is linear, t = -C / B. A root counts when 0 <= z <= height. The
normal is the gradient, grad F = (2x / a^2, 2y / b^2, -1), which points away
from the bowl's inside (down and out); to world space by the inverse
transpose of to_world.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from whitted.tracer import transform as tf
from whitted.tracer.backend import deferred
from whitted.tracer.settings import Matrix, Table, as_tuple, check_transform
from whitted.tracer.shapes import base

dr = deferred("drjit")


def intersect(o, d, inv_a2, inv_b2, height, tmax):
    """(t, hit) for rays in the paraboloid's local space; inv_a2 = 1 / a^2, inv_b2 = 1 / b^2."""
    A = d.x * d.x * inv_a2 + d.y * d.y * inv_b2
    B = 2 * (o.x * d.x * inv_a2 + o.y * d.y * inv_b2) - d.z
    C = o.x * o.x * inv_a2 + o.y * o.y * inv_b2 - o.z
    disc = B * B - 4 * A * C
    quadratic = A > 1e-12 * (d.z * d.z + 1e-30)
    q = -0.5 * (B + dr.copysign(dr.sqrt(dr.maximum(disc, 0)), B))
    r0 = dr.select(quadratic, C / q, -C / B)
    r1 = dr.select(quadratic, q / A, -C / B)
    real = dr.select(quadratic, disc >= 0, B != 0)
    t0 = dr.minimum(r0, r1)
    t1 = dr.maximum(r0, r1)
    z0 = dr.fma(d.z, t0, o.z)
    z1 = dr.fma(d.z, t1, o.z)
    ok0 = real & (t0 > 0) & (t0 < tmax) & (z0 >= 0) & (z0 <= height)
    ok1 = real & (t1 > 0) & (t1 < tmax) & (z1 >= 0) & (z1 <= height)
    return dr.select(ok0, t0, t1), ok0 | ok1


def gradient(p, inv_a2, inv_b2):
    """grad F at a local point: (2x / a^2, 2y / b^2, -1) (unnormalised)."""
    return type(p)(2 * p.x * inv_a2, 2 * p.y * inv_b2, -1)


def uv(p, a, b, height):
    """The surface's parameters: x = a s cos(phi), y = b s sin(phi), z = s^2, as
    (s / sqrt(height), phi / 2 pi) in [0, 1]^2 (the tessellation for Mitsuba uses the same)."""
    import math

    r = dr.sqrt(dr.maximum(p.z, 0) / height)
    phi = dr.atan2(p.y / b, p.x / a)
    phi = dr.select(phi < 0, phi + 2 * math.pi, phi)
    return r, phi * (0.5 / math.pi)


# --------------------------------------------------------------------------- the kind


@dataclass(frozen=True)
class Paraboloid(base.ShapeModel):
    """z = x^2 / a^2 + y^2 / b^2 for 0 <= z <= height in local space, placed by ``to_world``."""
    shape_type: ClassVar[str] = "paraboloid"
    tessellated: ClassVar[bool] = True   # Mitsuba has no paraboloid
    a: float
    b: float
    height: float
    to_world: Matrix
    material: str | None
    emitter: Any = None   # always None: no sampler, so no area emitter
    placement: base.Placement | None = base.placement_field()


MODEL = Paraboloid


def parse(t: Table, ctx: base.Context) -> Paraboloid:
    m = ctx.to_world()
    shape = Paraboloid(t.number("a", 1.0, lo=0, lo_open=True),
                       t.number("b", 1.0, lo=0, lo_open=True),
                       t.number("height", 1.0, lo=0, lo_open=True), as_tuple(m),
                       ctx.material, ctx.emitter, ctx.placement())
    h = math.sqrt(shape.height)
    check_transform(t, "height", m @ tf.scale((shape.a * h, shape.b * h, shape.height)),
                    "shape (a, b and height against each other)")
    return shape


def bounds(shape) -> tuple[np.ndarray, np.ndarray]:
    s = np.sqrt(shape.height)
    return base.box_corners(shape.to_world, (-shape.a * s, -shape.b * s, 0),
                            (shape.a * s, shape.b * s, shape.height))


class Block(base.LocalBlock):
    """Paraboloids, each intersected in its own local space (unrolled)."""

    @staticmethod
    def matrix(shape) -> np.ndarray:
        return np.asarray(shape.to_world)

    @staticmethod
    def extra(shape):
        return (1 / shape.a ** 2, 1 / shape.b ** 2, shape.height, shape.a, shape.b)

    def local_test(self, ol, dl, t, extra):
        ia2, ib2, h, _, _ = extra
        return intersect(ol, dl, ia2, ib2, h, t)

    def local_surface(self, local, extra):
        ia2, ib2, h, a, b = extra
        grad = gradient(local, ia2, ib2)
        u, v = uv(local, a, b, h)
        return local, grad, u, v
