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

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from whitted.tracer import faults
from whitted.tracer import transform as tf
from whitted.tracer.backend import deferred, jit
from whitted.tracer.settings import Matrix, Table, Vec3, as_tuple, check_transform
from whitted.tracer.shapes import base

dr = deferred("drjit")


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


# --------------------------------------------------------------------------- the kind


def _mitsuba_frame(n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The tangents Mitsuba's Frame3f(n) chooses (Duff et al. 2017), so that uv agree."""
    sign = 1.0 if n[2] >= 0 else -1.0
    a = -1.0 / (sign + n[2])
    b = n[0] * n[1] * a
    return (np.array([1 + sign * n[0] * n[0] * a, sign * b, -sign * n[0]]),
            np.array([b, sign + n[1] * n[1] * a, -n[1]]))


@dataclass(frozen=True)
class Cylinder(base.ShapeModel):
    """Mitsuba's open cylinder from p0 to p1 with a radius, then ``to_world``."""
    shape_type: ClassVar[str] = "cylinder"
    p0: Vec3
    p1: Vec3
    radius: float
    to_world: Matrix
    material: str | None
    emitter: Any = None   # an AreaEmitter (tracer.emitters.area) or None
    placement: base.Placement | None = base.placement_field()

    def local_to_world(self) -> np.ndarray:
        """Unit cylinder x^2 + y^2 = 1, 0 <= z <= 1 to world, composed as Mitsuba does."""
        d = np.subtract(self.p1, self.p0)
        length = float(np.linalg.norm(d))
        frame = np.eye(4)
        s_, t_ = _mitsuba_frame(d / length)
        frame[:3, 0], frame[:3, 1], frame[:3, 2] = s_, t_, d / length
        return (np.asarray(self.to_world) @ tf.translate(self.p0) @ frame
                @ tf.scale((self.radius, self.radius, length)))


MODEL = Cylinder


def parse(t: Table, ctx: base.Context) -> Cylinder:
    m = ctx.to_world()
    p0, p1 = t.vec3("p0", [0.0, 0.0, 0.0]), t.vec3("p1", [0.0, 0.0, 1.0])
    t.distinct("p1", p0, p1, "p0")
    shape = Cylinder(p0, p1, t.number("radius", 1.0, lo=0, lo_open=True), as_tuple(m),
                     ctx.material, ctx.emitter, ctx.placement())
    check_transform(t, "radius", shape.local_to_world(), "placement (radius against length)")
    lin = shape.local_to_world()[:3, :3]
    x, y, z = lin[:, 0], lin[:, 1], lin[:, 2]
    tol = 1e-6 * max(np.linalg.norm(x), np.linalg.norm(z))
    if (abs(np.dot(x, y)) > tol * np.linalg.norm(y) or abs(np.dot(x, z)) > tol *
            np.linalg.norm(z) or abs(np.dot(y, z)) > tol * np.linalg.norm(z) or
            abs(np.linalg.norm(x) - np.linalg.norm(y)) > tol or np.linalg.det(lin) < 0):
        t.fail("to_world", "a cylinder's to_world may not shear it, mirror it or scale its "
                           "cross-section unevenly (Mitsuba's cylinder does not support it)")
    return shape


def bounds(shape) -> tuple[np.ndarray, np.ndarray]:
    return base.box_corners(shape.local_to_world(), (-1, -1, 0), (1, 1, 1))


class Block(base.LocalBlock):
    """Cylinders, each intersected in its local unit cylinder (unrolled)."""

    @staticmethod
    def matrix(shape) -> np.ndarray:
        return shape.local_to_world()

    def local_test(self, ol, dl, t, extra):
        return intersect(ol, dl, t)

    def local_surface(self, local, extra):
        # Re-project onto the unit cylinder, as Mitsuba does, to limit round-off.
        inv_r = dr.rsqrt(local.x * local.x + local.y * local.y)
        local = jit.Array3f(local.x * inv_r, local.y * inv_r, local.z)
        grad = local_normal(local)
        u, v = uv(local)
        return local, grad, u, v


class Sampler:
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
        # Python floats, written into the kernel (inputs of it in the formula-bug sweep,
        # faults.number): a numpy scalar times a Dr.Jit array would be numpy's product,
        # computed on the host (tests/tracer/test_kernel_cache.py)
        def numbers(rows):
            return [[faults.number(x) for x in row] for row in rows]

        self.m, self.nm = numbers(a), numbers(np.linalg.inv(a).T)
        self.t = numbers([m[:3, 3]])[0]

    def sample(self, radiance, p, origin, u):
        s, c = dr.sincos(2 * math.pi * u.y)
        z = u.x
        m, t, nm = self.m, self.t, self.nm
        y = jit.Array3f(m[0][0] * c + m[0][1] * s + m[0][2] * z + t[0],
                        m[1][0] * c + m[1][1] * s + m[1][2] * z + t[1],
                        m[2][0] * c + m[2][1] * s + m[2][2] * z + t[2])
        n = dr.normalize(jit.Array3f(nm[0][0] * c + nm[0][1] * s, nm[1][0] * c + nm[1][1] * s,
                                     nm[2][0] * c + nm[2][1] * s))
        to_y = y - p
        dist = dr.norm(to_y)
        wi = to_y / dist
        cos_l = -dr.dot(n, wi)
        area = faults.number(self.area)
        return wi, dist, dr.select(cos_l > 0, radiance * (cos_l * area / (dist * dist)), 0)

    shadow_ray = staticmethod(base.FlatSampler.shadow_ray)
