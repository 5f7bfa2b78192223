"""The shape interface: what the scene, the geometry and the area lights ask of a shape kind.

Modelled on Mitsuba 3's shape plugins (``src/shapes/*.cpp``: one interface,
``ray_intersect`` / ``compute_surface_interaction`` / ``sample_position``, a
plugin registered by name) and pbrt-v4's shapes (``src/pbrt/shapes.h``:
``Sphere``, ``Triangle``, ... with one set of methods). A kind is one module
of :mod:`tracer.shapes` holding, beside its intersection formulas (pure
functions over Dr.Jit arrays, lecture 1 "Ray-sphere intersection", lecture 2
"Ray-surface intersection"):

* ``MODEL``: its scene-model dataclass, a :class:`ShapeModel` (re-exported by
  :mod:`tracer.scene`);
* ``parse(t, ctx)``: the ``[[shapes]]`` table into a ``MODEL``, its keys read
  through ``t``, a :class:`~tracer.settings.Table`; ``ctx`` (:class:`Context`)
  holds what the scene parser read before (material, emitter) and reads
  ``to_world`` when the kind asks (:meth:`Context.to_world`);
* ``pack(members, packing)``: its shapes as the geometry's blocks (a
  :class:`Block` each: the packed Dr.Jit table, closest hit, hit record), with
  the material ids and radiances of their primitives; by default
  (:func:`pack`) one ``Block(members)`` with one primitive a shape;
* ``Sampler`` (optional): how an area emitter on the shape is sampled
  (:class:`FlatSampler` for flat shapes); a kind without one carries no emitter;
* ``bounds(shape)`` (optional): an axis-aligned box, for the hierarchy of a
  group's instances.

Kind modules reach Dr.Jit through :func:`tracer.backend.deferred`: every kind
is imported whenever a scene is parsed, and parsing must not start Dr.Jit.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from whitted.tracer import faults
from whitted.tracer.backend import deferred, jit, upload, upload_rows
from whitted.tracer.settings import Table, read_steps

dr = deferred("drjit")

INVALID = 0xFFFFFFFF

#: Tables up to this size are unrolled into the kernel with constant numbers.
UNROLL = 16


class ShapeModel:
    """A shape of the scene model (a frozen dataclass a kind, fields of its own; no fields
    here, so that each kind keeps its field order)."""

    #: the kind, as Mitsuba's ``Shape::shape_type()`` says it (the scene's ``type``)
    shape_type: ClassVar[str] = ""
    #: whether the table names a ``material`` (an instance's materials are its group's)
    takes_material: ClassVar[bool] = True
    #: why the kind may not be a member of a group ("" where it may)
    not_in_groups: ClassVar[str] = ""
    #: the Mitsuba conversion tessellates it (a shape Mitsuba lacks)
    tessellated: ClassVar[bool] = False

    def primitive_count(self) -> int:
        """Primitives the tracer builds tables for (a mesh: its triangles)."""
        return 1


@dataclass(frozen=True)
class Placement:
    """Where a shape is, as its table in the file gives it, before the tracer composes
    anything: ``to_world``'s steps (:data:`tracer.settings.Step`; none: the identity) and
    the kind's own values in its own space (a triangle's or a polygon's ``points``, a
    sphere's ``center`` and ``radius``). The Mitsuba side builds its shape from these
    with Mitsuba's own transforms (reference/shapes/), so the tracer's composition of
    them (tracer/transform.py) is checked by the comparison instead of shared by it.
    A shape made in code has none (``placement`` None), and the conversion takes its
    composed matrix."""
    steps: tuple = ()
    points: tuple | None = None
    center: tuple | None = None
    radius: float | None = None


def placement_field():
    """The ``placement`` field every kind's model ends with (:class:`Placement`): not part
    of the shape's identity (two readings of one placement are the same shape)."""
    return field(default=None, compare=False, repr=False)


@dataclass
class Context:
    """What the scene parser read of a ``[[shapes]]`` table before the kind's own keys."""
    t: Table
    material: str | None
    emitter: Any
    materials: dict
    groups: dict
    base: Path
    in_group: bool = False
    _matrix: Any = field(default=None, repr=False)
    _steps: tuple = field(default=(), repr=False)

    def to_world(self) -> np.ndarray:
        """The table's ``to_world`` (steps, :func:`tracer.settings.read_steps`), read on
        the first call: a kind reads it where its keys begin."""
        if self._matrix is None:
            self._matrix, self._steps = read_steps(self.t, "to_world")
        return self._matrix

    def placement(self, **values) -> Placement:
        """The shape's :class:`Placement`: the steps of its ``to_world`` and ``values``."""
        self.to_world()
        return Placement(self._steps, **values)


# --------------------------------------------------------------------------- packing


def v3(rows) -> object:
    return upload_rows(jit.Array3f, rows)


def floats(values) -> object:
    return upload(jit.Float, values, np.float32)


def uints(values) -> object:
    return upload(jit.UInt32, values, np.uint32)


def const3(v) -> object:
    """A constant 3-vector written into the kernel (an input of it in the formula-bug
    sweep: :func:`tracer.faults.number`)."""
    return jit.Array3f(*(faults.number(v[k]) for k in range(3)))


def affine(m: np.ndarray, p, point: bool = True):
    """The 4x4 (or 3x3) matrix m, as kernel constants, applied to a point or a vector."""
    rows = [const3(m[r, :3]) for r in range(3)]
    x, y, z = (dr.dot(row, p) for row in rows)
    if point:
        x, y, z = (x + faults.number(m[0, 3]), y + faults.number(m[1, 3]),
                   z + faults.number(m[2, 3]))
    return jit.Array3f(x, y, z)


def pack(module, members: list, packing) -> list:
    """The default packing: one ``module.Block(members)``, one primitive a shape."""
    return [(module.Block(members), *packing.rows(members))]


class Block:
    """A contiguous range of primitive ids [base, base + count) of one kind."""
    base = 0
    count = 0

    def intersect(self, o, d, t, prim, active):
        raise NotImplementedError

    def surface(self, k, o, d, t, mask):
        """(p, n, ns, uv) for lanes in ``mask``, whose local primitive index is k."""
        raise NotImplementedError

    #: whether :meth:`occluded` stops at the first hit (else it is the closest hit's)
    any_hit = False

    #: whether a triangle mesh's BVH is walked, here or in an instanced group (the
    #: integrator then traces a pixel's samples K to a lane, tracer/integrator.py's GROUPS)
    has_mesh = False

    def occluded(self, o, d, tmax, active):
        """Where one of the block's primitives lies on the ray at 0 < t < tmax (lanes in
        ``active``; others may answer anything): by default its closest hit."""
        _, prim = self.intersect(o, d, tmax, dr.full(jit.UInt32, INVALID, dr.width(tmax)),
                                 active)
        return prim != INVALID

    def intersect_group(self, rays, ts, prims):
        """:meth:`intersect` of K rays a lane, ``rays`` a list of K (o, d, active): lists
        of K t and prim. By default each ray on its own; a block that can walk the K
        rays of a lane together (a mesh's) does. A ray outside its ``active`` keeps its
        t and prim: the rays of a lane share the loops that skip inactive lanes, and an
        unrolled table tests every ray it is given."""
        out = []
        for (o, d, a), t, prim in zip(rays, ts, prims, strict=True):
            ti, pi = self.intersect(o, d, t, prim, a)
            if a is not True:
                ti, pi = dr.select(a, ti, t), dr.select(a, pi, prim)
            out.append((ti, pi))
        return [t for t, _ in out], [prim for _, prim in out]

    def occluded_group(self, rays):
        """:meth:`occluded` of K rays a lane, ``rays`` a list of K (o, d, tmax, active)."""
        return [self.occluded(*ray) for ray in rays]

    def _update(self, ti, hit, i, t, prim):
        return dr.select(hit, ti, t), dr.select(hit, i + self.base, prim)

    def test(self, o, d, t, i):
        """(t, hit) of primitive i (a Python int, or a UInt32 array for looped tables)."""
        raise NotImplementedError

    def _unrolled(self, o, d, t, prim):
        """Every primitive written into the kernel one after another, nearest hit kept."""
        for i in range(self.count):
            ti, hit = self.test(o, d, t, i)
            t, prim = self._update(ti, hit, i, t, prim)
        return t, prim


class TableBlock(Block):
    """Primitives stored as arrays; unrolled with constants when few, else a symbolic loop."""
    fields: tuple[str, ...] = ()

    def _constants(self):
        self.const = {}
        for name in self.fields:
            a = getattr(self, name).numpy()
            if a.ndim == 1:
                self.const[name] = [faults.number(x) for x in a]
            else:
                self.const[name] = [const3(col) for col in a.T]

    def get(self, name, i, active=True):
        if isinstance(i, int):
            return self.const[name][i]
        src = getattr(self, name)
        return dr.gather(type(src), src, i, active)

    def intersect(self, o, d, t, prim, active):
        if self.count <= UNROLL:
            return self._unrolled(o, d, t, prim)
        return self._looped(o, d, t, prim, active)

    def _looped(self, o, d, t, prim, active):
        # drjit.while_loop, not a `while` under drjit.syntax (docs/extending.md, "Loops").
        def body(active, count, d, i, o, prim, t):
            ti, hit = self.test(o, d, t, i)
            t, prim = self._update(ti, hit, i, t, prim)
            return active, count, d, i + 1, o, prim, t

        names = ("active", "count", "d", "i", "o", "prim", "t")
        *_, prim, t = dr.while_loop(
            (active, dr.opaque(jit.UInt32, self.count), d, jit.UInt32(0), o, prim, t),
            lambda active, count, d, i, *_: active & (i < count), body, labels=names)
        return t, prim


class LocalBlock(Block):
    """Shapes each intersected in its own local space (quadrics: cylinders, paraboloids),
    unrolled: the ray goes in by the inverse of the shape's matrix, which keeps t, and the
    normal comes out by the inverse transpose. A kind says its matrix, its constants,
    its test and its local hit record."""

    def __init__(self, shapes):
        self.count = len(shapes)
        self.items = []
        for s in shapes:
            m = self.matrix(s)
            inv = np.linalg.inv(m)
            normal_m = np.linalg.inv(m[:3, :3]).T  # normals: the inverse transpose
            self.items.append((m, inv, normal_m, self.extra(s)))

    @staticmethod
    def matrix(shape) -> np.ndarray:
        """The shape's local-to-world 4x4 matrix."""
        raise NotImplementedError

    @staticmethod
    def extra(shape):
        """The shape's own constants, handed to :meth:`local_test` and :meth:`local_surface`."""
        return None

    def local_test(self, ol, dl, t, extra):
        """(t, hit) of a ray in local space."""
        raise NotImplementedError

    def local_surface(self, local, extra):
        """(the local point, re-projected if need be; the local gradient; u; v)."""
        raise NotImplementedError

    def test(self, o, d, t, i):
        _, inv, _, extra = self.items[i]
        ol, dl = affine(inv, o), affine(inv, d, point=False)
        return self.local_test(ol, dl, t, extra)

    def intersect(self, o, d, t, prim, active):
        return self._unrolled(o, d, t, prim)

    def surface(self, k, o, d, t, mask):
        p = dr.fma(d, t, o)
        n = dr.zeros(jit.Array3f, dr.width(p))
        uv = dr.zeros(jit.Array2f, dr.width(p))
        pw = p
        for i, item in enumerate(self.items):
            sel = mask & (k == i)
            m, inv, normal_m, extra = item
            local, grad, u, v = self.local_surface(affine(inv, p), extra)
            nw = dr.normalize(affine(normal_m, grad, point=False))
            n = dr.select(sel, nw, n)
            pw = dr.select(sel, affine(m, local), pw)
            uv = dr.select(sel, jit.Array2f(u, v), uv)
        return pw, n, n, uv


def box_of(points) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi) of a set of points, column by column: numpy's ``min(axis=0)`` of an
    (N, 3) array took 8.5 ms for the 500,000 vertices of the 1,000,000-triangle knot, a
    column's ``min()`` 0.8 ms (the same numbers; issue 33)."""
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    return (np.array([p[:, c].min() for c in range(3)]),
            np.array([p[:, c].max() for c in range(3)]))


def box_corners(m, lo, hi) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi) around the local box [lo, hi] under the 4x4 matrix m."""
    c = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])
                  for z in (lo[2], hi[2])], dtype=np.float64)
    return box_of(c @ np.asarray(m, dtype=np.float64)[:3, :3].T +
                  np.asarray(m, dtype=np.float64)[:3, 3])


# --------------------------------------------------------------------------- area sampling


class FlatSampler:
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
        area = faults.number(self.area)
        value = dr.select(cos_l > 0, radiance * (cos_l * area / (dist * dist)), 0)
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
