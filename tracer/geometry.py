"""The scene's shapes as Dr.Jit tables, closest-hit queries and the hit record.

Shapes are gathered into blocks of one kind each (spheres, rectangles,
disks, single triangles, polygons, cylinders, paraboloids, one block per
mesh, one per instance). Every primitive has a global id: each block owns a
contiguous range. A query asks every block for its nearest hit and keeps the
nearest of all, which is what lecture 1's "Intersection routine" does for
one ray at a time, here for a whole wavefront at once.

Small tables are written into the kernel one primitive after another with
their numbers as constants; larger ones are walked by a symbolic loop that
gathers each primitive; meshes are searched through a bounding-volume
hierarchy (tracer/bvh.py). An instance takes the ray into its group's object
space, asks the group's own geometry, and brings the hit record back
(lecture 2, "Instancing"): t is kept because the ray is transformed rather
than renormalised, points go back by the instance's to_world and normals by
its inverse transpose. A few instances of a group are unrolled one after the
other; from ``INSTANCE_SET_MIN`` on, the instances of a group sit in a
bounding-volume hierarchy of their world-space boxes (a top-level BVH, built
by tracer/bvh.py's builder), so that a ray visits about log n of n instances
and the kernel's size does not grow with n.

The hit record (:class:`Surface`) holds the position, the geometric normal
(outward, unit), the shading normal (the interpolated vertex normal of a
smooth mesh, else the geometric one) and Mitsuba's texture coordinates for
each kind of shape.
"""

from __future__ import annotations

from dataclasses import dataclass

import drjit as dr
import numpy as np

from whitted.tracer import backend, faults
from whitted.tracer.backend import any_mask, jit, upload, upload_rows
from whitted.tracer.scene import (
    Cylinder,
    Disk,
    Instance,
    Mesh,
    Paraboloid,
    Polygon,
    Rectangle,
    Sphere,
    Triangle,
)
from whitted.tracer.shapes import cylinder as cyl_f
from whitted.tracer.shapes import disk as disk_f
from whitted.tracer.shapes import paraboloid as par_f
from whitted.tracer.shapes import polygon as poly_f
from whitted.tracer.shapes import rectangle as rect_f
from whitted.tracer.shapes import sphere as sphere_f
from whitted.tracer.shapes import triangle as tri_f

INVALID = 0xFFFFFFFF

#: Tables up to this size are unrolled into the kernel with constant numbers.
UNROLL = 16

#: A group instanced this many times or more is searched through a hierarchy of its
#: instances' boxes (:class:`_InstanceSetBlock`); fewer are unrolled one by one.
INSTANCE_SET_MIN = 8


def _v3(rows) -> object:
    return upload_rows(jit.Array3f, rows)


def _f(values) -> object:
    return upload(jit.Float, values, np.float32)


def _u(values) -> object:
    return upload(jit.UInt32, values, np.uint32)


def _c3(v) -> object:
    """A constant 3-vector written into the kernel."""
    return jit.Array3f(float(v[0]), float(v[1]), float(v[2]))


def _affine(m: np.ndarray, p, point: bool = True):
    """The 4x4 (or 3x3) matrix m, as kernel constants, applied to a point or a vector."""
    rows = [jit.Array3f(float(m[r, 0]), float(m[r, 1]), float(m[r, 2])) for r in range(3)]
    x, y, z = (dr.dot(row, p) for row in rows)
    if point:
        x, y, z = x + float(m[0, 3]), y + float(m[1, 3]), z + float(m[2, 3])
    return jit.Array3f(x, y, z)


@dataclass
class Hit:
    """The hit record's core: ray parameter and global primitive id (INVALID for a miss)."""
    t: object
    prim: object

    @property
    def valid(self):
        return self.prim != INVALID


@dataclass
class Surface:
    """Where a ray hit: position, unit normals (geometric, shading), texture coordinates."""
    p: object
    n: object
    ns: object
    uv: object


# --------------------------------------------------------------------------- blocks


class _Block:
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

    def occluded(self, o, d, tmax, active):
        """Where one of the block's primitives lies on the ray at 0 < t < tmax (lanes in
        ``active``; others may answer anything): by default its closest hit."""
        _, prim = self.intersect(o, d, tmax, dr.full(jit.UInt32, INVALID, dr.width(tmax)),
                                 active)
        return prim != INVALID

    def intersect_group(self, rays, ts, prims):
        """:meth:`intersect` of K rays a lane, ``rays`` a list of K (o, d, active): lists
        of K t and prim. By default each ray on its own; a block that can walk the K
        rays of a lane together (:class:`_MeshBlock`) does."""
        out = [self.intersect(o, d, t, prim, a)
               for (o, d, a), t, prim in zip(rays, ts, prims, strict=True)]
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


class _TableBlock(_Block):
    """Primitives stored as arrays; unrolled with constants when few, else a symbolic loop."""
    fields: tuple[str, ...] = ()

    def _constants(self):
        self.const = {}
        for name in self.fields:
            a = getattr(self, name).numpy()
            if a.ndim == 1:
                self.const[name] = [float(x) for x in a]
            else:
                self.const[name] = [jit.Array3f(*(float(x) for x in col)) for col in a.T]

    def get(self, name, i, active=True):
        if isinstance(i, int):
            return self.const[name][i]
        src = getattr(self, name)
        return dr.gather(type(src), src, i, active)

    def intersect(self, o, d, t, prim, active):
        if self.count <= UNROLL:
            return self._unrolled(o, d, t, prim)
        return self._looped(o, d, t, prim, active)

    @backend.syntax
    def _looped(self, o, d, t, prim, active):
        i = jit.UInt32(0)
        count = dr.opaque(jit.UInt32, self.count)
        while active & (i < count):
            ti, hit = self.test(o, d, t, i)
            t, prim = self._update(ti, hit, i, t, prim)
            i += 1
        return t, prim


class _SphereBlock(_TableBlock):
    fields = ("c", "r")

    def __init__(self, spheres: list[Sphere]):
        self.count = len(spheres)
        self.c = _v3([s.center for s in spheres])
        self.r = _f([s.radius for s in spheres])
        # Rows of each sphere's inverse rotation (its local frame, for uv).
        rot = np.asarray([np.asarray(s.rotation) for s in spheres])  # (N, 3, 3)
        self.r0, self.r1, self.r2 = (_v3(rot[:, :, k]) for k in range(3))
        self._constants()

    def test(self, o, d, t, i):
        return sphere_f.intersect(o, d, self.get("c", i), self.get("r", i), t)

    def _unrolled(self, o, d, t, prim):
        """The nearest sphere, the roots compared as fractions and the nearest divided
        once (:func:`tracer.shapes.sphere.nearest_fraction`): one division a ray, not
        one a sphere (a vector division and a square root each take the one divider
        unit for many cycles). t is :meth:`test`'s for the sphere found, and that
        sphere is :meth:`test`'s but where two spheres' roots are within rounding of
        each other."""
        num, den = t, jit.Float(1.0)
        for i in range(self.count):
            n_i, d_i, hit = sphere_f.nearest_fraction(o, d, self.get("c", i),
                                                      self.get("r", i))
            closer = hit & (n_i * den < num * d_i)   # n_i / d_i < num / den, dens > 0
            num = dr.select(closer, n_i, num)
            den = dr.select(closer, d_i, den)
            prim = dr.select(closer, i + self.base, prim)
        return num / den, prim

    any_hit = True

    def occluded(self, o, d, tmax, active):
        """Any sphere with a root in (0, tmax) (:func:`tracer.shapes.sphere.occludes`: no
        division); many spheres in a loop that stops at the first."""
        if self.count > UNROLL:
            return self._occluded_looped(o, d, tmax, active)
        hit = dr.zeros(jit.Bool, dr.width(tmax))
        for i in range(self.count):
            hit |= sphere_f.occludes(o, d, self.get("c", i), self.get("r", i), tmax)
        return hit

    @backend.syntax
    def _occluded_looped(self, o, d, tmax, active):
        i = jit.UInt32(0)
        hit = dr.zeros(jit.Bool, dr.width(tmax))
        count = dr.opaque(jit.UInt32, self.count)
        while active & ~hit & (i < count):
            hit = sphere_f.occludes(o, d, self.get("c", i), self.get("r", i), tmax)
            i += 1
        return hit

    def surface(self, k, o, d, t, mask):
        c = self.get("c", k, mask)
        r = self.get("r", k, mask)
        p = dr.fma(d, t, o)
        n = dr.normalize(p - c)
        p = dr.fma(n, r, c)  # re-project onto the sphere: the error stays relative to r
        if faults.on("unnormalized-normal"):
            n = n * r   # the gradient p - c, not divided by r
        # Local direction R^T n (columns of R are the local axes in world space).
        local = jit.Array3f(dr.dot(dr.gather(jit.Array3f, self.r0, k, mask), n),
                            dr.dot(dr.gather(jit.Array3f, self.r1, k, mask), n),
                            dr.dot(dr.gather(jit.Array3f, self.r2, k, mask), n))
        phi = dr.atan2(local.y, local.x)
        phi = dr.select(phi < 0, phi + 2 * dr.pi, phi)
        uv = jit.Array2f(phi * (0.5 / dr.pi), dr.acos(dr.clip(local.z, -1, 1)) / dr.pi)
        return p, n, n, uv


class _PlanarBlock(_TableBlock):
    """Rectangles or disks: a centre, two axes (as a dual basis) and a normal."""
    fields = ("c", "n", "ud", "vd")

    def __init__(self, shapes, round_: bool):
        self.round = round_
        self.count = len(shapes)
        frames = [s.corners() for s in shapes]
        duals = [rect_f.frame(c, u, v) for c, u, v in frames]
        self.c = _v3([c for c, _, _ in frames])
        self.n = _v3([s.normal() for s in shapes])  # Mitsuba's: inverse transpose of +z
        self.ud = _v3([ud for _, ud, _ in duals])
        self.vd = _v3([vd for _, _, vd in duals])
        self._constants()

    def test(self, o, d, t, i):
        f = disk_f.intersect if self.round else rect_f.intersect
        ti, hit, _, _ = f(o, d, self.get("c", i), self.get("n", i), self.get("ud", i),
                          self.get("vd", i), t)
        return ti, hit

    def surface(self, k, o, d, t, mask):
        c, n = self.get("c", k, mask), self.get("n", k, mask)
        p = dr.fma(d, t, o)
        p = p - dr.dot(p - c, n) * n  # re-project onto the plane
        rel = p - c
        a = dr.dot(rel, self.get("ud", k, mask))
        b = dr.dot(rel, self.get("vd", k, mask))
        uv = jit.Array2f(*(disk_f.uv(a, b) if self.round else rect_f.uv(a, b)))
        return p, n, n, uv


class _TriangleBlock(_TableBlock):
    # The corners themselves (not p0 and two edges): a vertex that two triangles share
    # is then the same float32 point in both, which the watertight test needs.
    fields = ("p0", "p1", "p2")

    def __init__(self, tris: list[Triangle]):
        self.count = len(tris)
        v = np.asarray([t.vertices for t in tris], dtype=np.float64)
        self.p0, self.p1, self.p2 = (_v3(v[:, k]) for k in range(3))
        n = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
        self.n = _v3(n / np.linalg.norm(n, axis=1, keepdims=True))
        self._constants()

    def test(self, o, d, t, i):
        ti, hit, _, _ = tri_f.intersect(o, d, self.get("p0", i), self.get("p1", i),
                                        self.get("p2", i), t)
        return ti, hit

    def surface(self, k, o, d, t, mask):
        n = dr.gather(jit.Array3f, self.n, k, mask)
        p0, p1, p2 = (dr.gather(jit.Array3f, getattr(self, f), k, mask) for f in self.fields)
        _, _, beta, gamma = tri_f.intersect(o, d, p0, p1, p2, dr.inf)
        # Mitsuba's mesh without texture coordinates: uv = (beta, gamma).
        return dr.fma(d, t, o), n, n, jit.Array2f(beta, gamma)


class _PolygonBlock(_Block):
    """Each polygon unrolled: its plane and its 2D outline as kernel constants."""

    def __init__(self, polys: list[Polygon]):
        self.count = len(polys)
        self.items = []
        for poly in polys:
            pts = np.asarray(poly.vertices, dtype=np.float64)
            origin, u, v, n = poly_f.plane_frame(pts)
            xy = (pts - origin) @ np.stack([u, v], axis=1)
            self.items.append((origin, u, v, n, [float(x) for x in xy[:, 0]],
                               [float(y) for y in xy[:, 1]]))

    def test(self, o, d, t, i):
        origin, u, v, n, xs, ys = self.items[i]
        ti, hit, _, _ = poly_f.intersect(o, d, _c3(origin), _c3(n), _c3(u), _c3(v), xs, ys, t)
        return ti, hit

    def intersect(self, o, d, t, prim, active):
        return self._unrolled(o, d, t, prim)

    def surface(self, k, o, d, t, mask):
        p = dr.fma(d, t, o)
        n = dr.zeros(jit.Array3f, dr.width(p))
        uv = dr.zeros(jit.Array2f, dr.width(p))
        for i, (origin, u, v, nn, _, _) in enumerate(self.items):
            sel = mask & (k == i)
            rel = p - _c3(origin)
            n = dr.select(sel, _c3(nn), n)
            # The plane's own 2D coordinates (the conversion gives Mitsuba the same uvs).
            uv = dr.select(sel, jit.Array2f(dr.dot(rel, _c3(u)), dr.dot(rel, _c3(v))), uv)
        return p, n, n, uv


class _QuadricBlock(_Block):
    """Cylinders or paraboloids, each intersected in its own local space (unrolled)."""

    def __init__(self, shapes, kind: str):
        self.kind = kind
        self.count = len(shapes)
        self.items = []
        for s in shapes:
            m = s.local_to_world() if kind == "cyl" else np.asarray(s.to_world)
            inv = np.linalg.inv(m)
            normal_m = np.linalg.inv(m[:3, :3]).T  # normals: the inverse transpose
            extra = None if kind == "cyl" else (1 / s.a ** 2, 1 / s.b ** 2, s.height, s.a, s.b)
            self.items.append((m, inv, normal_m, extra))

    def test(self, o, d, t, i):
        _, inv, _, extra = self.items[i]
        ol, dl = _affine(inv, o), _affine(inv, d, point=False)
        if self.kind == "cyl":
            return cyl_f.intersect(ol, dl, t)
        ia2, ib2, h, _, _ = extra
        return par_f.intersect(ol, dl, ia2, ib2, h, t)

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
            local = _affine(inv, p)
            if self.kind == "cyl":
                # Re-project onto the unit cylinder, as Mitsuba does, to limit round-off.
                inv_r = dr.rsqrt(local.x * local.x + local.y * local.y)
                local = jit.Array3f(local.x * inv_r, local.y * inv_r, local.z)
                grad = cyl_f.local_normal(local)
                u, v = cyl_f.uv(local)
            else:
                ia2, ib2, h, a, b = extra
                grad = par_f.gradient(local, ia2, ib2)
                u, v = par_f.uv(local, a, b, h)
            nw = dr.normalize(_affine(normal_m, grad, point=False))
            n = dr.select(sel, nw, n)
            pw = dr.select(sel, _affine(m, local), pw)
            uv = dr.select(sel, jit.Array2f(u, v), uv)
        return pw, n, n, uv


class _MeshBlock(_Block):
    """A triangle mesh behind a bounding-volume hierarchy (tracer/bvh.py)."""

    def __init__(self, mesh: Mesh):
        from whitted.tracer.bvh import shared_bvh

        v, f = np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces)
        self.count = len(f)
        self.bvh = shared_bvh(v[f[:, 0]], v[f[:, 1]], v[f[:, 2]])
        n = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
        n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-30)
        self.face_n = _v3(n)
        self.faces = _u(f.reshape(-1))
        self.p = _v3(v)
        self.vn = None if mesh.normals is None else _v3(mesh.normals)
        self.vt = None
        if mesh.uvs is not None:
            self.vt = upload_rows(jit.Array2f, mesh.uvs)

    def intersect(self, o, d, t, prim, active):
        (t,), (prim,) = self.intersect_group([(o, d, active)], [t], [prim])
        return t, prim

    any_hit = True

    def occluded(self, o, d, tmax, active):
        return self.bvh.occluded(o, d, tmax, active)

    def intersect_group(self, rays, ts, prims):
        found = self.bvh.closest_hit_group([(o, d, t, a) for (o, d, a), t
                                            in zip(rays, ts, strict=True)])
        out = [self._update(ti, tri != INVALID, tri, t, prim)
               for (ti, tri, _, _), t, prim in zip(found, ts, prims, strict=True)]
        return [t for t, _ in out], [prim for _, prim in out]

    def occluded_group(self, rays):
        return self.bvh.occluded_group(rays)

    def surface(self, k, o, d, t, mask):
        i0 = dr.gather(jit.UInt32, self.faces, 3 * k, mask)
        i1 = dr.gather(jit.UInt32, self.faces, 3 * k + 1, mask)
        i2 = dr.gather(jit.UInt32, self.faces, 3 * k + 2, mask)
        p0 = dr.gather(jit.Array3f, self.p, i0, mask)
        p1 = dr.gather(jit.Array3f, self.p, i1, mask)
        p2 = dr.gather(jit.Array3f, self.p, i2, mask)
        _, _, beta, gamma = tri_f.intersect(o, d, p0, p1, p2, dr.inf)
        n = dr.gather(jit.Array3f, self.face_n, k, mask)
        ns = n
        if self.vn is not None:  # barycentric interpolation of the vertex normals
            ns = tri_f.interpolate(
                beta, gamma, dr.gather(jit.Array3f, self.vn, i0, mask),
                dr.gather(jit.Array3f, self.vn, i1, mask),
                dr.gather(jit.Array3f, self.vn, i2, mask))
            if not faults.on("normal-not-renormalized"):
                ns = dr.normalize(ns)
        if self.vt is not None:
            uv = tri_f.interpolate(beta, gamma, dr.gather(jit.Array2f, self.vt, i0, mask),
                                   dr.gather(jit.Array2f, self.vt, i1, mask),
                                   dr.gather(jit.Array2f, self.vt, i2, mask))
        else:
            uv = jit.Array2f(beta, gamma)
        return dr.fma(d, t, o), n, ns, uv


class _InstanceBlock(_Block):
    """A group's geometry seen through to_world (lecture 2: transform the ray, not the shape)."""

    def __init__(self, inst: Instance, child: Geometry):
        self.child = child
        self.count = child.count
        m = np.asarray(inst.to_world, dtype=np.float64)
        self.m, self.inv = m, np.linalg.inv(m)
        self.normal_m = instance_normal_matrix(m)

    def _to_object(self, o, d):
        ol = _affine(self.inv, o)
        dl = _affine(self.inv, d, point=False)
        # Unit direction in object space; t scales by its length.
        scale = dr.norm(dl)
        return ol, dl / scale, scale

    def intersect(self, o, d, t, prim, active):
        ol, dl, scale = self._to_object(o, d)
        hit = self.child.closest_hit(ol, dl, t * scale, active)
        found = hit.valid
        return self._update(hit.t / scale, found, hit.prim, t, prim)

    def surface(self, k, o, d, t, mask):
        ol, dl, scale = self._to_object(o, d)
        s = self.child.surface(Hit(t * scale, dr.select(mask, k, INVALID)), ol, dl)
        p = _affine(self.m, s.p)
        n = dr.normalize(_affine(self.normal_m, s.n, point=False))
        ns = dr.normalize(_affine(self.normal_m, s.ns, point=False))
        return p, n, ns, s.uv


def shape_bounds(shape) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi): an axis-aligned box around a shape, in the space its coordinates are in."""
    def box_of(points):
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        return p.min(axis=0), p.max(axis=0)

    def corners(m, lo, hi):
        c = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])
                      for z in (lo[2], hi[2])], dtype=np.float64)
        return box_of(c @ np.asarray(m, dtype=np.float64)[:3, :3].T +
                      np.asarray(m, dtype=np.float64)[:3, 3])

    if isinstance(shape, Sphere):
        c = np.asarray(shape.center, dtype=np.float64)
        return c - shape.radius, c + shape.radius
    if isinstance(shape, (Rectangle, Disk)):
        return corners(shape.to_world, (-1, -1, 0), (1, 1, 0))
    if isinstance(shape, (Triangle, Polygon, Mesh)):
        return box_of(shape.vertices)
    if isinstance(shape, Cylinder):
        return corners(shape.local_to_world(), (-1, -1, 0), (1, 1, 1))
    if isinstance(shape, Paraboloid):
        s = np.sqrt(shape.height)
        return corners(shape.to_world, (-shape.a * s, -shape.b * s, 0),
                       (shape.a * s, shape.b * s, shape.height))
    raise TypeError(f"no bounds for {type(shape).__name__}")


class _InstanceSetBlock(_Block):
    """Many instances of one group behind a BVH over their world-space boxes.

    Primitive ids: instance j's copy of the group's primitive k is j * m + k,
    m the group's primitive count. The hierarchy is built by
    :func:`tracer.bvh.build_box_bvh` and stored in the same node records as a
    triangle BVH (:func:`tracer.bvh.pack_nodes`); the traversal below walks
    it like :class:`tracer.bvh.BVH` does, and at a leaf takes the ray into the
    instance's object space and asks the group's geometry, as
    :class:`_InstanceBlock` does for one instance.
    """

    def __init__(self, instances: list[Instance], child: Geometry, bounds):
        from whitted.tracer.bvh import build_box_bvh, pack_nodes

        self.child = child
        self.n = len(instances)
        self.count = self.n * child.count
        m = np.asarray([inst.to_world for inst in instances], dtype=np.float64)
        inv = np.linalg.inv(m)
        normal = instance_normal_matrix(m)
        self.m_rows, self.m_t = [_v3(m[:, r, :3]) for r in range(3)], _v3(m[:, :3, 3])
        self.inv_rows, self.inv_t = [_v3(inv[:, r, :3]) for r in range(3)], _v3(inv[:, :3, 3])
        self.normal_rows = [_v3(normal[:, r, :]) for r in range(3)]
        # World boxes: the group's box through each instance's to_world (its 8 corners).
        lo, hi = bounds
        c = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])
                      for z in (lo[2], hi[2])], dtype=np.float64)
        w = np.einsum("nij,kj->nki", m[:, :3, :3], c) + m[:, None, :3, 3]
        arrays = build_box_bvh(w.min(axis=1), w.max(axis=1), max_leaf=1)
        self.depth = arrays.depth
        rec, self._root, self._stack = pack_nodes(arrays)
        self.nodes = upload(jit.Float, rec if len(rec) else np.zeros((1, 16)), np.float32)
        self.order = _u(arrays.order)

    @staticmethod
    def _apply(rows, t, idx, p, mask):
        r = [dr.gather(jit.Array3f, row, idx, mask) for row in rows]
        x, y, z = (dr.dot(ri, p) for ri in r)
        if t is not None:
            tc = dr.gather(jit.Array3f, t, idx, mask)
            x, y, z = x + tc.x, y + tc.y, z + tc.z
        return jit.Array3f(x, y, z)

    def _to_object(self, inst, o, d, mask):
        ol = self._apply(self.inv_rows, self.inv_t, inst, o, mask)
        dl = self._apply(self.inv_rows, None, inst, d, mask)
        scale = dr.norm(dl)
        return ol, dl / scale, scale

    def intersect(self, o, d, t, prim, active):
        return self._loop(o, d, t, prim, jit.Bool(active) | dr.zeros(jit.Bool, dr.width(t)))

    @backend.syntax
    def _loop(self, o, d, t, prim, alive):
        from whitted.tracer.bvh import COUNT_BITS, LEAF_FLAG, inner_step, inverse_direction

        n = dr.width(t)
        inv = inverse_direction(d)
        node = dr.full(jit.UInt32, self._root, n)
        sp = dr.zeros(jit.UInt32, n)
        stack = dr.alloc_local(jit.UInt32, self._stack, jit.UInt32(0))
        nodes = self.nodes
        base, m = self.base, self.child.count

        while alive:
            while alive & ((node & LEAF_FLAG) == 0):
                node, sp, alive = inner_step(nodes, node, sp, stack, alive, [o], [inv], [t])

            # The leaf's instances: the ray in each one's object space, the group asked.
            i = (node & (LEAF_FLAG - 1)) >> COUNT_BITS
            end = i + (node & ((1 << COUNT_BITS) - 1))
            while alive & (i < end):
                act = alive & (i < end)
                inst = dr.gather(jit.UInt32, self.order, i, act)
                ol, dl, scale = self._to_object(inst, o, d, act)
                hit = self.child.closest_hit(ol, dl, t * scale, act)
                found = act & hit.valid
                t = dr.select(found, hit.t / scale, t)
                prim = dr.select(found, inst * m + hit.prim + base, prim)
                i += 1

            pop = alive & (sp > 0)
            sp = dr.select(pop, sp - 1, sp)
            node = dr.select(pop, stack.read(sp, pop), node)
            alive &= pop
        return t, prim

    def surface(self, k, o, d, t, mask):
        m = self.child.count
        inst = k // m
        ol, dl, scale = self._to_object(inst, o, d, mask)
        s = self.child.surface(Hit(t * scale, dr.select(mask, k - inst * m, INVALID)), ol, dl)
        p = self._apply(self.m_rows, self.m_t, inst, s.p, mask)
        n = dr.normalize(self._apply(self.normal_rows, None, inst, s.n, mask))
        ns = dr.normalize(self._apply(self.normal_rows, None, inst, s.ns, mask))
        return p, n, ns, s.uv


def instance_normal_matrix(m: np.ndarray) -> np.ndarray:
    """The 3x3 matrix that takes an instance's normals to world space: (M^-1)^T.

    Lecture 2, "Instancing" / "Intersecting transformed objects": points go by
    M, but a normal must stay perpendicular to the transformed tangents t,
    (A n) . (M t) = 0 for all t with n . t = 0, which holds for A = (M^-1)^T;
    M itself only works for rotations and uniform scales. ``m``: a 4x4
    to_world matrix or a stack of them (..., 4, 4).
    """
    m3 = np.asarray(m, dtype=np.float64)[..., :3, :3]
    if faults.on("instance-normal-by-matrix"):
        return m3.copy()
    return np.swapaxes(np.linalg.inv(m3), -1, -2)


# --------------------------------------------------------------------------- geometry


class Geometry:
    """All shapes of a scene (or of one group), with intersection and hit records."""

    def __init__(self, scene, shapes=None, material_names=None):
        shapes = list(scene.shapes if shapes is None else shapes)
        names = list(scene.materials) if material_names is None else material_names

        def of(kind):
            return [s for s in shapes if type(s) is kind]

        self.blocks = []
        mids, rads = [], []  # per block: material ids and radiances of its primitives

        def mat_id(shape) -> int:
            return len(names) if shape.material is None else names.index(shape.material)

        def add(block, members):
            block.base = sum(b.count for b in self.blocks)
            self.blocks.append(block)
            mids.append(np.asarray([mat_id(m) for m in members], dtype=np.uint32))
            rads.append(np.asarray([m.emitter.radiance if m.emitter is not None else (0, 0, 0)
                                    for m in members], dtype=np.float32).reshape(-1, 3))

        for kind, make in ((Sphere, _SphereBlock),
                           (Rectangle, lambda s: _PlanarBlock(s, False)),
                           (Disk, lambda s: _PlanarBlock(s, True)),
                           (Triangle, _TriangleBlock), (Polygon, _PolygonBlock),
                           (Cylinder, lambda s: _QuadricBlock(s, "cyl")),
                           (Paraboloid, lambda s: _QuadricBlock(s, "par"))):
            members = of(kind)
            if members:
                add(make(members), members)
        # one material and one emitter for all its triangles (cubes too)
        for mesh in [s for s in shapes if isinstance(s, Mesh)]:
            block = _MeshBlock(mesh)
            block.base = sum(b.count for b in self.blocks)
            self.blocks.append(block)
            mids.append(np.full(block.count, mat_id(mesh), dtype=np.uint32))
            radiance = mesh.emitter.radiance if mesh.emitter is not None else (0, 0, 0)
            rads.append(np.tile(np.asarray(radiance, dtype=np.float32), (block.count, 1)))
        # Instances: one geometry per group (its own materials; groups do not emit), the
        # instances of a much-used group in one hierarchy, the others one by one.
        by_group: dict[str, list[Instance]] = {}
        for inst in of(Instance):
            by_group.setdefault(inst.group, []).append(inst)
        for gname, insts in by_group.items():
            members = scene.groups[gname]
            child = Geometry(scene, members, names)
            child_mid = child.material_id.numpy()[:child.count]
            if len(insts) >= INSTANCE_SET_MIN:
                boxes = [shape_bounds(s) for s in members]
                bounds = (np.min([b[0] for b in boxes], axis=0),
                          np.max([b[1] for b in boxes], axis=0))
                group_blocks = [_InstanceSetBlock(insts, child, bounds)]
            else:
                group_blocks = [_InstanceBlock(inst, child) for inst in insts]
            for block in group_blocks:
                block.base = sum(b.count for b in self.blocks)
                self.blocks.append(block)
                mids.append(np.tile(child_mid, block.count // max(child.count, 1)))
                rads.append(np.zeros((block.count, 3), dtype=np.float32))
        self.count = sum(b.count for b in self.blocks)
        mid = np.concatenate(mids) if mids else np.zeros(1, dtype=np.uint32)
        rad = np.concatenate(rads) if rads else np.zeros((1, 3), dtype=np.float32)
        self.material_id = _u(mid if len(mid) else np.zeros(1, dtype=np.uint32))
        self.radiance = _v3(rad if len(rad) else np.zeros((1, 3), dtype=np.float32))
        #: whether a triangle mesh is among the blocks (top level only)
        self.has_mesh = any(isinstance(b, _MeshBlock) for b in self.blocks)
        #: the shapes that emit light (area lights), top level only
        self.emitters = [s for s in shapes if getattr(s, "emitter", None) is not None]

    def closest_hit(self, o, d, tmax, active=True) -> Hit:
        """Nearest intersection of each ray in (0, tmax); inactive rays report a miss.

        ``d`` must be a unit vector. Loops run per SIMD packet while any lane is
        active, so a packet of rays that need no test costs almost nothing.
        """
        return self.closest_hit_group([(o, d, tmax, active)])[0]

    def occluded(self, o, d, tmax, active=True):
        """True where something blocks the segment from o along d shorter than tmax.

        Each block answers for itself (:meth:`_Block.occluded`): a mesh stops at the
        first triangle its BVH finds in the segment rather than the nearest, and a
        later block tests only the rays no earlier one blocked. The answer is the
        closest hit's (a hit in (0, tmax) exists or not); on the 144,000-triangle
        knot (``benchmarks/bench_mesh.py``) the shadow rays' any-hit took the render
        from 0.346 to 0.318 s.
        """
        return self.occluded_group([(o, d, tmax, active)])[0]

    def closest_hit_group(self, rays: list) -> list:
        """:meth:`closest_hit` of K rays a lane: ``rays`` a list of K (o, d, tmax, active)
        of one width, the answer a list of K :class:`Hit`. A mesh walks its BVH with
        the K rays of a lane together (:meth:`tracer.bvh.BVH.closest_hit_group`), so the
        rays of a lane should be alike (samples of one pixel); the hits are those of
        :meth:`closest_hit` for each ray."""
        n = max(dr.width(x) for ray in rays for x in ray)
        ts = tuple(jit.Float(tmax) + dr.zeros(jit.Float, n) for _, _, tmax, _ in rays)
        prims = tuple(dr.full(jit.UInt32, INVALID, n) for _ in rays)
        every = all(a is True for *_, a in rays)
        actives = [jit.Bool(True) if every else jit.Bool(a) | dr.zeros(jit.Bool, n)
                   for *_, a in rays]
        sub = [(o, d, a) for (o, d, _, _), a in zip(rays, actives, strict=True)]

        def step(ts, prims):
            for block in self.blocks:
                ts, prims = block.intersect_group(sub, ts, prims)
            return tuple(ts), tuple(prims)

        if every:
            ts, prims = step(ts, prims)
        else:
            ts, prims = self._once(any_mask(actives), step, (ts, prims))
        return [Hit(t, prim) for t, prim in zip(ts, prims, strict=True)]

    def occluded_group(self, rays: list) -> list:
        """:meth:`occluded` of K rays a lane (see :meth:`closest_hit_group`): a list of K
        jit.Bool."""
        if not any(block.any_hit for block in self.blocks):
            # Without a block that can stop early, the closest hit is as fast (slightly
            # faster on three_lights, 0.042-0.044 s against 0.046-0.047 s at 320x240).
            return [hit.valid for hit in self.closest_hit_group(rays)]
        n = max(dr.width(x) for ray in rays for x in ray)
        every = all(a is True for *_, a in rays)
        rays = [(o, d, jit.Float(tmax) + dr.zeros(jit.Float, n),
                 dr.full(jit.Bool, True, n) if every else jit.Bool(a) | dr.zeros(jit.Bool, n))
                for o, d, tmax, a in rays]

        def step(*blocked):
            blocked = list(blocked)
            for block in self.blocks:
                more = block.occluded_group([(o, d, tmax, a & ~b) for (o, d, tmax, a), b
                                             in zip(rays, blocked, strict=True)])
                blocked = [b | m for b, m in zip(blocked, more, strict=True)]
            return tuple(blocked)

        none = tuple(dr.zeros(jit.Bool, n) for _ in rays)
        if every:
            return list(step(*none))
        # Inactive lanes keep False (the loop's condition).
        return list(self._once(any_mask([a for *_, a in rays]), step, none))

    @staticmethod
    @backend.syntax
    def _once(active, step, state: tuple) -> tuple:
        """``step(*state)`` in a loop that runs at most once: the SIMD packets without an
        active lane skip it, and lanes outside ``active`` keep ``state``."""
        todo = jit.Bool(active)
        while todo:
            state = step(*state)
            todo = jit.Bool(False)
        return state

    def surface(self, hit: Hit, o, d) -> Surface:
        """The hit record: position, geometric and shading normals, uv of each valid hit."""
        valid = hit.valid
        p = dr.fma(d, hit.t, o)
        n = dr.zeros(jit.Array3f, dr.width(p))
        ns = dr.zeros(jit.Array3f, dr.width(p))
        uv = dr.zeros(jit.Array2f, dr.width(p))
        for block in self.blocks:
            k = hit.prim - block.base
            mask = valid & (hit.prim >= block.base) & (k < block.count)
            bp, bn, bns, buv = block.surface(k, o, d, hit.t, mask)
            p = dr.select(mask, bp, p)
            n = dr.select(mask, bn, n)
            ns = dr.select(mask, bns, ns)
            uv = dr.select(mask, buv, uv)
        return Surface(p, n, ns, uv)


#: How far new rays start off their surface, in float32 ulps (2^-24) of 1 + max |p_i|:
#: Mitsuba 3's ``math::RayEpsilon`` (1500 x 2^-24), see :func:`spawn_offset`.
RAY_EPSILON_ULPS = 1500


def spawn_offset(p):
    """Distance to move a ray origin off its surface, relative to the magnitude of p.

    Float32 positions carry a relative error of about 2^-24; an offset of
    2^-24 x :data:`RAY_EPSILON_ULPS` x (1 + max |p_i|) clears it with a wide
    margin yet stays far below any feature size of a scene in sensible units.
    The factor is Mitsuba 3's (``math::RayEpsilon`` = 1500 x 2^-24, applied the
    same way by its ``Interaction::offset_p``), so that secondary rays start at
    the same points on both sides of a comparison: behind glass, whose
    refraction magnifies a ray's lateral shift, another offset (1024 x 2^-24
    was tried) moves 0.7 % of a glass scene's pixels by more than 1e-3.

    The offset is part of the ray tree, not only a guard: where a tree passes
    a silhouette or a shadow edge within the offset's reach (magnified by the
    bounces since), trees started on the surface, as Heckbert's minray starts
    them in double precision, part from ours (the harness's comparison with
    minray names those values).
    """
    return (1 + dr.max(dr.abs(p))) * (RAY_EPSILON_ULPS / (1 << 24))
