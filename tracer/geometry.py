"""The scene's shapes as Dr.Jit tables, closest-hit queries and the hit record.

Shapes are gathered into blocks of one kind each (spheres, rectangles,
disks, single triangles, polygons, cylinders, paraboloids, one block per
mesh, one per instance). Each kind's module (``tracer/shapes/<kind>.py``)
packs its own blocks and intersects them; :func:`pack` is the one loop over
the kinds, and instancing, which recurses into a group's geometry, is here.
Every primitive has a global id: each block owns a contiguous range. A
query asks every block for its nearest hit and keeps the nearest of all,
which is what lecture 1's "Intersection routine" does for one ray at a
time, here for a whole wavefront at once.

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
and the kernel's size does not grow with n. The K rays a lane of
:meth:`Geometry.closest_hit_group` (a pixel's samples, where a mesh is
instanced) walk that hierarchy together and ask each instance they reach with
all K, so that the group's mesh walks its tree once for them.

The hit record (:class:`Surface`) holds the position, the geometric normal
(outward, unit), the shading normal (the interpolated vertex normal of a
smooth mesh, else the geometric one) and Mitsuba's texture coordinates for
each kind of shape.
"""

from __future__ import annotations

from dataclasses import dataclass

import drjit as dr
import numpy as np

from whitted.tracer import faults, shapes
from whitted.tracer.backend import any_mask, jit, upload
from whitted.tracer.shapes.base import INVALID as INVALID
from whitted.tracer.shapes.base import UNROLL as UNROLL
from whitted.tracer.shapes.base import Block as _Block
from whitted.tracer.shapes.base import affine as _affine
from whitted.tracer.shapes.base import pack as base_pack
from whitted.tracer.shapes.base import uints as _u
from whitted.tracer.shapes.base import v3 as _v3
from whitted.tracer.shapes.instance import Instance
from whitted.tracer.shapes.sphere import Block as _SphereBlock  # noqa: F401 (tests use it)

#: A group instanced this many times or more is searched through a hierarchy of its
#: instances' boxes (:class:`_InstanceSetBlock`); fewer are unrolled one by one. From
#: two on: one traversal loop instead of one per instance (``bench_speed.py process``
#: prints the render's time of four placed tori; benchmarks/HISTORY.md, issue 33).
INSTANCE_SET_MIN = 2


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



# --------------------------------------------------------------------------- instances

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
        (t,), (prim,) = self.intersect_group([(o, d, active)], [t], [prim])
        return t, prim

    def intersect_group(self, rays, ts, prims):
        """The K rays of a lane in object space, asked of the group together
        (:meth:`Geometry.closest_hit_group`: a mesh walks its tree once for them)."""
        asked, scales = [], []
        for (o, d, a), t in zip(rays, ts, strict=True):
            ol, dl, scale = self._to_object(o, d)
            asked.append((ol, dl, t * scale, a))
            scales.append(scale)
        hits = self.child.closest_hit_group(asked)
        out = [self._update(hit.t / scale, hit.valid, hit.prim, t, prim)
               for hit, scale, t, prim in zip(hits, scales, ts, prims, strict=True)]
        return [t for t, _ in out], [prim for _, prim in out]

    @property
    def any_hit(self) -> bool:
        """Whether :meth:`occluded` stops early: where the group's geometry does (a mesh)."""
        return any(b.any_hit for b in self.child.blocks)

    @property
    def has_mesh(self) -> bool:
        return self.child.has_mesh

    def occluded(self, o, d, tmax, active):
        """The group's own answer in object space (:meth:`Geometry.occluded`)."""
        return self.occluded_group([(o, d, tmax, active)])[0]

    def occluded_group(self, rays):
        asked = []
        for o, d, tmax, a in rays:
            ol, dl, scale = self._to_object(o, d)
            asked.append((ol, dl, tmax * scale, a))
        return self.child.occluded_group(asked)

    def surface(self, k, o, d, t, mask):
        ol, dl, scale = self._to_object(o, d)
        s = self.child.surface(Hit(t * scale, dr.select(mask, k, INVALID)), ol, dl)
        p = _affine(self.m, s.p)
        n = dr.normalize(_affine(self.normal_m, s.n, point=False))
        ns = dr.normalize(_affine(self.normal_m, s.ns, point=False))
        return p, n, ns, s.uv

def shape_bounds(shape) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi): an axis-aligned box around a shape, in the space its coordinates are in."""
    fn = getattr(shapes.module_of(shape), "bounds", None)
    if fn is None:
        raise TypeError(f"no bounds for {type(shape).__name__}")
    return fn(shape)


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
        (t,), (prim,) = self.intersect_group([(o, d, active)], [t], [prim])
        return t, prim

    def intersect_group(self, rays, ts, prims):
        """:meth:`intersect` of K rays a lane: the hierarchy walked once for the K rays
        (:func:`tracer.bvh.inner_step`), each instance reached asking its group with all
        of them (:meth:`Geometry.closest_hit_group`), as a mesh's tree is walked
        (:meth:`tracer.bvh.BVH.closest_hit_group`)."""
        n = max(dr.width(x) for x in (*ts, *prims))
        acts = [jit.Bool(a) | dr.zeros(jit.Bool, n) for _, _, a in rays]
        ts = [jit.Float(t) + dr.zeros(jit.Float, n) for t in ts]
        return self._loop([o for o, _, _ in rays], [d for _, d, _ in rays], ts, list(prims),
                          acts, shadow=False)

    #: :meth:`occluded` stops at the first instance that blocks the ray
    any_hit = True

    @property
    def has_mesh(self) -> bool:
        return self.child.has_mesh

    def occluded(self, o, d, tmax, active):
        """Where an instance blocks the segment (0, tmax): the hierarchy walked farther
        child first (a shadow ray starts beside its own surface, which seldom blocks it,
        :func:`tracer.bvh.inner_step`), each instance asked with the group's own
        :meth:`Geometry.occluded_group` (a mesh's any-hit), the ray leaving at the first that
        blocks it. The answer is :meth:`intersect`'s (a hit in (0, tmax) exists or not);
        before, the nearest hit was searched (``bench_speed.py process``'s scenes instance
        their meshes)."""
        return self.occluded_group([(o, d, tmax, active)])[0]

    def occluded_group(self, rays):
        """:meth:`occluded` of K rays a lane, walked together; a ray leaves the packet
        when blocked, the packet when each of its rays is blocked or done."""
        n = max(dr.width(x) for ray in rays for x in ray)
        ts = [jit.Float(tmax) + dr.zeros(jit.Float, n) for _, _, tmax, _ in rays]
        acts = [jit.Bool(a) | dr.zeros(jit.Bool, n) for *_, a in rays]
        blocked, _ = self._loop([o for o, *_ in rays], [d for _, d, *_ in rays], ts, None,
                                acts, shadow=True)
        return blocked

    def _loop(self, os, ds, ts, prims, acts, shadow):
        """The walk of :meth:`intersect_group` (the nearest hits: ``(ts, prims)``), or with
        ``shadow`` of :meth:`occluded_group` (``ts`` the segments' ends: ``(blocked,
        None)``), K rays a lane, as :meth:`tracer.bvh.BVH._loop` walks a mesh's tree
        (``drjit.while_loop`` calls, as there). With K = 1 the lane's ``alive`` is the
        ray's state."""
        from whitted.tracer.bvh import COUNT_BITS, LEAF_FLAG, inner_step, inverse_direction

        K = len(os)
        n = dr.width(ts[0])
        invs = [inverse_direction(d) for d in ds]
        node = dr.full(jit.UInt32, self._root, n)
        sp = dr.zeros(jit.UInt32, n)
        stack = dr.alloc_local(jit.UInt32, self._stack, jit.UInt32(0))
        nodes = self.nodes
        blocked = [dr.zeros(jit.Bool, n) for _ in range(K)] if shadow else None
        alive = any_mask(acts)
        if K == 1:
            acts = None

        def walk(acts, alive, blocked, node, prims, sp, stack, ts):
            def at_inner(acts, alive, node, sp, stack, ts):
                return alive & ((node & LEAF_FLAG) == 0)

            def step(acts, alive, node, sp, stack, ts):
                node, sp, alive = inner_step(nodes, node, sp, stack, alive, os, invs, ts,
                                             shadow, acts)
                return acts, alive, node, sp, stack, ts

            acts, alive, node, sp, stack, ts = dr.while_loop(
                (acts, alive, node, sp, stack, ts), at_inner, step,
                labels=("acts", "alive", "node", "sp", "stack", "ts"))

            # The leaf's instances: the rays in each one's object space, the group asked.
            def in_leaf(acts, alive, blocked, end, i, prims, ts):
                return alive & (i < end)

            def visit(acts, alive, blocked, end, i, prims, ts):
                act = alive & (i < end)
                inst = dr.gather(jit.UInt32, self.order, i, act)
                ts, prims, blocked, acts, alive = self._visit(inst, act, os, ds, ts, prims,
                                                              blocked, acts, alive)
                return acts, alive, blocked, end, i + 1, prims, ts

            i = (node & (LEAF_FLAG - 1)) >> COUNT_BITS
            end = i + (node & ((1 << COUNT_BITS) - 1))
            acts, alive, blocked, end, i, prims, ts = dr.while_loop(
                (acts, alive, blocked, end, i, prims, ts), in_leaf, visit,
                labels=("acts", "alive", "blocked", "end", "i", "prims", "ts"))

            pop = alive & (sp > 0)
            sp = dr.select(pop, sp - 1, sp)
            node = dr.select(pop, stack.read(sp, pop), node)
            alive &= pop
            return acts, alive, blocked, node, prims, sp, stack, ts

        acts, alive, blocked, node, prims, sp, stack, ts = dr.while_loop(
            (acts, alive, blocked, node, prims, sp, stack, ts),
            lambda acts, alive, *_: alive, walk,
            labels=("acts", "alive", "blocked", "node", "prims", "sp", "stack", "ts"))
        return (blocked, None) if shadow else (ts, prims)

    def _visit(self, inst, act, os, ds, ts, prims, blocked, acts, alive):
        """Instance ``inst`` asked for the lanes in ``act``, with each of their K rays
        still taking part (``acts``, None for one ray a lane): (ts, prims) updated with
        its nearest hits, or, in :meth:`occluded_group` (``blocked`` not None), the rays
        it blocks marked and done."""
        K = len(os)
        rays, scales = [], []
        for k in range(K):
            ol, dl, scale = self._to_object(inst, os[k], ds[k], act)
            rays.append((ol, dl, ts[k] * scale, act if acts is None else act & acts[k]))
            scales.append(scale)
        if blocked is not None:
            more = self.child.occluded_group(rays)
            for k in range(K):
                hit = rays[k][3] & more[k]
                blocked[k] = blocked[k] | hit
                if acts is None:
                    alive = alive & ~hit
                else:
                    acts[k] = acts[k] & ~hit
            if acts is not None:
                alive = alive & any_mask(acts)
            return ts, prims, blocked, acts, alive
        hits = self.child.closest_hit_group(rays)
        for k in range(K):
            found = rays[k][3] & hits[k].valid
            ts[k] = dr.select(found, hits[k].t / scales[k], ts[k])
            prims[k] = dr.select(found, inst * self.child.count + hits[k].prim + self.base,
                                 prims[k])
        return ts, prims, blocked, acts, alive

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

# --------------------------------------------------------------------------- packing


#: The order in which the kinds' blocks take their primitive ids, as before shapes became
#: plugins, so that ties between kinds resolve as they did; kinds in one entry are packed
#: together in the scene's order (a cube is a mesh). Kinds not named here come after
#: these, in registry order (tracer/shapes/__init__.py).
PACK_ORDER = ("sphere", "rectangle", "disk", "triangle", "polygon", "cylinder", "paraboloid",
              ("mesh", "cube"), "instance")


def pack(members: list, packing: Packing) -> list:
    """Every kind's blocks, in :data:`PACK_ORDER`: (block, material ids, radiances) each.

    The one loop over kinds: each kind's module packs its own shapes (its
    ``pack(members, packing)``, or one ``Block(members)`` by default,
    :func:`tracer.shapes.base.pack`).
    """
    entries = [e if isinstance(e, tuple) else (e,) for e in PACK_ORDER]
    named = {k for e in entries for k in e}
    entries += [(k,) for k in shapes.REGISTRY if k not in named]
    out = []
    for kinds in entries:
        mine = [s for s in members if shapes.type_of(s) in kinds]
        if mine:
            module = shapes.REGISTRY[kinds[0]]
            if hasattr(module, "pack"):
                out += module.pack(mine, packing)
            else:
                out += base_pack(module, mine, packing)
    return out


class Packing:
    """What a kind's ``pack`` asks of the geometry: its primitives' material ids and
    radiances, and the geometry of a group (instances)."""

    def __init__(self, scene, names: list):
        self.scene, self.names = scene, names

    def material_id(self, shape) -> int:
        return len(self.names) if shape.material is None else self.names.index(shape.material)

    def rows(self, members: list) -> tuple[np.ndarray, np.ndarray]:
        """Material ids and radiances of one primitive a shape."""
        mids = np.asarray([self.material_id(m) for m in members], dtype=np.uint32)
        rads = np.asarray([m.emitter.radiance if m.emitter is not None else (0, 0, 0)
                           for m in members], dtype=np.float32).reshape(-1, 3)
        return mids, rads

    def repeated(self, shape, count: int) -> tuple[np.ndarray, np.ndarray]:
        """Material ids and radiances of ``count`` primitives of one shape (a mesh's)."""
        mids = np.full(count, self.material_id(shape), dtype=np.uint32)
        radiance = shape.emitter.radiance if shape.emitter is not None else (0, 0, 0)
        return mids, np.tile(np.asarray(radiance, dtype=np.float32), (count, 1))

    def instances(self, insts: list) -> list:
        """Instances: one geometry per group (its own materials; groups do not emit), the
        instances of a much-used group in one hierarchy, the others one by one."""
        scene, out = self.scene, []
        by_group: dict[str, list] = {}
        for inst in insts:
            by_group.setdefault(inst.group, []).append(inst)
        for gname, group in by_group.items():
            members = scene.groups[gname]
            child = Geometry(scene, members, self.names)
            child_mid = child.material_id.numpy()[:child.count]
            if len(group) >= INSTANCE_SET_MIN:
                boxes = [shape_bounds(s) for s in members]
                bounds = (np.min([b[0] for b in boxes], axis=0),
                          np.max([b[1] for b in boxes], axis=0))
                group_blocks = [_InstanceSetBlock(group, child, bounds)]
            else:
                group_blocks = [_InstanceBlock(inst, child) for inst in group]
            for block in group_blocks:
                out.append((block, np.tile(child_mid, block.count // max(child.count, 1)),
                            np.zeros((block.count, 3), dtype=np.float32)))
        return out


# --------------------------------------------------------------------------- geometry


class Geometry:
    """All shapes of a scene (or of one group), with intersection and hit records."""

    def __init__(self, scene, shapes=None, material_names=None):
        members = list(scene.shapes if shapes is None else shapes)
        packing = Packing(scene, list(scene.materials) if material_names is None
                          else material_names)
        self.blocks = []
        mids, rads = [], []  # per block: material ids and radiances of its primitives
        for block, mid, rad in pack(members, packing):
            block.base = sum(b.count for b in self.blocks)
            self.blocks.append(block)
            mids.append(mid)
            rads.append(rad)
        self.count = sum(b.count for b in self.blocks)
        #: the shapes that emit light (area lights), top level only
        self.emitters = [s for s in members if getattr(s, "emitter", None) is not None]
        mid = np.concatenate(mids) if mids else np.zeros(1, dtype=np.uint32)
        self.material_id = _u(mid if len(mid) else np.zeros(1, dtype=np.uint32))
        # Each primitive's radiance, read only where some shape emits (the integrator's
        # _seen); else one zero. Two placed copies of the 1,000,000-triangle knot made
        # 3,000,000 rows of zeros, concatenated and uploaded: about 20 ms of every
        # render of that scene (issue 33).
        rad = np.concatenate(rads) if rads and self.emitters else []
        self.radiance = _v3(rad if len(rad) else np.zeros((1, 3), dtype=np.float32))
        #: whether a triangle mesh is among the blocks, or in a group they instance
        self.has_mesh = any(b.has_mesh for b in self.blocks)

    def emitting(self) -> np.ndarray:
        """numpy bool per primitive: whether it emits light (a nonzero radiance)."""
        if not self.emitters:
            return np.zeros(max(self.count, 1), dtype=bool)
        return np.asarray(self.radiance).T.max(axis=1) > 0

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
                if not every:  # a block may answer anything for a ray it was not asked
                    more = [m & a for m, (_, _, _, a) in zip(more, rays, strict=True)]
                blocked = [b | m for b, m in zip(blocked, more, strict=True)]
            return tuple(blocked)

        none = tuple(dr.zeros(jit.Bool, n) for _ in rays)
        if every:
            return list(step(*none))
        # Inactive lanes keep False (the loop's condition).
        return list(self._once(any_mask([a for *_, a in rays]), step, none))

    @staticmethod
    def _once(active, step, state: tuple) -> tuple:
        """``step(*state)`` in a loop that runs at most once: the SIMD packets without an
        active lane skip it, and lanes outside ``active`` keep ``state``."""
        def body(state, todo):
            return step(*state), jit.Bool(False)

        state, _ = dr.while_loop((state, jit.Bool(active)), lambda state, todo: todo, body,
                                 labels=("state", "todo"))
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
