"""Ray-sphere intersection (implicit surface |p - c|^2 - r^2 = 0).

Substituting the ray p(t) = o + t d gives the quadratic a t^2 + 2 b' t + c = 0
with a = d.d, b' = d.(o - c), c = |o - c|^2 - r^2 (lecture 1, "Ray-sphere
intersection": two, one or no real roots by the sign of the discriminant).
Two float32 refinements keep it accurate far from the sphere, following
Haines et al., "Precision Improvements for Ray/Sphere Intersection" (Ray
Tracing Gems, ch. 7, 2019): the discriminant is computed as
a (r^2 - |f - (b'/a) d|^2), which avoids cancelling b'^2 against a c, and the
two roots as q / a and c / q with q = -(b' + sign(b') sqrt(disc)), which avoids
cancelling -b' against sqrt(disc).

The surface normal is the normalised gradient of the implicit function,
grad(|p - c|^2 - r^2) / 2 = p - c, divided by r.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from whitted.tracer import faults
from whitted.tracer import transform as tf
from whitted.tracer.backend import deferred, jit
from whitted.tracer.settings import Matrix, Table, Vec3, as_tuple, check_transform
from whitted.tracer.shapes import base

dr = deferred("drjit")
lights = deferred("whitted.tracer.lights")


def quadratic(o, d, center, radius, unit: bool = True):
    """(b', c, disc, a) of the ray-sphere quadratic a t^2 + 2 b' t + c = 0, with
    f = o - centre: a = d.d, b' = d.f, c = |f|^2 - r^2 and the discriminant in the
    accurate form a (r^2 - |f - (b'/a) d|^2) (module docstring). ``unit`` promises
    |d| = 1: a is then 1, returned as None, and disc = r^2 - |f - b' d|^2."""
    f = o - center
    b = dr.dot(f, d)
    c = dr.squared_norm(f) - radius * radius
    if unit:
        a = None
        disc = radius * radius - dr.squared_norm(f - b * d)
        disc = faults.pick("sphere-half-b-discriminant", lambda: b * b - 4 * c, disc)
    else:
        a = dr.squared_norm(d)
        disc = a * (radius * radius - dr.squared_norm(f - (b / a) * d))
    return b, c, disc, a


def roots(o, d, center, radius, unit: bool = False):
    """Both roots (t0 <= t1) of the ray-sphere quadratic and a mask of rays with real roots.

    Where the discriminant is 0 (a tangent ray) t0 == t1: one root. Roots may
    be negative: a ray starting inside the sphere has t0 < 0 < t1. ``unit``
    promises |d| = 1 (a = 1), which saves two divisions.
    """
    b, c, disc, a = quadratic(o, d, center, radius, unit)
    real = disc >= 0
    q = -(b + dr.copysign(dr.sqrt(dr.maximum(disc, 0)), b))
    t_a = c / q
    t_b = q if unit else q / a
    # q == 0 only when b == 0 and disc == 0 (a tangent ray through... the tangent point)
    t_a = dr.select(q == 0, 0, t_a)
    t0 = dr.minimum(t_a, t_b)
    t1 = dr.maximum(t_a, t_b)
    return t0, t1, real


def nearest_fraction(o, d, center, radius):
    """The nearest root > 0 as a fraction (num, den), den > 0, and whether there is one;
    |d| = 1. A block of spheres compares its spheres' roots as fractions and divides
    once, for the nearest (``tracer.geometry._SphereBlock``); :func:`intersect` divides.

    The roots are q and c / q (:func:`roots`), |q| = |b'| + sqrt(disc), q of the
    sign opposite to b''s sign bit; their product is c. Where q > 0 the nearer
    positive root is c / q if c > 0 (c / q <= q, as c <= b'^2 <= q^2), else q; where
    q < 0 only c / q can be positive, when c < 0. So the root is |c| / |q| where c
    and q have one sign, and q / 1 where q > 0 and c <= 0; |c| / |q| is c / q to
    the bit. A vector division takes the one divider unit for many cycles (as does
    a square root), so a block of five spheres divides once instead of five times.
    """
    b, c, disc, _ = quadratic(o, d, center, radius)
    q_abs = dr.abs(b) + dr.sqrt(dr.maximum(disc, 0))        # |q|, as roots() rounds it
    q_pos = dr.copysign(1.0, b) < 0                          # q > 0 (where |q| > 0)
    frac = ((c > 0) == q_pos) & (c != 0)                     # c and q of one sign
    num = dr.select(frac, dr.abs(c), q_abs)
    den = dr.select(frac, q_abs, 1.0)
    rule = frac | q_pos   # the nearer root if it is > 0, else the farther one
    # the bug: t = t0, only where both roots are > 0
    rule = faults.pick("sphere-near-root-from-inside", lambda: frac & q_pos, rule)
    return num, den, (disc >= 0) & (q_abs > 0) & rule


def intersect(o, d, center, radius, tmax):
    """Nearest root in (0, tmax) and whether there is one (the hit record's t); |d| = 1.

    The hit is the nearest root in front of the ray, t0 if t0 > 0, else t1 (a ray
    from inside the sphere meets it at the far root; the roots: lecture 1,
    "Ray-sphere intersection"), picked by the roots' signs (:func:`nearest_fraction`).
    """
    num, den, found = nearest_fraction(o, d, center, radius)
    t = num / den
    return t, found & (t < tmax)


def occludes(o, d, center, radius, tmax):
    """Whether a root lies in (0, tmax), as :func:`intersect` says, without its division
    (a shadow ray needs the answer, not t): num / den < tmax is decided exactly, by the
    sign of fma(tmax, den, -num) (den > 0), so the answer differs from :func:`intersect`'s
    only where num / den rounds to tmax."""
    num, den, found = nearest_fraction(o, d, center, radius)
    return found & (dr.fma(tmax, den, -num) > 0)


def normal(p, center, radius):
    """Outward unit normal: the gradient of |p - c|^2 - r^2, normalised."""
    return (p - center) / radius


# --------------------------------------------------------------------------- the kind


@dataclass(frozen=True)
class Sphere(base.ShapeModel):
    shape_type: ClassVar[str] = "sphere"
    center: Vec3
    radius: float
    material: str | None
    emitter: Any = None   # an AreaEmitter (tracer.emitters.area) or None
    #: rotation of the sphere's own frame (its texture coordinates), row-major 3x3
    rotation: Matrix = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))
    placement: base.Placement | None = base.placement_field()

    def to_world(self) -> np.ndarray:
        """The whole placement as Mitsuba builds it: rotation, uniform scale, translation."""
        m = np.eye(4)
        m[:3, :3] = np.asarray(self.rotation) * self.radius
        m[:3, 3] = self.center
        return m


MODEL = Sphere


def parse(t: Table, ctx: base.Context) -> Sphere:
    m = ctx.to_world()
    center = np.asarray(t.vec3("center", [0.0, 0.0, 0.0]))
    radius = t.number("radius", 1.0, lo=0, lo_open=True)
    if not tf.is_similarity(m) or np.linalg.det(m[:3, :3]) < 0:
        t.fail("to_world", "a sphere takes only translations, rotations and uniform "
                           "positive scales (the result must stay a sphere)")
    scale = float(np.linalg.norm(m[:3, 0]))
    # (the switch is asked only where the scale can matter)
    unscaled = scale != 1.0 and faults.on("sphere-radius-unscaled")
    world_radius = radius if unscaled else radius * scale
    shape = Sphere(tuple(float(x) for x in tf.apply_point(m, center)), world_radius,
                   ctx.material, ctx.emitter, as_tuple(m[:3, :3] / scale),
                   ctx.placement(center=tuple(float(x) for x in center), radius=radius))
    check_transform(t, "radius", shape.to_world(), "placement (centre and radius)")
    return shape


def bounds(shape: Sphere) -> tuple[np.ndarray, np.ndarray]:
    c = np.asarray(shape.center, dtype=np.float64)
    return c - shape.radius, c + shape.radius


class Block(base.TableBlock):
    fields = ("c", "r")

    def __init__(self, spheres: list[Sphere]):
        self.count = len(spheres)
        self.c = base.v3([s.center for s in spheres])
        self.r = base.floats([s.radius for s in spheres])
        # Rows of each sphere's inverse rotation (its local frame, for uv).
        rot = np.asarray([np.asarray(s.rotation) for s in spheres])  # (N, 3, 3)
        self.r0, self.r1, self.r2 = (base.v3(rot[:, :, k]) for k in range(3))
        self._constants()

    def test(self, o, d, t, i):
        return intersect(o, d, self.get("c", i), self.get("r", i), t)

    def _unrolled(self, o, d, t, prim):
        """The nearest sphere, the roots compared as fractions and the nearest divided
        once (:func:`nearest_fraction`): one division a ray, not one a sphere (a vector
        division and a square root each take the one divider unit for many cycles). t
        is :meth:`test`'s for the sphere found, and that sphere is :meth:`test`'s but
        where two spheres' roots are within rounding of each other."""
        num, den = t, jit.Float(1.0)
        for i in range(self.count):
            n_i, d_i, hit = nearest_fraction(o, d, self.get("c", i), self.get("r", i))
            closer = hit & (n_i * den < num * d_i)   # n_i / d_i < num / den, dens > 0
            num = dr.select(closer, n_i, num)
            den = dr.select(closer, d_i, den)
            prim = dr.select(closer, i + self.base, prim)
        return num / den, prim

    any_hit = True

    def occluded(self, o, d, tmax, active):
        """Any sphere with a root in (0, tmax) (:func:`occludes`: no division); many
        spheres in a loop that stops at the first."""
        if self.count > base.UNROLL:
            return self._occluded_looped(o, d, tmax, active)
        hit = dr.zeros(jit.Bool, dr.width(tmax))
        for i in range(self.count):
            hit |= occludes(o, d, self.get("c", i), self.get("r", i), tmax)
        return hit

    def _occluded_looped(self, o, d, tmax, active):
        def body(active, count, hit, i):
            return active, count, occludes(o, d, self.get("c", i), self.get("r", i), tmax), i + 1

        _, _, hit, _ = dr.while_loop(
            (active, dr.opaque(jit.UInt32, self.count), dr.zeros(jit.Bool, dr.width(tmax)),
             jit.UInt32(0)),
            lambda active, count, hit, i: active & ~hit & (i < count), body,
            labels=("active", "count", "hit", "i"))
        return hit

    def surface(self, k, o, d, t, mask):
        c = self.get("c", k, mask)
        r = self.get("r", k, mask)
        p = dr.fma(d, t, o)
        n = dr.normalize(p - c)
        p = dr.fma(n, r, c)  # re-project onto the sphere: the error stays relative to r
        n = faults.pick("unnormalized-normal", lambda: n * r, n)   # the gradient p - c
        # Local direction R^T n (columns of R are the local axes in world space).
        local = jit.Array3f(dr.dot(dr.gather(jit.Array3f, self.r0, k, mask), n),
                            dr.dot(dr.gather(jit.Array3f, self.r1, k, mask), n),
                            dr.dot(dr.gather(jit.Array3f, self.r2, k, mask), n))
        phi = dr.atan2(local.y, local.x)
        phi = dr.select(phi < 0, phi + 2 * dr.pi, phi)
        uv = jit.Array2f(phi * (0.5 / dr.pi), dr.acos(dr.clip(local.z, -1, 1)) / dr.pi)
        return p, n, n, uv


class Sampler:
    """A sphere sampled uniformly in the cone of directions it subtends (solid angle)."""
    aim = (0.0, 0.0)  # the cone's axis: towards the centre

    def __init__(self, shape):
        self.center, self.radius = base.const3(shape.center), faults.number(shape.radius)

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
        t0, _, real = roots(origin, wi, self.center, self.radius)
        # A grazing sample can miss by rounding: take the tangent distance then.
        dist = dr.select(real & (t0 > 0), t0, dr.dot(self.center - origin, wi))
        return wi, dist, dr.select(outside, radiance / pdf, 0)
