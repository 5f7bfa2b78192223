"""A bounding-volume hierarchy over triangles: built in numpy, traversed in Dr.Jit.

Build
-----
:func:`build_bvh` splits the triangles top-down with the surface area
heuristic (SAH; Goldsmith and Salmon 1987, MacDonald and Booth 1990): a node
with bounding box B split into children with boxes B_L, B_R holding n_L, n_R
triangles is expected to cost

    C_split = C_trav + C_isect (A(B_L) n_L + A(B_R) n_R) / A(B),

A the surface area, because a random ray that hits B hits B_L with
probability A(B_L) / A(B) (Cauchy's formula for convex bodies). Candidate
splits are the boundaries of equal-width bins along each axis of the box of
the triangles' centroids, with each triangle counted in the bin of its
centroid: the binned SAH of Wald, "On fast Construction of SAH-based Bounding
Volume Hierarchies" (IEEE Symposium on Interactive Ray Tracing 2007). A node
becomes a leaf when it holds at most ``max_leaf`` triangles and
C_leaf = C_isect n is no more than C_split.

The build is breadth-first: every node of one level of the tree is split at
once by vectorised numpy operations on all their triangles (the triangles of
a node are contiguous), so the Python loop runs once per level and a few
times per bin, never once per triangle or per node.

Traversal
---------
The tree is stored for traversal as in Aila and Laine, "Understanding the
Efficiency of Ray Traversal on GPUs" (High Performance Graphics 2009): each
inner node holds the boxes of its two children, so one 64-byte record read
decides which children a ray enters. A child reference is either the index
of an inner node or, with the top bit set, a leaf: the start of its
triangles in the reordered triangle list and their count.

Each ray keeps a stack of deferred children in Dr.Jit local memory
(:func:`drjit.alloc_local`) inside a symbolic loop: when a ray enters both
children it goes on with the nearer one and pushes the other; a child whose
box is entered beyond the nearest hit so far is skipped; a ray stops when
its stack is empty (or, for shadow rays, at the first hit). Triangles are
tested by :func:`tracer.shapes.triangle.intersect`, the test the rest of the
tracer uses, so results agree with a brute-force loop over all triangles.

Choices measured on the LLVM backend (AVX-512, 2 cores), against Mitsuba 3's
Embree on the same rays: testing a leaf's triangles in a loop of their own
(rather than a fixed number of masked tests per step) and placing records on
64-byte boundaries each gave about 1.7x; a 4-wide tree, reading records as
Array4f packets, and a stack of entry distances to skip deferred nodes were
each slower. With these, closest hits on a 100,000
triangle mesh take about 2x Embree's time (tests/test_bvh.py checks results,
never times).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import drjit as dr
import numpy as np

from tracer.backend import jit
from tracer.shapes import triangle as tri_f

__all__ = ["BVH", "BVHArrays", "INVALID", "build_box_bvh", "build_bvh", "pack_nodes"]

#: Triangle index reported for a ray that hits nothing.
INVALID = 0xFFFFFFFF

#: Bit of a child reference that marks a leaf; below it: start << COUNT_BITS | count.
LEAF_FLAG = 0x80000000
COUNT_BITS = 3
START_LIMIT = 1 << (31 - COUNT_BITS)

#: Relative error bound of a float32 product of 3 roundings, gamma_3 = 3u / (1 - 3u),
#: u = 2^-24 (Higham, "Accuracy and Stability of Numerical Algorithms", 2nd ed., 3.1).
GAMMA3 = 3 * 2.0**-24 / (1 - 3 * 2.0**-24)


@dataclass(frozen=True, eq=False)
class BVHArrays:
    """A BVH as flat numpy arrays; node 0 is the root and nodes are in depth-first order.

    Attributes
    ----------
    lo, hi : (M, 3) float64 corners of each node's bounding box.
    left, right : (M,) int64 child node indices; -1 for a leaf.
    start, count : (M,) int64 a leaf's triangles, ``order[start:start + count]``;
        count is 0 for an inner node.
    order : (N,) int64 original triangle indices, leaf after leaf.
    depth : levels below the root (0 when the root is a leaf).
    seconds : wall-clock build time.
    """
    lo: np.ndarray
    hi: np.ndarray
    left: np.ndarray
    right: np.ndarray
    start: np.ndarray
    count: np.ndarray
    order: np.ndarray
    depth: int
    seconds: float

    @property
    def leaf(self) -> np.ndarray:
        """True for leaf nodes."""
        return self.left < 0


def half_area(lo: np.ndarray, hi: np.ndarray, axis: int = -1) -> np.ndarray:
    """Half the surface area dx dy + dy dz + dz dx of boxes; empty boxes (hi < lo) give 0.

    The SAH only compares ratios of areas, so the factor 2 is left out.
    """
    d = np.maximum(hi - lo, 0.0)
    x, y, z = (np.take(d, k, axis=axis) for k in range(3))
    return x * y + y * z + z * x


def build_bvh(p0: np.ndarray, p1: np.ndarray, p2: np.ndarray, *, bins: int = 16,
              max_leaf: int = 4, traversal_cost: float = 2.0,
              intersection_cost: float = 1.0) -> BVHArrays:
    """Build a binned-SAH BVH over triangles (p0[i], p1[i], p2[i]).

    Parameters
    ----------
    p0, p1, p2 : (N, 3) world-space corners.
    bins : bins per axis for nodes of more than 32 triangles (Wald 2007 uses
        16 to 32); smaller nodes use 8, or 4 for at most 8 triangles, since a
        bin per triangle or more finds nothing better.
    max_leaf : the most triangles of a leaf (at most 7, the width of the
        count field of a leaf reference).
    traversal_cost, intersection_cost : C_trav and C_isect of the SAH. Measured
        with :class:`BVH`'s traversal on a CPU: a node step (14 gathered floats,
        two slab tests) costs about two triangle tests (9 gathered floats, one
        solve; measured with Cramer's rule, which the watertight test matches
        in speed); C_trav of 1 to 3 give times within 15 % of each other.
    """
    t_start = time.perf_counter()
    p0, p1, p2 = (np.asarray(p, dtype=np.float64).reshape(-1, 3) for p in (p0, p1, p2))
    if not (len(p0) == len(p1) == len(p2)):
        raise ValueError("p0, p1 and p2 must have the same number of triangles")
    if not 1 <= max_leaf < (1 << COUNT_BITS):
        raise ValueError(f"max_leaf must be between 1 and {(1 << COUNT_BITS) - 1}")
    n = len(p0)
    if n >= START_LIMIT:
        raise ValueError(f"at most {START_LIMIT - 1} triangles are supported")
    if not (np.isfinite(p0).all() and np.isfinite(p1).all() and np.isfinite(p2).all()):
        raise ValueError("triangle corners must be finite")
    if n == 0:
        empty = np.zeros((0, 3))
        none = np.zeros(0, np.int64)
        return BVHArrays(empty, empty, none, none, none, none, none, 0,
                         time.perf_counter() - t_start)

    tri_lo = np.minimum(np.minimum(p0, p1), p2)
    tri_hi = np.maximum(np.maximum(p0, p1), p2)
    # The triangles still to place, grouped by node (segment) in order: their ids and
    # a column of box lo (rows 0:3), box hi (3:6) and box centroid (6:9, what the bins
    # sort); rows of one quantity are contiguous, as numpy's reductions prefer.
    ids = np.arange(n)
    tri = np.ascontiguousarray(np.concatenate([tri_lo, tri_hi, 0.5 * (tri_lo + tri_hi)],
                                              axis=1).T)
    seg_node = np.zeros(1, np.int64)
    seg_cnt = np.array([n], np.int64)

    levels: list[dict[str, np.ndarray]] = []
    order = np.empty(n, np.int64)
    placed = 0
    next_id = 1
    while len(seg_node):
        S = len(seg_node)
        offs = np.cumsum(seg_cnt) - seg_cnt
        seg = np.repeat(np.arange(S), seg_cnt)
        mins = np.minimum.reduceat(tri, offs, axis=1).T
        maxs = np.maximum.reduceat(tri, offs, axis=1).T
        box_lo, box_hi = mins[:, 0:3], maxs[:, 3:6]
        c_lo = mins[:, 6:9]
        ext = maxs[:, 6:9] - c_lo

        # Best binned-SAH split of every node, in size classes with their own bin count.
        cost = np.full(S, np.inf)
        axis = np.zeros(S, np.int64)
        split_bin = np.zeros(S, np.int64)
        scale = np.zeros((S, 3))
        nbins = np.ones(S, np.int64)
        for nb, cls in ((4, seg_cnt <= 8), (8, (seg_cnt > 8) & (seg_cnt <= 32)),
                        (bins, seg_cnt > 32)):
            cls &= seg_cnt > 1
            if not cls.any():
                continue
            sc = np.where(ext[cls] > 0, nb / np.where(ext[cls] > 0, ext[cls], 1.0), 0.0)
            if cls.all():
                sub, local = tri, seg
            else:
                sel = cls[seg]
                sub, local = tri[:, sel], (np.cumsum(cls) - 1)[seg[sel]]
            c, ax, b = _binned_sah(sub, local, c_lo[cls], sc, seg_cnt[cls], nb)
            cost[cls], axis[cls], split_bin[cls], scale[cls], nbins[cls] = c, ax, b, sc, nb

        area = half_area(box_lo, box_hi)
        split_cost = traversal_cost + intersection_cost * cost / np.where(area > 0, area, 1.0)
        no_sah = ~np.isfinite(cost)  # all centroids coincide: split in the middle of the list
        leaf = (seg_cnt <= max_leaf) & (no_sah | (intersection_cost * seg_cnt <= split_cost))

        # Leaves: their triangles go to the output order now.
        start = np.zeros(S, np.int64)
        count = np.where(leaf, seg_cnt, 0)
        tri_leaf = leaf[seg]
        k = int(np.count_nonzero(tri_leaf))
        order[placed:placed + k] = ids[tri_leaf]
        start[leaf] = placed + np.cumsum(seg_cnt[leaf]) - seg_cnt[leaf]
        placed += k

        split = ~leaf
        ns = int(np.count_nonzero(split))
        left = np.full(S, -1, np.int64)
        left[split] = next_id + 2 * np.arange(ns)
        right = np.where(split, left + 1, -1)
        next_id += 2 * ns
        levels.append(dict(node=seg_node, lo=box_lo, hi=box_hi, left=left, right=right,
                           start=start, count=count))
        if ns == 0:
            break

        # Partition: each split node's triangles, left child's first, keeping their order.
        if k:
            m = ~tri_leaf
            s_m, ids, tri = seg[m], ids[m], tri[:, m]
        else:
            s_m = seg
        ax_t = axis[s_m]
        rows = np.arange(len(s_m))
        b = ((tri[6 + ax_t, rows] - c_lo[s_m, ax_t]) * scale[s_m, ax_t]).astype(np.int64)
        np.clip(b, 0, nbins[s_m] - 1, out=b)  # the same bins as _binned_sah's
        go_left = b <= split_bin[s_m]
        median = no_sah[s_m]
        if median.any():
            rank = (np.arange(len(seg))[m] if k else rows) - offs[s_m]
            go_left = np.where(median, rank < seg_cnt[s_m] // 2, go_left)
        cs = (np.cumsum(split) - 1)[s_m]  # index among the split nodes
        cnt_s = seg_cnt[split]
        first = (np.cumsum(cnt_s) - cnt_s)[cs]
        n_left = np.bincount(cs, weights=go_left, minlength=ns).astype(np.int64)
        lefts_before = np.cumsum(go_left) - go_left
        rank_l = lefts_before - lefts_before[first]
        rank_r = (rows - first) - rank_l
        dest = np.where(go_left, first + rank_l, first + n_left[cs] + rank_r)
        ids = _scatter(ids, dest)
        tri_new = np.empty_like(tri)
        tri_new[:, dest] = tri
        tri = tri_new
        seg_node = np.stack([left[split], right[split]], axis=1).reshape(-1)
        seg_cnt = np.stack([n_left, cnt_s - n_left], axis=1).reshape(-1)

    arrays = _depth_first(levels, next_id, order)
    return BVHArrays(*arrays, depth=len(levels) - 1, seconds=time.perf_counter() - t_start)


def build_box_bvh(lo: np.ndarray, hi: np.ndarray, **options) -> BVHArrays:
    """A binned-SAH BVH over axis-aligned boxes [lo[i], hi[i]] (e.g. placed instances).

    The builder sees only the bounding box of each triangle, so box i is given
    as the degenerate triangle (lo, hi, hi), whose bounding box it is; ``order``
    then lists box indices. Options as for :func:`build_bvh`.
    """
    lo, hi = (np.asarray(a, dtype=np.float64).reshape(-1, 3) for a in (lo, hi))
    return build_bvh(lo, hi, hi, **options)


def _scatter(x: np.ndarray, dest: np.ndarray) -> np.ndarray:
    out = np.empty_like(x)
    out[dest] = x
    return out


def _binned_sah(tri, seg, c_lo, scale, cnt, nb):
    """Cheapest binned-SAH split of each of S nodes over the three axes.

    Parameters: per triangle a column of ``tri`` (box lo, box hi, box centroid)
    and its node ``seg`` (0..S-1); per node the centroid box corner ``c_lo``, ``scale`` =
    nb / (centroid box extent) (0 on a flat axis) and triangle count ``cnt``.

    Returns (cost, axis, bin): cost = A(B_L) n_L + A(B_R) n_R (half areas) of
    the best split, which puts bins 0..bin on the left; inf where no axis can
    be split (all centroids in one bin).
    """
    S = len(cnt)
    lo, hi, c = tri[0:3], tri[3:6], tri[6:9]
    best = np.full(S, np.inf)
    best_axis = np.zeros(S, np.int64)
    best_bin = np.zeros(S, np.int64)
    for ax in range(3):
        b = ((c[ax] - c_lo[seg, ax]) * scale[seg, ax]).astype(np.int64)
        # The largest centroid lands on bin nb; it belongs to the last bin.
        np.clip(b, 0, nb - 1, out=b)
        key = b * S + seg  # bin-major: the prefix sweeps below work on whole rows
        n_bin = np.bincount(key, minlength=nb * S).reshape(nb, S)
        b_lo = np.full((3, nb * S), np.inf)
        b_hi = np.full((3, nb * S), -np.inf)
        for k in range(3):
            np.minimum.at(b_lo[k], key, lo[k])
            np.maximum.at(b_hi[k], key, hi[k])
        b_lo = b_lo.reshape(3, nb, S)
        b_hi = b_hi.reshape(3, nb, S)
        # Sweep from the left and from the right (Wald 2007, section 3.3).
        area_l = np.empty((nb - 1, S))
        area_r = np.empty((nb - 1, S))
        run_lo, run_hi = b_lo[:, 0].copy(), b_hi[:, 0].copy()
        for i in range(nb - 1):
            if i:
                np.minimum(run_lo, b_lo[:, i], out=run_lo)
                np.maximum(run_hi, b_hi[:, i], out=run_hi)
            area_l[i] = half_area(run_lo, run_hi, axis=0)
        run_lo, run_hi = b_lo[:, nb - 1].copy(), b_hi[:, nb - 1].copy()
        for i in range(nb - 2, -1, -1):
            if i < nb - 2:
                np.minimum(run_lo, b_lo[:, i + 1], out=run_lo)
                np.maximum(run_hi, b_hi[:, i + 1], out=run_hi)
            area_r[i] = half_area(run_lo, run_hi, axis=0)
        n_l = np.cumsum(n_bin, axis=0)[:-1]
        n_r = cnt[None, :] - n_l
        cost = np.where((n_l > 0) & (n_r > 0), area_l * n_l + area_r * n_r, np.inf)
        cost[:, scale[:, ax] == 0] = np.inf
        i = np.argmin(cost, axis=0)
        c_ax = cost[i, np.arange(S)]
        better = c_ax < best
        best = np.where(better, c_ax, best)
        best_axis = np.where(better, ax, best_axis)
        best_bin = np.where(better, i, best_bin)
    return best, best_axis, best_bin


def _depth_first(levels, total, order):
    """Renumber the nodes (built level by level) in depth-first order, left child first.

    Depth-first order puts a node's subtree in one block of memory, and the
    triangles of its leaves too, which the traversal reads with fewer cache
    misses than level order.
    """
    node = np.concatenate([lv["node"] for lv in levels])
    cols = {k: np.empty((total,) + levels[0][k].shape[1:], levels[0][k].dtype)
            for k in ("lo", "hi", "left", "right", "start", "count")}
    for k, a in cols.items():
        a[node] = np.concatenate([lv[k] for lv in levels])
    left, right = cols["left"], cols["right"]
    # Subtree sizes, bottom-up, one level at a time.
    size = np.ones(total, np.int64)
    for lv in reversed(levels):
        inner = lv["node"][lv["left"] >= 0]
        size[inner] = 1 + size[left[inner]] + size[right[inner]]
    # New indices, top-down: left child right after its parent, then the right subtree.
    new = np.zeros(total, np.int64)
    for lv in levels:
        inner = lv["node"][lv["left"] >= 0]
        new[left[inner]] = new[inner] + 1
        new[right[inner]] = new[inner] + 1 + size[left[inner]]
    out = {k: _scatter(a, new) for k, a in cols.items()}
    inner = out["left"] >= 0
    out["left"][inner] = new[out["left"][inner]]
    out["right"][inner] = new[out["right"][inner]]
    # Triangles leaf after leaf in depth-first order.
    leaves = np.flatnonzero(~inner)
    counts = out["count"][leaves]
    src = np.repeat(out["start"][leaves] - (np.cumsum(counts) - counts), counts)
    order = order[src + np.arange(len(src))]
    out["start"][leaves] = np.cumsum(counts) - counts
    return (out["lo"], out["hi"], out["left"], out["right"], out["start"], out["count"], order)


def pack_nodes(b: BVHArrays) -> tuple[np.ndarray, int, int]:
    """(records, root reference, stack size) of the traversal layout.

    One record of 16 float32 per inner node: the boxes of its two children as
    lo.x lo.y lo.z of the left, the same of the right, hi of the left, hi of
    the right, then the two child references (uint32 bits) and two unused
    slots: 64 bytes, one cache line once aligned (:func:`_aligned`). Inner
    nodes keep their depth-first order, so a parent and its left child are
    neighbours in memory. Boxes are rounded outwards to float32 and widened by
    2^-20 of their largest coordinate, more than the float32 rounding of the
    corners. :func:`tracer.shapes.triangle.intersect` works in the ray's
    sheared space and may take a ray a few roundings of the ray's length
    beside its triangle; the widening of t_far in the slab test covers that
    (tests/test_watertight.py aims rays from far away at edges on box faces).

    The stack size is the depth of the tree plus one: a ray at a node of
    depth k has at most k deferred nodes (one per ancestor), so its stack
    pointer never exceeds the depth, and the extra slot keeps even that value
    a valid index (a ray waiting at a deepest leaf holds it while the others
    of its packet still run the loop).
    """
    inner = np.flatnonzero(b.left >= 0)
    rank = np.full(len(b.left), -1, np.int64)
    rank[inner] = np.arange(len(inner))
    ref = np.where(b.left >= 0, rank,
                   LEAF_FLAG | (b.start << COUNT_BITS) | b.count).astype(np.uint32)
    lo, hi = _outward(b.lo, b.hi)
    rec = np.zeros((len(inner), 16), np.float32)
    ln, rn = b.left[inner], b.right[inner]
    rec[:, 0:3], rec[:, 3:6] = lo[ln], lo[rn]
    rec[:, 6:9], rec[:, 9:12] = hi[ln], hi[rn]
    rec[:, 12] = ref[ln].view(np.float32)
    rec[:, 13] = ref[rn].view(np.float32)
    root = int(ref[0]) if len(ref) else INVALID
    return rec, root, b.depth + 1


def _outward(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """float32 boxes that contain the float64 ones, widened as :func:`pack_nodes` says."""
    pad = np.maximum(np.abs(lo), np.abs(hi)).max(axis=1, keepdims=True) * 2.0**-20 + 1e-30
    lo32 = (lo - pad).astype(np.float32)
    hi32 = (hi + pad).astype(np.float32)
    lo32 = np.where(lo32 > lo, np.nextafter(lo32, np.float32(-np.inf)), lo32)
    hi32 = np.where(hi32 < hi, np.nextafter(hi32, np.float32(np.inf)), hi32)
    return lo32, hi32


class BVH:
    """A BVH over triangles, uploaded to Dr.Jit, answering closest-hit and occlusion queries.

    Parameters
    ----------
    p0, p1, p2 : (N, 3) world-space triangle corners (float64 or anything numpy reads).
    **build_options : passed to :func:`build_bvh`.

    Attributes
    ----------
    arrays : the :class:`BVHArrays` of the build.
    build_seconds : time of :func:`build_bvh` (numpy only, not the upload).
    node_count : nodes of the tree, leaves included.
    triangle_count : triangles.
    depth : levels below the root; the traversal stack has one entry more.
    perm : jit.UInt32 original index of each triangle in leaf order.
    nodes : jit.Float inner-node records (:func:`pack_nodes`).
    tris : jit.Float triangle records in leaf order, 16 floats each:
        p0 (3), p1 (3), p2 (3), unused (7).
    """

    def __init__(self, p0: np.ndarray, p1: np.ndarray, p2: np.ndarray, **build_options):
        p0, p1, p2 = (np.asarray(p, dtype=np.float64).reshape(-1, 3) for p in (p0, p1, p2))
        self.arrays = build_bvh(p0, p1, p2, **build_options)
        self.build_seconds = self.arrays.seconds
        self.node_count = len(self.arrays.left)
        self.triangle_count = len(p0)
        self.depth = self.arrays.depth
        rec, self._root, self._stack = pack_nodes(self.arrays)
        self.nodes = _aligned(rec if len(rec) else np.zeros((1, 16), np.float32))
        o = self.arrays.order
        self.perm = jit.UInt32(o.astype(np.uint32))
        tr = np.zeros((len(o), 16), np.float32)
        # The corners rounded once to float32, as tracer.geometry stores them: a vertex
        # shared by two triangles is the same float32 point in both (the watertight
        # test relies on it), and both modules give the same numbers.
        tr[:, 0:3], tr[:, 3:6], tr[:, 6:9] = p0[o], p1[o], p2[o]
        self.tris = _aligned(tr)

    def triangles(self) -> tuple:
        """(p0, p1, p2) as jit.Array3f in leaf order (index i is original ``perm[i]``)."""
        i = dr.arange(jit.UInt32, self.triangle_count) * 16
        return tuple(jit.Array3f(*(dr.gather(jit.Float, self.tris, i + 3 * k + c)
                                   for c in range(3))) for k in range(3))

    # ---------------------------------------------------------------- queries

    def closest_hit(self, o: jit.Array3f, d: jit.Array3f, tmax: jit.Float | float,
                    active: jit.Bool | bool = True) -> tuple:
        """(t, tri, beta, gamma) of the nearest hit with 0 < t < tmax of each ray.

        ``o`` and ``d`` are jit.Array3f (``d`` need not be a unit vector; t is in
        units of its length), ``tmax`` a jit.Float or a number, ``active`` a
        jit.Bool or True. ``tri`` is the hit triangle's index in the order given
        to the constructor, :data:`INVALID` where nothing is hit or the ray is
        inactive (t is tmax there); (beta, gamma) are the barycentrics of
        :func:`tracer.shapes.triangle.intersect`, which tests every triangle.
        """
        return self._trace(o, d, tmax, active, shadow=False)

    def occluded(self, o: jit.Array3f, d: jit.Array3f, tmax: jit.Float | float,
                 active: jit.Bool | bool = True) -> jit.Bool:
        """jit.Bool: some triangle lies on the ray at 0 < t < tmax (found as soon as any is)."""
        _, tri, _, _ = self._trace(o, d, tmax, active, shadow=True)
        return tri != INVALID

    # ---------------------------------------------------------------- traversal

    def _trace(self, o, d, tmax, active, shadow):
        o, d = jit.Array3f(o), jit.Array3f(d)
        n = max(dr.width(o), dr.width(d), dr.width(tmax), dr.width(active))
        t = jit.Float(tmax) + dr.zeros(jit.Float, n)
        alive = jit.Bool(active) | dr.zeros(jit.Bool, n)
        if self.triangle_count == 0:
            z = dr.zeros(jit.Float, n)
            return t, dr.full(jit.UInt32, INVALID, n), z, z
        t, tri, beta, gamma = self._loop(o, d, t, alive, shadow)
        # Back to the caller's triangle numbering.
        found = tri != INVALID
        orig = dr.gather(jit.UInt32, self.perm, tri, found)
        return t, dr.select(found, orig, INVALID), beta, gamma

    @dr.syntax
    def _loop(self, o, d, t, alive, shadow):
        """The traversal, "while-while" in the words of Aila and Laine (2009).

        Each pass of the outer loop walks inner nodes until the ray stands at a
        leaf, then tests the leaf's triangles, then pops the next deferred
        node. Dr.Jit runs a loop for a packet of rays (16 on a CPU with AVX-512,
        a warp on a GPU) until all of them are done with it, so keeping the
        node steps and the triangle tests in separate loops lets the rays of a
        packet do the same kind of work at the same time.
        """
        n = dr.width(t)
        # 1 / d for the slab test; a zero component becomes a tiny one of the same sign,
        # so that (l - o) / d is +-huge rather than the NaN of 0 * inf.
        tiny = 1e-30
        inv = 1.0 / jit.Array3f(*(dr.select(dr.abs(d[k]) < tiny, dr.copysign(tiny, d[k]), d[k])
                                  for k in range(3)))
        rs = tri_f.ray_space(o, d)  # the triangle test's per-ray part, once per ray
        tri = dr.full(jit.UInt32, INVALID, n)
        beta = dr.zeros(jit.Float, n)
        gamma = dr.zeros(jit.Float, n)
        node = dr.full(jit.UInt32, self._root, n)
        sp = dr.zeros(jit.UInt32, n)
        # Initialised although never read before written: with an uninitialised
        # buffer, LLVM may treat the old contents in Dr.Jit's masked
        # read-modify-write of a slot as undefined and store all 16 lanes,
        # overwriting other rays' deferred nodes (seen as random crashes).
        stack = dr.alloc_local(jit.UInt32, self._stack, jit.UInt32(0))
        nodes, tris = self.nodes, self.tris
        # Widening t_far makes the float32 slab test conservative (Pharr, Jakob and
        # Humphreys, "Physically Based Rendering", 3rd ed., section 3.9.2).
        widen = 1 + 2 * GAMMA3

        while alive:
            # Inner nodes, until this ray stands at a leaf or has nothing left to visit.
            while alive & ((node & LEAF_FLAG) == 0):
                # Memory accesses carry the loop's condition as an explicit mask: lanes
                # that wait (at a leaf, or done) run the body too, with stale indices.
                step = alive & ((node & LEAF_FLAG) == 0)
                # Only the 14 floats used are read: Dr.Jit drops the unused gathers.
                r = dr.gather(jit.ArrayXf, nodes, node, step, shape=(16, n))
                tn_l, tf_l = _slab(o, inv, r[0], r[1], r[2], r[6], r[7], r[8])
                tn_r, tf_r = _slab(o, inv, r[3], r[4], r[5], r[9], r[10], r[11])
                # Entered before the nearest hit so far, and not only behind the origin.
                hit_l = step & (tn_l <= tf_l * widen) & (tf_l > 0) & (tn_l < t)
                hit_r = step & (tn_r <= tf_r * widen) & (tf_r > 0) & (tn_r < t)
                ref_l = dr.reinterpret_array(jit.UInt32, r[12])
                ref_r = dr.reinterpret_array(jit.UInt32, r[13])
                # Both entered: go on with the nearer, defer the other.
                r_first = tn_r < tn_l
                near = dr.select(hit_l & ~(hit_r & r_first), ref_l, ref_r)
                both = hit_l & hit_r
                stack.write(dr.select(r_first, ref_l, ref_r), sp, both)
                sp = dr.select(both, sp + 1, sp)
                # Neither: the deferred node pushed last, or the end of the ray.
                descend = hit_l | hit_r
                pop = step & ~descend & (sp > 0)
                sp = dr.select(pop, sp - 1, sp)
                node = dr.select(descend, near, dr.select(pop, stack.read(sp, pop), node))
                alive &= ~step | descend | pop

            # The leaf's triangles, one after the other.
            i = (node & (LEAF_FLAG - 1)) >> COUNT_BITS
            end = i + (node & ((1 << COUNT_BITS) - 1))
            while alive & (i < end):
                q = dr.gather(jit.ArrayXf, tris, i, alive & (i < end), shape=(16, n))
                tk, hk, bk, gk = tri_f.intersect(
                    o, d, jit.Array3f(q[0], q[1], q[2]), jit.Array3f(q[3], q[4], q[5]),
                    jit.Array3f(q[6], q[7], q[8]), t, rs)
                hk &= alive & (i < end)
                t = dr.select(hk, tk, t)
                tri = dr.select(hk, i, tri)
                beta = dr.select(hk, bk, beta)
                gamma = dr.select(hk, gk, gamma)
                i += 1
                if shadow:
                    i = dr.select(hk, end, i)  # any hit will do

            pop = alive & (sp > 0)
            if shadow:
                pop &= tri == INVALID
            sp = dr.select(pop, sp - 1, sp)
            node = dr.select(pop, stack.read(sp, pop), node)
            alive &= pop
        return t, tri, beta, gamma


def _slab(o, inv, lx, ly, lz, hx, hy, hz):
    """(t_near, t_far) of the ray o + t d against the box [l, h], given inv = 1 / d.

    Between the two planes of one axis the ray runs for t in
    [(l - o) / d, (h - o) / d], ordered by the sign of d; the box is the
    intersection of the three intervals (the slab test of Kay and Kajiya,
    "Ray Tracing Complex Scenes", SIGGRAPH 1986). Computing (l - o) * inv
    rather than l * inv - o * inv keeps each t within a relative 3 roundings
    of its exact value, the bound the widening of t_far relies on.
    """
    t0x, t1x = (lx - o.x) * inv.x, (hx - o.x) * inv.x
    t0y, t1y = (ly - o.y) * inv.y, (hy - o.y) * inv.y
    t0z, t1z = (lz - o.z) * inv.z, (hz - o.z) * inv.z
    tn = dr.maximum(dr.maximum(dr.minimum(t0x, t1x), dr.minimum(t0y, t1y)),
                    dr.minimum(t0z, t1z))
    tf = dr.minimum(dr.minimum(dr.maximum(t0x, t1x), dr.maximum(t0y, t1y)),
                    dr.maximum(t0z, t1z))
    return tn, tf


def _aligned(rec: np.ndarray):
    """A jit.Float of the float32 records ``rec``, starting on a 64-byte boundary if possible.

    A record of 16 floats then fills one cache line instead of straddling two
    (measured: 1.7x faster traversal than a random alignment). On the CPU,
    Dr.Jit uses the memory of a contiguous numpy array it is given (and keeps
    the array alive), so the data are placed at an aligned offset in a larger
    numpy buffer; elsewhere (CUDA) Dr.Jit copies them into its own memory.
    """
    buf = np.empty(rec.size + 16, np.float32)
    start = (-buf.ctypes.data // 4) % 16
    view = buf[start:start + rec.size]
    view[:] = rec.reshape(-1)
    return jit.Float(view)

