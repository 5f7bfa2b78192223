"""The scene's shapes as Dr.Jit tables, closest-hit queries and the hit record.

Shapes are grouped by kind into structure-of-arrays tables; every primitive
has a global id: spheres first, then rectangles, then triangles. A query
walks each table in a symbolic loop (one loop iteration per primitive, all
rays of the wavefront at once) and keeps the nearest hit, which is what
lecture 1's "Intersection routine" does for one ray at a time. Tables live in
Dr.Jit arrays, not kernel constants, so the compiled kernels depend on the
scene's structure (which lights, which shape kinds) but not on its numbers.
"""

from __future__ import annotations

from dataclasses import dataclass

import drjit as dr
import numpy as np

from tracer.backend import jit
from tracer.scene import Rectangle, Scene, Sphere, Triangle
from tracer.shapes import rectangle as rect_f
from tracer.shapes import sphere as sphere_f
from tracer.shapes import triangle as tri_f

INVALID = 0xFFFFFFFF

#: Tables up to this size are unrolled into the kernel with constant numbers.
UNROLL = 16

# Material kinds, as stored in the material table.
DIFFUSE, MIRROR, DIELECTRIC, BLACK = 0, 1, 2, 3


def _v3(rows) -> object:
    a = np.asarray(rows, dtype=np.float32).reshape(-1, 3)
    return jit.Array3f(a[:, 0], a[:, 1], a[:, 2])


def _f(values) -> object:
    return jit.Float(np.asarray(values, dtype=np.float32))


def _u(values) -> object:
    return jit.UInt32(np.asarray(values, dtype=np.uint32))


@dataclass
class Hit:
    """The hit record: ray parameter and global primitive id (INVALID for a miss)."""
    t: object
    prim: object

    @property
    def valid(self):
        return self.prim != INVALID


@dataclass
class Surface:
    """Where a ray hit: position, unit geometric normal (outward), texture coordinates."""
    p: object
    n: object
    uv: object


class Geometry:
    """Intersection tables built from a validated scene."""

    def __init__(self, scene: Scene):
        spheres = [s for s in scene.shapes if isinstance(s, Sphere)]
        rects = [s for s in scene.shapes if isinstance(s, Rectangle)]
        tris = [s for s in scene.shapes if isinstance(s, Triangle)]
        #: shapes in global-id order
        self.shapes = spheres + rects + tris
        self.n_spheres, self.n_rects, self.n_tris = len(spheres), len(rects), len(tris)

        if spheres:
            self.sph_c = _v3([s.center for s in spheres])
            self.sph_r = _f([s.radius for s in spheres])
        if rects:
            frames = [r.corners() for r in rects]
            duals = [rect_f.frame(c, u, v) for c, u, v in frames]
            self.rect_c = _v3([c for c, _, _ in frames])
            self.rect_u = _v3([u for _, u, _ in frames])
            self.rect_v = _v3([v for _, _, v in frames])
            # Normal as Mitsuba orients it (the inverse transpose of to_world applied to +z).
            self.rect_n = _v3([r.normal() for r in rects])
            self.rect_ud = _v3([ud for _, ud, _ in duals])
            self.rect_vd = _v3([vd for _, _, vd in duals])
        if tris:
            v = np.asarray([t.vertices for t in tris], dtype=np.float64)
            self.tri_p0 = _v3(v[:, 0])
            self.tri_e1 = _v3(v[:, 1] - v[:, 0])
            self.tri_e2 = _v3(v[:, 2] - v[:, 0])
            n = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
            self.tri_n = _v3(n / np.linalg.norm(n, axis=1, keepdims=True))

        self._const = _constants(self)

        # Per-primitive material index (into Materials) and emitted radiance.
        names = list(scene.materials)
        self.material_id = _u([names.index(s.material) if s.material is not None
                               else len(names) for s in self.shapes] or [0])
        self.emitters = [i for i, s in enumerate(self.shapes) if s.emitter is not None]
        self.radiance = _v3([s.emitter.radiance if s.emitter is not None else (0, 0, 0)
                             for s in self.shapes] or [(0, 0, 0)])
        self.count = len(self.shapes)

    # ---------------------------------------------------------------- queries

    def closest_hit(self, o, d, tmax, active=True) -> Hit:
        """Nearest intersection of each ray in (0, tmax); inactive rays report a miss.

        ``d`` must be a unit vector. Tables of up to :data:`UNROLL` primitives are
        written into the kernel one primitive after another, with their numbers
        as constants; larger tables are walked by a symbolic loop that gathers
        each primitive. Loops run per SIMD packet while any lane is active, so a
        packet of rays that need no test (say, shadow rays from points facing
        away from the light) costs almost nothing.
        """
        n = dr.width(o)
        t = jit.Float(tmax) + dr.zeros(jit.Float, n)
        prim = dr.full(jit.UInt32, INVALID, n)
        if active is True:
            return Hit(*self._all(o, d, t, prim, True))
        return Hit(*self._masked(o, d, t, prim, jit.Bool(active) | dr.zeros(jit.Bool, n)))

    def occluded(self, o, d, tmax, active=True):
        """True where something blocks the segment from o along d shorter than tmax."""
        return self.closest_hit(o, d, tmax, active).valid

    @dr.syntax
    def _masked(self, o, d, t, prim, active):
        # A loop that runs at most once: the packets without an active lane skip it.
        todo = jit.Bool(active)
        while todo:
            t, prim = self._all(o, d, t, prim, active)
            todo = jit.Bool(False)
        return t, prim

    def _all(self, o, d, t, prim, active):
        for kind in ("sph", "rect", "tri"):
            count = getattr(self, f"n_{kind}s" if kind != "sph" else "n_spheres")
            if count == 0:
                continue
            if count <= UNROLL:
                t, prim = self._unrolled(kind, o, d, t, prim)
            else:
                t, prim = self._looped(kind, o, d, t, prim, active)
        return t, prim

    def _test(self, kind, o, d, t, i):
        """(t, hit) of primitive ``i`` (a Python int or a UInt32 array) of one table."""
        if kind == "sph":
            return sphere_f.intersect(o, d, self._get("sph_c", i), self._get("sph_r", i), t)
        if kind == "rect":
            ti, hit, _, _ = rect_f.intersect(o, d, self._get("rect_c", i),
                                             self._get("rect_n", i), self._get("rect_ud", i),
                                             self._get("rect_vd", i), t)
            return ti, hit
        ti, hit, _, _ = tri_f.intersect(o, d, self._get("tri_p0", i), self._get("tri_e1", i),
                                        self._get("tri_e2", i), t)
        return ti, hit

    def _get(self, name, i):
        if isinstance(i, int):
            return self._const[name][i]
        src = getattr(self, name)
        return dr.gather(type(src), src, i)

    def _base(self, kind):
        return {"sph": 0, "rect": self.n_spheres, "tri": self.n_spheres + self.n_rects}[kind]

    def _unrolled(self, kind, o, d, t, prim):
        base = self._base(kind)
        for i in range(getattr(self, "n_spheres" if kind == "sph" else f"n_{kind}s")):
            ti, hit = self._test(kind, o, d, t, i)
            t = dr.select(hit, ti, t)
            prim = dr.select(hit, base + i, prim)
        return t, prim

    @dr.syntax
    def _looped(self, kind, o, d, t, prim, active):
        i = jit.UInt32(0)
        count = dr.opaque(jit.UInt32, getattr(self, "n_spheres" if kind == "sph"
                                              else f"n_{kind}s"))
        base = self._base(kind)
        while active & (i < count):
            ti, hit = self._test(kind, o, d, t, i)
            t = dr.select(hit, ti, t)
            prim = dr.select(hit, i + base, prim)
            i += 1
        return t, prim

    # ---------------------------------------------------------------- hit record

    def surface(self, hit: Hit, o, d, need_uv: bool = False) -> Surface:
        """Position, outward unit normal and (with ``need_uv``) uv of each valid hit."""
        valid = hit.valid
        p = dr.fma(d, hit.t, o)
        n = dr.zeros(jit.Array3f, dr.width(p))
        uv = dr.zeros(jit.Array2f, dr.width(p))
        prim = hit.prim
        if self.n_spheres:
            is_s = valid & (prim < self.n_spheres)
            c = dr.gather(jit.Array3f, self.sph_c, prim, is_s)
            r = dr.gather(jit.Float, self.sph_r, prim, is_s)
            ns = dr.normalize(p - c)
            # Re-project onto the sphere: the hit point's error stays relative to r.
            p = dr.select(is_s, dr.fma(ns, r, c), p)
            n = dr.select(is_s, ns, n)
            # Mitsuba's sphere uv: (phi / 2 pi, theta / pi) in the sphere's frame.
            if need_uv:
                phi = dr.atan2(ns.y, ns.x)
                phi = dr.select(phi < 0, phi + 2 * dr.pi, phi)
                uv = dr.select(is_s, jit.Array2f(phi * (0.5 / dr.pi),
                                                  dr.acos(dr.clip(ns.z, -1, 1)) / dr.pi), uv)
        if self.n_rects:
            j = prim - self.n_spheres
            is_r = valid & (prim >= self.n_spheres) & (j < self.n_rects)
            n = dr.select(is_r, dr.gather(jit.Array3f, self.rect_n, j, is_r), n)
            if need_uv:
                rel = p - dr.gather(jit.Array3f, self.rect_c, j, is_r)
                a = dr.dot(rel, dr.gather(jit.Array3f, self.rect_ud, j, is_r))
                b = dr.dot(rel, dr.gather(jit.Array3f, self.rect_vd, j, is_r))
                uv = dr.select(is_r, jit.Array2f(*rect_f.uv(a, b)), uv)
        if self.n_tris:
            k = prim - (self.n_spheres + self.n_rects)
            is_t = valid & (prim >= self.n_spheres + self.n_rects)
            n = dr.select(is_t, dr.gather(jit.Array3f, self.tri_n, k, is_t), n)
            if need_uv:
                _, _, beta, gamma = tri_f.intersect(
                    o, d, dr.gather(jit.Array3f, self.tri_p0, k, is_t),
                    dr.gather(jit.Array3f, self.tri_e1, k, is_t),
                    dr.gather(jit.Array3f, self.tri_e2, k, is_t), dr.inf)
                # Mitsuba's mesh without uvs: the barycentrics (beta, gamma).
                uv = dr.select(is_t, jit.Array2f(beta, gamma), uv)
        return Surface(p, n, uv)


def _constants(geo) -> dict[str, list]:
    """The tables as lists of Python-side constants, for unrolled intersection code."""
    out = {}
    for name in ("sph_c", "sph_r", "rect_c", "rect_n", "rect_ud", "rect_vd",
                 "tri_p0", "tri_e1", "tri_e2"):
        if not hasattr(geo, name):
            continue
        a = getattr(geo, name).numpy()
        if a.ndim == 1:
            out[name] = [float(x) for x in a]
        else:
            out[name] = [jit.Array3f(*(float(x) for x in col)) for col in a.T]
    return out


def spawn_offset(p):
    """Distance to move a ray origin off its surface, relative to the magnitude of p.

    Float32 positions carry a relative error of about 2^-24; an offset of
    2^-24 x 1024 x (1 + max |p_i|) clears it with a wide margin yet stays far
    below any feature size of a scene in sensible units.
    """
    return (1 + dr.max(dr.abs(p))) * (1024.0 / (1 << 24))
