"""``type = "mesh"``: a triangle mesh from an OBJ or PLY file, placed by ``to_world``.

Its triangles are found through a bounding-volume hierarchy (:mod:`tracer.bvh`)
and intersected by the watertight test of :mod:`tracer.shapes.triangle`; a
smooth mesh's shading normal interpolates its vertex normals with the hit's
barycentrics (lecture 2, "Interpolating normals"), and its texture coordinates
are the file's, else Mitsuba's (beta, gamma).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from whitted.tracer import faults
from whitted.tracer import transform as tf
from whitted.tracer.backend import deferred, jit, upload, upload_rows
from whitted.tracer.settings import Matrix, Table, as_tuple, check_extent
from whitted.tracer.shapes import base
from whitted.tracer.shapes import triangle as tri_f

dr = deferred("drjit")
lights = deferred("whitted.tracer.lights")


@dataclass(frozen=True, eq=False)
class Mesh(base.ShapeModel):
    """A triangle mesh from an OBJ or PLY file, in world space after ``to_world``."""
    shape_type: ClassVar[str] = "mesh"
    file: str
    smooth: bool
    vertices: np.ndarray       # (V, 3) world space
    faces: np.ndarray          # (F, 3)
    normals: np.ndarray | None  # (V, 3) world space, unit; None: face normals
    uvs: np.ndarray | None     # (V, 2)
    to_world: Matrix
    material: str | None
    emitter: Any = None   # an AreaEmitter (tracer.emitters.area) or None
    placement: base.Placement | None = base.placement_field()
    # A hash of what vertices and faces are made from (the parsed file's key and
    # to_world), or None: the key of their cached normals and tree (_placed_key).
    key: str | None = None

    def primitive_count(self) -> int:
        return len(self.faces)


MODEL = Mesh


def parse(t: Table, ctx: base.Context) -> Mesh:
    from whitted.tracer.meshio import MeshError, load_mesh, row_lengths, vertex_normals

    m = ctx.to_world()
    name = t.string("file")
    path = Path(name) if Path(name).is_absolute() else ctx.base / name
    if not path.exists():  # a FIFO, device or folder: load_mesh says what it is
        t.fail("file", f"no such mesh file: {path}")
    smooth = t.boolean("smooth", True)
    try:
        data = load_mesh(path)
    except MeshError as e:
        t.fail("file", str(e))
    verts = tf.apply_point(m, data.vertices)
    check_extent(t, "file", verts, "vertices")
    key = _placed_key(data.key, m)
    normals = None
    if smooth:
        if data.normals is not None:  # normals transform by the inverse transpose
            normals = (data.normals @ m[:3, :3].T if faults.on("normals-by-matrix")
                       else tf.apply_normal(m, data.normals))
        else:  # as Mitsuba does: from the faces, after to_world
            normals = vertex_normals(verts, data.faces, key)
        normals = normals / np.maximum(row_lengths(normals), 1e-30)[:, None]
    return Mesh(str(path), smooth, verts, np.asarray(data.faces), normals, data.uvs,
                as_tuple(m), ctx.material, ctx.emitter, ctx.placement(), key)


def _placed_key(file_key: str | None, m: np.ndarray) -> str | None:
    """A hash of what a mesh's world-space vertices and faces are made from: the parsed
    file (its :attr:`tracer.meshio.MeshData.key`, None for a file not kept on disk, and
    then None), ``to_world`` and the code that applies it."""
    if file_key is None:
        return None
    from whitted.tracer.cache import content_key, source_digest

    return content_key("placed", file_key, np.ascontiguousarray(m, dtype=np.float64),
                       source_digest(tf.__file__))


def bounds(shape) -> tuple[np.ndarray, np.ndarray]:
    return base.box_of(shape.vertices)


def pack(members: list, packing) -> list:
    """One block a mesh, one material and one emitter for all its triangles (cubes too)."""
    out = []
    for mesh in members:
        block = Block(mesh)
        out.append((block, *packing.repeated(mesh, block.count)))
    return out


def _tree_key(v: np.ndarray, f: np.ndarray) -> str:
    """The key of the tree of a mesh without :attr:`Mesh.key` (:func:`_tree`):
    a hash of its vertices and faces, which give its corners, and half their bytes."""
    from whitted.tracer.cache import content_key

    return content_key(v, f)


def _tree(v: np.ndarray, f: np.ndarray, key: str | None, p, faces):
    """:func:`tracer.bvh.shared_mesh_bvh` of the mesh's triangles (the records gathered
    from its uploaded vertices ``p`` and ``faces``), under ``key``, else under
    :func:`_tree_key`."""
    from whitted.tracer.bvh import shared_mesh_bvh

    return shared_mesh_bvh(v, f, key if key is not None else _tree_key(v, f), p, faces)


def face_normal(p0, p1, p2):
    """The unit normal of the triangles (p0, p1, p2) (jit.Array3f), their winding's:
    normalize((p1 - p0) x (p2 - p0)), as Mitsuba's mesh computes its face normal
    (``si.n = dr::normalize(dr::cross(dp0, dp1))``, src/render/mesh.cpp), in float32 from
    the float32 corners; 0 for a degenerate triangle.

    The edges are first scaled by the power of two that brings their largest component
    to [1, 2): the same unit vector bit for bit, since a power of two scales every
    number exactly, where the cross product of a tiny triangle's edges (below about
    1e-19 in size) would otherwise underflow float32. Computed in the kernel where a hit
    is shaded; the normals had been computed on the host in float64 for every triangle
    and uploaded, 40 ms of the 1,000,000-triangle knot's every start (issue 33)."""
    e1, e2 = p1 - p0, p2 - p0
    m = dr.maximum(dr.max(dr.abs(e1)), dr.max(dr.abs(e2)))
    # 2^-e for m = 1.x * 2^e: biased exponent 254 - E, from m's biased exponent E; for
    # E = 0 (m subnormal, or zero), 2^127
    bits = dr.reinterpret_array(jit.UInt32, m) & 0x7F800000
    scale = dr.reinterpret_array(jit.Float, jit.UInt32(0x7F000000) - bits)
    c = dr.cross(e1 * scale, e2 * scale)
    return dr.select(dr.squared_norm(c) > 0, dr.normalize(c), 0)


class Block(base.Block):
    """A triangle mesh behind a bounding-volume hierarchy (tracer/bvh.py)."""

    def __init__(self, mesh: Mesh):
        v, f = np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces)
        self.count = len(f)
        self.faces = base.uints(f.reshape(-1))
        self.p = base.v3(v)
        self.bvh = _tree(v, f, mesh.key, self.p, self.faces)
        self.vn = None if mesh.normals is None else base.v3(mesh.normals)
        self.vt = None
        if mesh.uvs is not None:
            self.vt = upload_rows(jit.Array2f, mesh.uvs)

    def intersect(self, o, d, t, prim, active):
        (t,), (prim,) = self.intersect_group([(o, d, active)], [t], [prim])
        return t, prim

    any_hit = True
    has_mesh = True

    def occluded(self, o, d, tmax, active):
        return self.bvh.occluded(o, d, tmax, active)

    def intersect_group(self, rays, ts, prims):
        found = self.bvh.closest_hit_group([(o, d, t, a) for (o, d, a), t
                                            in zip(rays, ts, strict=True)])
        out = [self._update(ti, tri != base.INVALID, tri, t, prim)
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
        n = face_normal(p0, p1, p2)
        ns = n
        if self.vn is not None:  # barycentric interpolation of the vertex normals
            ns = tri_f.interpolate(
                beta, gamma, dr.gather(jit.Array3f, self.vn, i0, mask),
                dr.gather(jit.Array3f, self.vn, i1, mask),
                dr.gather(jit.Array3f, self.vn, i2, mask))
            ns = faults.pick("normal-not-renormalized", lambda ns=ns: ns, dr.normalize(ns))
        if self.vt is not None:
            uv = tri_f.interpolate(beta, gamma, dr.gather(jit.Array2f, self.vt, i0, mask),
                                   dr.gather(jit.Array2f, self.vt, i1, mask),
                                   dr.gather(jit.Array2f, self.vt, i2, mask))
        else:
            uv = jit.Array2f(beta, gamma)
        # The point from the barycentrics, on the triangle as Mitsuba places it
        # (fmadd(p1, b1, fmadd(p2, b2, p0 b0)), src/render/mesh.cpp), rather than o + t d,
        # which may lie a rounding past the triangle's edge (behind a neighbour at a seam).
        alpha = 1.0 - beta - gamma
        p = dr.fma(p1, beta, dr.fma(p2, gamma, p0 * alpha))
        return p, n, ns, uv


class Sampler(base.FlatSampler):
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
        self.p0 = upload_rows(jit.Array3f, p0)
        self.e1 = upload_rows(jit.Array3f, p1 - p0)
        self.e2 = upload_rows(jit.Array3f, p2 - p0)
        self.normals = upload_rows(jit.Array3f, cross / twice[:, None])

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
