"""A bounding-volume hierarchy over triangles: built and traversed in Dr.Jit.

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
once, by Dr.Jit kernels on all its triangles (:func:`_split_levels`); the
host loop runs once per level. Small nodes are a SIMD lane each, large ones
are cut into chunks of a lane each whose bins are then summed, so that no
two lanes ever update the same bin (scatter-reductions into the bins, which
collide in every SIMD packet, were 3-4x slower). Measured on the 2-core CPU
machine with ``python benchmarks/bench_speed.py mesh``: a 1,000,000-triangle
mesh in about 0.6 s where the earlier numpy build (a tree of the same SAH
cost) took 7.5 s.

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

A lane may also carry K rays that walk the tree together, as a packet
(:meth:`BVH.closest_hit_group`, :meth:`BVH.occluded_group`): one stack, each
node and triangle read once for the K rays. On a CPU a node step's time goes
to reading its record, per lane (Dr.Jit has no load that the lanes of a SIMD
packet share), while the K slab tests are cheap; the integrator gives a lane
K samples of one pixel (:data:`tracer.integrator.GROUPS`). The knot of
``benchmarks/bench_mesh.py``, its camera rays alone: 86 to 58 ms with K = 4,
its shadow rays 75 to 50 ms (a throwaway script, medians of 5).

Choices measured on the LLVM backend (AVX-512, 2 cores), against Mitsuba 3's
Embree on the same rays: testing a leaf's triangles in a loop of their own
(rather than a fixed number of masked tests per step) and placing records on
64-byte boundaries each gave about 1.7x; a 4-wide tree, reading records as
Array4f packets, and a stack of entry distances to skip deferred nodes were
each slower. tests/tracer/test_bvh.py and tests/tracer/test_packets.py check results, never
times; ``benchmarks/bench_mesh.py`` times the render against Embree's.
"""

from __future__ import annotations

import time
from collections import OrderedDict
from dataclasses import dataclass

import drjit as dr
import numpy as np

from whitted.tracer import backend
from whitted.tracer.backend import aligned_zeros, any_mask, greater, jit, lesser, upload
from whitted.tracer.shapes import triangle as tri_f

__all__ = ["BVH", "BVHArrays", "INVALID", "build_box_bvh", "build_bvh", "pack_nodes",
           "sah_cost", "shared_bvh", "shared_mesh_bvh"]

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
    lo, hi : (M, 3) float32 corners of each node's bounding box: the smallest float32
        box that holds its triangles (their float64 corners rounded outwards).
    left, right : (M,) int64 child node indices; -1 for a leaf.
    start, count : (M,) int64 a leaf's triangles, ``order[start:start + count]``;
        count is 0 for an inner node.
    order : (N,) int64 original triangle indices, leaf after leaf (int32 in a tree read
        from the disk cache).
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
    if not 2 <= bins <= 256:
        raise ValueError("bins must be between 2 and 256")
    n = len(p0)
    if n >= START_LIMIT:
        raise ValueError(f"at most {START_LIMIT - 1} triangles are supported")
    if not (np.isfinite(p0).all() and np.isfinite(p1).all() and np.isfinite(p2).all()):
        raise ValueError("triangle corners must be finite")
    if n == 0:
        empty = np.zeros((0, 3), np.float32)
        none = np.zeros(0, np.int64)
        return BVHArrays(empty, empty, none, none, none, none, none, 0,
                         time.perf_counter() - t_start)

    lo, hi = _triangle_boxes(p0, p1, p2)
    levels, order = _split_levels(lo, hi, bins, max_leaf, float(traversal_cost),
                                  float(intersection_cost))
    arrays = _depth_first(levels, order)
    return BVHArrays(*arrays, depth=len(levels) - 1, seconds=time.perf_counter() - t_start)


def sah_cost(lo, hi, count, inner, traversal_cost: float = 2.0,
             intersection_cost: float = 1.0) -> float:
    """A tree's expected cost by the SAH the builder minimises (module docstring),
    relative to its root's area: C_trav times the inner nodes' areas plus C_isect
    times each leaf's area and triangle count. A measure of a tree's quality that
    does not depend on timing (``benchmarks/bench_mesh.py`` prints it)."""
    d = np.maximum(np.asarray(hi, np.float64) - lo, 0)
    area = d[:, 0] * d[:, 1] + d[:, 1] * d[:, 2] + d[:, 2] * d[:, 0]
    inner = np.asarray(inner, bool)
    return float((traversal_cost * area[inner].sum()
                  + intersection_cost * (area[~inner] * np.asarray(count)[~inner]).sum())
                 / area[0])


#: Box sets of at most this many boxes (the instances of a group in most scenes) are built
#: on the host by :func:`_small_box_tree`, not by the device builder, whose first call in a
#: process (its kernels read from the cache, a wait for the device at each level, and then
#: its loops' source transformed by drjit.syntax) took 40-60 ms for 4 boxes, and later
#: calls 15 ms (a throwaway script); the host takes well under a millisecond for a few
#: boxes.
SMALL_BOX_SET = 64


def build_box_bvh(lo: np.ndarray, hi: np.ndarray, **options) -> BVHArrays:
    """A binned-SAH BVH over axis-aligned boxes [lo[i], hi[i]] (e.g. placed instances).

    The builder sees only the bounding box of each triangle, so box i is given
    as the degenerate triangle (lo, hi, hi), whose bounding box it is; ``order``
    then lists box indices. Options as for :func:`build_bvh`. Up to
    :data:`SMALL_BOX_SET` boxes, the tree is :func:`_small_box_tree`'s.
    """
    lo, hi = (np.asarray(a, dtype=np.float64).reshape(-1, 3) for a in (lo, hi))
    if not 1 <= len(lo) <= SMALL_BOX_SET or len(hi) != len(lo):
        return build_bvh(lo, hi, hi, **options)
    t_start = time.perf_counter()
    if not (np.isfinite(lo).all() and np.isfinite(hi).all()):
        raise ValueError("triangle corners must be finite")
    max_leaf = options.get("max_leaf", 4)
    if not 1 <= max_leaf < (1 << COUNT_BITS):
        raise ValueError(f"max_leaf must be between 1 and {(1 << COUNT_BITS) - 1}")
    arrays = _small_box_tree(*_float32_boxes(np.minimum(lo, hi), np.maximum(lo, hi)),
                             max_leaf, float(options.get("traversal_cost", 2.0)),
                             float(options.get("intersection_cost", 1.0)))
    return BVHArrays(*arrays, seconds=time.perf_counter() - t_start)


def _float32_boxes(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The float32 boxes that hold the float64 ones, rounded as :func:`_triangle_boxes`
    rounds a triangle's (outwards, and a bound that would be subnormal to zero or the
    smallest normal float32, whichever lies outside: the CPU's kernels flush subnormals)."""
    lo32, hi32 = lo.astype(np.float32), hi.astype(np.float32)
    lo32 = np.where(lo32 > lo, np.nextafter(lo32, np.float32(-np.inf)), lo32)
    hi32 = np.where(hi32 < hi, np.nextafter(hi32, np.float32(np.inf)), hi32)
    lo32 = np.where(np.abs(lo32) < FLT_MIN, np.where(lo < 0, -FLT_MIN, 0.0), lo32)
    hi32 = np.where(np.abs(hi32) < FLT_MIN, np.where(hi > 0, FLT_MIN, 0.0), hi32)
    return lo32.astype(np.float32), hi32.astype(np.float32)


def _half_areas(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Half the surface areas of boxes (rows), float64; empty boxes give 0."""
    d = np.maximum(np.asarray(hi, np.float64) - lo, 0.0)
    return d[..., 0] * d[..., 1] + d[..., 1] * d[..., 2] + d[..., 2] * d[..., 0]


def _small_box_tree(lo: np.ndarray, hi: np.ndarray, max_leaf: int, c_trav: float,
                    c_isect: float) -> tuple:
    """(lo, hi, left, right, start, count, order, depth) of a SAH tree over a few float32
    boxes, built top-down on the host and numbered depth-first, as :func:`build_bvh`'s.

    Each node tries every split between its boxes sorted by centroid on each axis (the
    binned builder's candidates are a subset) and takes the cheapest, A_L n_L + A_R n_R;
    it becomes a leaf by the binned builder's rule: at most ``max_leaf`` boxes and no
    split expected to be cheaper (C_isect n <= C_trav + C_isect cost / A), or one box.
    Where all centroids coincide, a larger node is split in half, as there.
    """
    centre = (lo.astype(np.float64) + hi) * 0.5
    nodes: list[list] = []   # [lo, hi, left, right, start, count] in depth-first order
    order: list[int] = []
    depth = 0

    def build(ids: np.ndarray, level: int) -> int:
        nonlocal depth
        k = len(nodes)
        box_lo, box_hi = lo[ids].min(axis=0), hi[ids].max(axis=0)
        nodes.append([box_lo, box_hi, -1, -1, 0, 0])
        m = len(ids)
        best, split = np.inf, None
        for a in range(3 if m > 1 else 0):
            if centre[ids, a].min() == centre[ids, a].max():
                continue   # no split on this axis (the binned builder's rule)
            s = ids[np.argsort(centre[ids, a], kind="stable")]
            left = _half_areas(np.minimum.accumulate(lo[s], axis=0)[:-1],
                               np.maximum.accumulate(hi[s], axis=0)[:-1])
            right = _half_areas(np.minimum.accumulate(lo[s][::-1], axis=0)[::-1][1:],
                                np.maximum.accumulate(hi[s][::-1], axis=0)[::-1][1:])
            n_left = np.arange(1, m)
            cost = left * n_left + right * (m - n_left)
            i = int(np.argmin(cost))
            if cost[i] < best:
                best, split = float(cost[i]), (s[:i + 1], s[i + 1:])
        area = float(_half_areas(box_lo, box_hi))
        cost_split = c_trav + c_isect * best / (area if area > 0 else 1.0)
        if m < 2 or (m <= max_leaf and (split is None or c_isect * m <= cost_split)):
            nodes[k][4:] = [len(order), m]
            order.extend(int(i) for i in ids)
            depth = max(depth, level)
            return k
        if split is None:   # every centroid in one point: the list split in half
            split = (ids[:m // 2], ids[m // 2:])
        nodes[k][2] = build(split[0], level + 1)
        nodes[k][3] = build(split[1], level + 1)
        return k

    build(np.arange(len(lo)), 0)
    cols = list(zip(*nodes, strict=True))
    return (np.array(cols[0], np.float32).reshape(-1, 3),
            np.array(cols[1], np.float32).reshape(-1, 3),
            *(np.array(c, np.int64) for c in cols[2:]), np.array(order, np.int64), depth)


def _half_area_jit(lo, hi):
    """Half the surface area of boxes (Dr.Jit); empty boxes (hi < lo) give 0."""
    d = greater(hi - lo, 0.0)
    return d.x * d.y + d.y * d.z + d.z * d.x


def _component(v, axis):
    """Component ``axis`` (per lane: 0, 1 or 2) of an Array3f."""
    return dr.select(axis == 0, v.x, dr.select(axis == 1, v.y, v.z))


def _bin_scale(c_lo, c_hi, nb):
    """Per axis, nb / (the centroid box's extent): bins per unit length; 0 on a flat axis."""
    ext = c_hi - c_lo
    return jit.Array3f(*(dr.select(ext[k] > 0, jit.Float(nb) / ext[k], 0.0) for k in range(3)))


def _bin(c, c_lo, scale, nb):
    """The bin of centroid coordinate c: floor((c - c_lo) scale), the largest in bin nb - 1.

    One function for the binning and for the partition, so that both put a
    triangle in the same bin (the same float32 operations in the same order).
    """
    b = jit.UInt32((c - c_lo) * scale)
    return dr.minimum(b, nb - 1)


def _triangle_boxes(p0: np.ndarray, p1: np.ndarray, p2: np.ndarray) -> tuple:
    """(lo, hi) jit.Array3f: per triangle, the smallest float32 box around its float64 corners.

    One Dr.Jit kernel reads the corners (as flat float64 arrays, no copy in
    numpy), takes their minimum and maximum, rounds them to float32 and, where
    the nearest float32 lies inside, moves it one float32 outwards. Dr.Jit's CPU
    kernels flush subnormal floats to zero, so a bound that would be subnormal
    becomes zero or the smallest normal float32, whichever lies outside.
    """
    F, F64, U = jit.Float, jit.Float64, jit.UInt32
    # Only gathered: a gather's code does not depend on the memory's alignment, so numpy's
    # memory serves as it is (no copy, unlike backend.upload).
    corners = [F64(np.ascontiguousarray(p).reshape(-1)) for p in (p0, p1, p2)]
    i = dr.arange(U, len(p0)) * 3
    lo, hi = [], []
    for k in range(3):
        a, b, c = (dr.gather(F64, p, i + k) for p in corners)
        x, y = dr.minimum(dr.minimum(a, b), c), dr.maximum(dr.maximum(a, b), c)
        x32, y32 = F(x), F(y)  # the nearest float32
        x32 = dr.select(F64(x32) > x, _next_float(x32, -1), x32)
        y32 = dr.select(F64(y32) < y, _next_float(y32, 1), y32)
        lo.append(dr.select(dr.abs(x32) < FLT_MIN, dr.select(x < 0, -FLT_MIN, 0.0), x32))
        hi.append(dr.select(dr.abs(y32) < FLT_MIN, dr.select(y > 0, FLT_MIN, 0.0), y32))
    lo, hi = jit.Array3f(*lo), jit.Array3f(*hi)
    dr.eval(lo, hi)
    return lo, hi


#: The smallest normal float32, 2^-126.
FLT_MIN = 2.0 ** -126


def _next_float(x, direction: int):
    """The float32 after x towards +inf (direction 1) or -inf (-1), x finite; from zero
    (which the conversion also gives for a subnormal) the smallest normal float32."""
    U = jit.UInt32
    bits = dr.reinterpret_array(U, x)
    away = dr.select(x > 0, direction > 0, direction < 0)  # away from zero: |x| grows
    step = dr.reinterpret_array(jit.Float, dr.select(away, bits + 1, bits - 1))
    return dr.select(x == 0, direction * FLT_MIN, step)


#: Nodes of at most this many triangles find their split in one SIMD lane each (loops
#: over their triangles into bins in local memory); larger ones are cut into chunks of
#: this many, each binned in a lane, and a node's bins are the sums of its chunks'. Both
#: ways give the same bins, so from 32 up (a smaller node uses fewer bins, which the
#: chunked path does not) the tree does not depend on it (all seven arrays compared,
#: knots of 14,400, 144,000 and 1,000,000 triangles; tests/tracer/test_bvh.py). On the CPU,
#: warm builds (a throwaway script, medians of 9, two rounds): 144,000 triangles 88-92 ms at 128,
#: 81-84 at 512, 80 at 1024, 75-78 at 4096; 1,000,000 triangles 484-528 ms at 128,
#: 424-434 at 4096; 14,400 triangles 34-36 ms at each.
CHUNK = 4096
#: The same on a GPU, where a lane that loops over 4,096 triangles would leave most of
#: the device idle (not measured: none was lent).
CHUNK_GPU = 128


def _chunk() -> int:
    """:data:`CHUNK` on the CPU, :data:`CHUNK_GPU` on a GPU."""
    return CHUNK_GPU if backend.name() == "cuda" else CHUNK


def _split_levels(lo, hi, bins, max_leaf, c_trav, c_isect):
    """The tree's topology, level by level, split on the device (Dr.Jit).

    Returns ``levels`` (one dict per level, numpy: node ids, children, boxes,
    and a leaf's start and count) and ``order`` (triangle ids, leaf after leaf
    in the order the leaves were made). Nodes are numbered level after level.

    Each pass splits every node of a level at once; the triangles of a node are
    contiguous and nodes are in order. A small node (:data:`CHUNK` triangles or
    fewer) is one SIMD lane: loops over its triangles give its box and centroid
    box, then its bins on all three axes (count and box, in local memory), then
    a sweep from the right and from the left per axis (Wald 2007, section 3.3)
    the cheapest split. A large node is cut into chunks, a lane each, whose
    boxes and bins are summed per node by a lane per node (or per node and bin)
    looping over its chunks, and swept the same way. No atomics: the build is
    deterministic. Then each triangle moves, by prefix sums (stable), to its
    place in ``order`` if its node became a leaf, or else into its child's range
    of the next level. Float32 throughout, from triangle boxes rounded outwards
    (:func:`_triangle_boxes`): a node's box, a union of those, holds its triangles.
    """
    F, U, B, A3 = jit.Float, jit.UInt32, jit.Bool, jit.Array3f
    n = dr.width(lo)
    nbmax = max(bins, 8)
    tid = dr.arange(U, n)
    seg = upload(U, np.zeros(n, np.uint32), np.uint32)  # memory, as later levels' (not 0)
    order = dr.zeros(U, n)
    dr.eval(lo, hi, tid, seg, order)
    h_cnt = np.array([n], np.int64)
    S, N, base, placed = 1, n, 0, 0
    chunk = _chunk()
    levels = []
    while True:
        # A basic block a level: value numbering then never merges a level's constants
        # with values alive from the levels before, which made the kernels of every level
        # differ and be compiled anew (bench_speed.py process, a cold kernel cache).
        backend.new_scope()
        h_first = np.cumsum(h_cnt) - h_cnt
        # A level's arrays on the device have two nodes at least (_padded): the root's
        # level gets an empty second node, first 0, no triangles, a leaf, dropped below.
        S_d = max(S, 2)
        cnt = upload(U, _padded(h_cnt, S_d), np.uint32)
        first = upload(U, _padded(h_first, S_d), np.uint32)
        nb = dr.select(cnt <= 8, U(4), dr.select(cnt <= 32, U(8), U(bins)))
        big = cnt > chunk
        dr.eval(nb, big)
        # Small nodes, a lane each: box, centroid box and cheapest split. Where every
        # node is large (the top levels), _large_nodes fills every entry: nothing to trace
        # (a large root's pad is small: the loop runs for it, a kernel the levels below use).
        h_big = np.flatnonzero(h_cnt > chunk)
        if len(h_big) < S_d:
            small = _small_nodes(lo, hi, first, cnt, nb, ~big, nbmax)
            # All seven results of the one loop in one kernel, whatever comes next: left
            # lazy, _large_nodes's scatters evaluated them one at a time (the loop traced,
            # compiled and run once for each), and the next level's leaf test folded them
            # into a kernel of its own (a cold build compiled four variants of the loop).
            dr.eval(*small)
            best, best_axis, best_bin, box_lo, box_hi, c_lo, c_hi = small
        else:
            best, best_axis, best_bin = (dr.full(F, dr.inf, S_d), dr.zeros(U, S_d),
                                         dr.zeros(U, S_d))
            box_lo, box_hi = dr.full(A3, dr.inf, S_d), dr.full(A3, -dr.inf, S_d)
            c_lo, c_hi = dr.full(A3, dr.inf, S_d), dr.full(A3, -dr.inf, S_d)
        if len(h_big):
            best, best_axis, best_bin, box_lo, box_hi, c_lo, c_hi = _large_nodes(
                lo, hi, h_first, h_cnt, h_big, nbmax, bins, chunk,
                (best, best_axis, best_bin, box_lo, box_hi, c_lo, c_hi))
        scale = _bin_scale(c_lo, c_hi, nb)

        # Leaves: at most max_leaf triangles and no split expected to be cheaper.
        area = _half_area_jit(box_lo, box_hi)
        split_cost = c_trav + c_isect * best / dr.select(area > 0, area, 1.0)
        no_sah = dr.isinf(best)  # all centroids in one bin: split the node's list in half
        leaf = (cnt <= max_leaf) & (no_sah | (c_isect * F(cnt) <= split_cost))
        leaf |= cnt < 2
        dr.eval(leaf, no_sah, c_lo, scale, best_axis, best_bin, box_lo, box_hi)
        h_leaf = leaf.numpy()[:S]
        split = ~h_leaf
        ns = int(np.count_nonzero(split))
        h_rank = np.cumsum(split) - split
        h_start = placed + np.cumsum(np.where(h_leaf, h_cnt, 0)) - np.where(h_leaf, h_cnt, 0)
        left = np.where(h_leaf, -1, base + S + 2 * h_rank)
        levels.append(dict(node=base + np.arange(S), left=left,
                           lo=backend.host3(box_lo)[:S], hi=backend.host3(box_hi)[:S],
                           right=np.where(h_leaf, -1, left + 1),
                           start=np.where(h_leaf, h_start, 0),
                           count=np.where(h_leaf, h_cnt, 0)))
        n_leaf = int(h_cnt[h_leaf].sum())
        placed += n_leaf

        # Each triangle: its rank r in its node; a leaf's go to order[start + r].
        r = dr.arange(U, N) - dr.gather(U, first, seg)
        t_leaf = dr.gather(B, leaf, seg)
        start = upload(U, _padded(h_start, S_d), np.uint32)
        dr.scatter(order, tid, dr.gather(U, start, seg, t_leaf) + r, t_leaf)
        if ns == 0:
            dr.eval(order)
            break
        # The others to the left or right child, keeping their order.
        ax = dr.gather(U, best_axis, seg)
        c = (lo + hi) * 0.5
        by_bin = _bin(_component(c, ax),
                      _component(A3(*(dr.gather(F, v, seg) for v in c_lo)), ax),
                      _component(A3(*(dr.gather(F, v, seg) for v in scale)), ax),
                      dr.gather(U, nb, seg)) <= dr.gather(U, best_bin, seg)
        half = r < dr.gather(U, cnt, seg) // 2
        last = first + dr.maximum(cnt, 1) - 1  # the empty pad reads its first, 0
        for attempt in range(2):
            go_left = dr.select(dr.gather(B, no_sah, seg), half, by_bin) & ~t_leaf
            lefts = dr.prefix_sum(dr.select(go_left, U(1), U(0)))  # before each triangle
            dr.eval(lefts, go_left, order)
            # Lefts of a node: those before its end less those before its start.
            n_left = (dr.gather(U, lefts, last)
                      + dr.select(dr.gather(B, go_left, last), U(1), U(0))
                      - dr.gather(U, lefts, first))
            h_nl = n_left.numpy()[:S].astype(np.int64)
            # A split that leaves a child empty would repeat forever; the binning and
            # this partition compute the same bins, but should they ever disagree, such
            # a node is split in half instead (never seen: a guard, not a path).
            empty = split & ((h_nl == 0) | (h_nl == h_cnt))
            if attempt or not empty.any():
                break
            no_sah = no_sah | B(_padded(empty, S_d))
        if empty.any():
            raise RuntimeError("BVH build: a split left a child empty")
        split_first = np.cumsum(np.where(split, h_cnt, 0)) - np.where(split, h_cnt, 0)
        l_before = lefts - dr.gather(U, lefts, dr.gather(U, first, seg))
        t_nl = dr.gather(U, n_left, seg)
        dest = (dr.gather(U, upload(U, _padded(split_first, S_d), np.uint32), seg)
                + dr.select(go_left, l_before, t_nl + r - l_before))
        new_seg = 2 * dr.gather(U, upload(U, _padded(h_rank, S_d), np.uint32), seg) + dr.select(
            go_left, U(0), U(1))
        keep = ~t_leaf
        N_next = N - n_leaf
        nxt = [dr.empty(type(v), N_next) for v in (tid, lo, hi, seg)]
        for src, dst in zip((tid, lo, hi, new_seg), nxt, strict=True):
            dr.scatter(dst, src, dest, keep)
        dr.eval(*nxt)
        tid, lo, hi, seg = nxt
        h_cnt = np.stack([h_nl[split], h_cnt[split] - h_nl[split]], axis=1).reshape(-1)
        base += S
        S, N = 2 * ns, N_next
    return levels, order.numpy().astype(np.int64)


def _padded(a: np.ndarray, n: int) -> np.ndarray:
    """``a`` with zeros (False) appended up to ``n`` entries: a node array for the device.

    Dr.Jit reads an array of one entry as a scalar (loaded once for every lane, a gather
    from it the value itself), so a level of one node, the root, traced kernels of its
    own: a cold build compiled a dozen kernels twice, and a small root compiled the small
    nodes' loop (the largest kernel) in a variant no other level shares (issue 33). With
    two entries at least, every level traces the same kernels.
    """
    if len(a) >= n:
        return a
    return np.concatenate([a, np.zeros(n - len(a), a.dtype)])


def _large_nodes(lo, hi, h_first, h_cnt, h_big, nbmax, bins, chunk, small):
    """Box, centroid box and cheapest split of the large nodes ``h_big`` (host indices).

    ``small`` holds the per-node results of :func:`_small_nodes` (valid for the
    other nodes); the large nodes' entries are replaced. The arrays of one entry a large
    node have two at least (:func:`_padded`): a level of one large node gets an empty
    second, no chunks, whose results are not written.
    """
    F, U, A3 = jit.Float, jit.UInt32, jit.Array3f
    m = len(h_big)
    m_d = max(m, 2)
    # Chunk k of a node of nc chunks holds its triangles k, k + nc, k + 2 nc, ...: the
    # lanes of a SIMD packet, consecutive chunks, then read consecutive triangles. A
    # large node has two chunks at least, so every chunk array has two entries too.
    nc = (h_cnt[h_big] + chunk - 1) // chunk  # chunks per large node (chunk: _chunk())
    ch_node = np.repeat(np.arange(len(h_big)), nc)
    ch_k = np.arange(len(ch_node)) - np.repeat(np.cumsum(nc) - nc, nc)
    ch_first = h_first[h_big][ch_node] + ch_k
    ch_stride = nc[ch_node]
    ch_cnt = (h_cnt[h_big][ch_node] - ch_k + ch_stride - 1) // ch_stride
    nc_d = _padded(nc, m_d)
    n_first = upload(U, np.cumsum(nc_d) - nc_d, np.uint32)  # a node's first chunk
    n_nc = upload(U, nc_d, np.uint32)
    cf, cc, cs = (upload(U, a, np.uint32) for a in (ch_first, ch_cnt, ch_stride))
    # Chunks' boxes, then each node's.
    k_lo, k_hi, k_clo, k_chi = _chunk_boxes(lo, hi, cf, cc, cs)
    dr.eval(k_lo, k_hi, k_clo, k_chi)
    b_lo, b_hi, c_lo, c_hi = _chunk_boxes(k_lo, k_hi, n_first, n_nc, centroids=(k_clo, k_chi))
    nb = U(bins)
    scale = _bin_scale(c_lo, c_hi, nb)
    dr.eval(b_lo, b_hi, c_lo, c_hi, scale)
    # Chunks' bins (3 axes x nbmax, in that order per chunk), then each node's.
    node = upload(U, ch_node, np.uint32)
    per = 3 * nbmax
    k_n, k_blo, k_bhi = _chunk_bins(lo, hi, cf, cc, cs, dr.gather(A3, c_lo, node),
                                    dr.gather(A3, scale, node), nb, nbmax)
    dr.eval(k_n, k_blo, k_bhi)
    q = dr.arange(U, m_d * per)
    n_bins, bl, bh = _sum_bin_chunks(q // per, q % per, n_first, n_nc, per, k_n, k_blo, k_bhi)
    dr.eval(n_bins, bl, bh)
    # The count of large nodes an input of the kernels, not a constant in them: the levels
    # then share their kernels (a cold build compiled them anew for each level, issue 33).
    m_in = dr.opaque(U, m_d)
    cnt = upload(U, _padded(h_cnt[h_big], m_d), np.uint32)
    best = dr.full(F, dr.inf, m_d)
    best_axis, best_bin = dr.zeros(U, m_d), dr.zeros(U, m_d)
    # The three axes' sweeps in one call, lane a m + i for axis a of node i.
    q = dr.arange(U, 3 * m_d)
    costs, ats = _sweep(n_bins, bl, bh, (q % m_in) * per + (q // m_in) * nbmax,
                        dr.full(U, bins, 3 * m_d), dr.gather(U, cnt, q % m_in))
    dr.eval(costs, ats)
    for a in range(3):
        cost = dr.gather(F, costs, dr.arange(U, m_d) + a * m_in)
        at = dr.gather(U, ats, dr.arange(U, m_d) + a * m_in)
        better = (scale[a] > 0) & (cost < best)
        best = dr.select(better, cost, best)
        best_axis = dr.select(better, U(a), best_axis)
        best_bin = dr.select(better, at, best_bin)
    out = list(small)
    idx = upload(U, _padded(h_big, m_d), np.uint32)
    real = dr.arange(U, m_d) < dr.opaque(U, m)  # not the pad
    for i, v in enumerate((best, best_axis, best_bin, b_lo, b_hi, c_lo, c_hi)):
        dr.scatter(out[i], v, idx, real)
    dr.eval(*out)
    return tuple(out)


def _chunk_boxes(lo, hi, first, cnt, stride=1, centroids=None):
    """Per chunk (a lane): the box and the centroid box of boxes first + j stride, j < cnt.

    The boxes are triangles' (their centroids are computed), or with
    ``centroids`` = (c_lo, c_hi) chunks' boxes and centroid boxes, whose unions
    give a node's.
    """
    A3, U = jit.Array3f, jit.UInt32
    S = dr.width(first)
    b_lo, b_hi = dr.full(A3, dr.inf, S), dr.full(A3, -dr.inf, S)
    c_lo, c_hi = dr.full(A3, dr.inf, S), dr.full(A3, -dr.inf, S)

    def body(b_hi, b_lo, c_hi, c_lo, j):
        k = first + j * stride
        tl = dr.gather(A3, lo, k)
        th = dr.gather(A3, hi, k)
        if centroids is None:
            cl = ch = (tl + th) * 0.5
        else:
            cl, ch = dr.gather(A3, centroids[0], k), dr.gather(A3, centroids[1], k)
        b_lo, b_hi = lesser(b_lo, tl), greater(b_hi, th)
        c_lo, c_hi = lesser(c_lo, cl), greater(c_hi, ch)
        return b_hi, b_lo, c_hi, c_lo, j + 1

    b_hi, b_lo, c_hi, c_lo, _ = dr.while_loop(
        (b_hi, b_lo, c_hi, c_lo, dr.zeros(U, S)), lambda *state: state[-1] < cnt, body,
        labels=("b_hi", "b_lo", "c_hi", "c_lo", "j"))
    return b_lo, b_hi, c_lo, c_hi


def _sum_bin_chunks(node, q, n_first, n_nc, per, k_n, k_blo, k_bhi):
    """Per (node, bin) (a lane): the count and box of the bin over the node's chunks."""
    A3, U = jit.Array3f, jit.UInt32
    S = dr.width(node)
    n = dr.zeros(U, S)
    b_lo, b_hi = dr.full(A3, dr.inf, S), dr.full(A3, -dr.inf, S)
    f = dr.gather(U, n_first, node)
    m = dr.gather(U, n_nc, node)

    def body(b_hi, b_lo, j, n):
        k = (f + j) * per + q
        n = n + dr.gather(U, k_n, k)
        b_lo = lesser(b_lo, dr.gather(A3, k_blo, k))
        b_hi = greater(b_hi, dr.gather(A3, k_bhi, k))
        return b_hi, b_lo, j + 1, n

    b_hi, b_lo, _, n = dr.while_loop((b_hi, b_lo, dr.zeros(U, S), n),
                                     lambda b_hi, b_lo, j, n: j < m, body,
                                     labels=("b_hi", "b_lo", "j", "n"))
    return n, b_lo, b_hi


def _chunk_bins(lo, hi, first, cnt, stride, c_lo, scale, nb, nbmax):
    """Per chunk (a lane): count and box of each bin of each axis, ``3 nbmax`` per chunk."""
    U, A3 = jit.UInt32, jit.Array3f
    S = dr.width(first)
    n_bin, lo_bin, hi_bin = _bin_triangles(lo, hi, first, cnt, stride, c_lo, scale, nb, nbmax,
                                           dr.full(jit.Bool, True, S))
    per = 3 * nbmax
    k_n = dr.empty(U, S * per)
    k_lo, k_hi = dr.empty(A3, S * per), dr.empty(A3, S * per)
    base = dr.arange(U, S) * per

    def body(hi_bin, i, k_hi, k_lo, k_n, lo_bin, n_bin):
        dr.scatter(k_n, n_bin[i], base + i)
        dr.scatter(k_lo, A3(lo_bin[0][i], lo_bin[1][i], lo_bin[2][i]), base + i)
        dr.scatter(k_hi, A3(hi_bin[0][i], hi_bin[1][i], hi_bin[2][i]), base + i)
        return hi_bin, i + 1, k_hi, k_lo, k_n, lo_bin, n_bin

    _, _, k_hi, k_lo, k_n, _, _ = dr.while_loop(
        (hi_bin, dr.zeros(U, S), k_hi, k_lo, k_n, lo_bin, n_bin),
        lambda hi_bin, i, *_: i < per, body,
        labels=("hi_bin", "i", "k_hi", "k_lo", "k_n", "lo_bin", "n_bin"))
    return k_n, k_lo, k_hi


def _bin_triangles(lo, hi, first, cnt, stride, c_lo, scale, nb, nbmax, active):
    """Bins of triangles first + j stride, j < cnt, in local memory: axis a, bin b at a nbmax + b.

    Returns (count, [box lo x, y, z], [box hi x, y, z]) as Dr.Jit local arrays.
    """
    F, U, A3 = jit.Float, jit.UInt32, jit.Array3f
    S = dr.width(first)
    n_bin = dr.alloc_local(U, 3 * nbmax, U(0))
    lo_bin = [dr.alloc_local(F, 3 * nbmax, F(dr.inf)) for _ in range(3)]
    hi_bin = [dr.alloc_local(F, 3 * nbmax, F(-dr.inf)) for _ in range(3)]

    def body(hi_bin, j, lo_bin, n_bin):
        k = first + j * stride
        tl = dr.gather(A3, lo, k)
        th = dr.gather(A3, hi, k)
        c = (tl + th) * 0.5
        for a in range(3):
            q = a * nbmax + _bin(c[a], c_lo[a], scale[a], nb)
            n_bin[q] = n_bin[q] + 1
            for m in range(3):
                lo_bin[m][q] = lesser(lo_bin[m][q], tl[m])
                hi_bin[m][q] = greater(hi_bin[m][q], th[m])
        return hi_bin, j + 1, lo_bin, n_bin

    hi_bin, _, lo_bin, n_bin = dr.while_loop(
        (hi_bin, dr.zeros(U, S), lo_bin, n_bin),
        lambda hi_bin, j, *_: active & (j < cnt), body,
        labels=("hi_bin", "j", "lo_bin", "n_bin"))
    return n_bin, lo_bin, hi_bin


def _small_nodes(lo, hi, first, cnt, nb, active, nbmax):
    """Per small node (a lane each, where ``active``): its box, centroid box and cheapest split.

    Returns (cost, axis, last left bin, box lo, box hi, centroid lo, centroid
    hi); cost as :func:`_sweep`'s, inf where no axis splits (and for the
    inactive lanes).
    """
    F, U, A3 = jit.Float, jit.UInt32, jit.Array3f
    S = dr.width(first)
    b_lo, b_hi, c_lo, c_hi = _chunk_boxes(lo, hi, first, dr.select(active, cnt, 0))
    scale = _bin_scale(c_lo, c_hi, nb)
    n_bin, lo_bin, hi_bin = _bin_triangles(lo, hi, first, cnt, 1, c_lo, scale, nb, nbmax, active)
    best, best_axis, best_bin = dr.full(F, dr.inf, S), dr.zeros(U, S), dr.zeros(U, S)
    right = dr.alloc_local(F, nbmax, F(0))
    names = ("hi_bin", "i", "lo_bin", "n_bin", "right", "run_hi", "run_lo", "run_n")
    for a in range(3):
        def from_right(hi_bin, i, lo_bin, n_bin, right, run_hi, run_lo, run_n, a=a):
            q = a * nbmax + i
            run_lo = lesser(run_lo, A3(lo_bin[0][q], lo_bin[1][q], lo_bin[2][q]))
            run_hi = greater(run_hi, A3(hi_bin[0][q], hi_bin[1][q], hi_bin[2][q]))
            run_n = run_n + n_bin[q]
            right[i] = _half_area_jit(run_lo, run_hi) * F(run_n)
            return hi_bin, i - 1, lo_bin, n_bin, right, run_hi, run_lo, run_n

        hi_bin, _, lo_bin, n_bin, right, *_ = dr.while_loop(
            (hi_bin, nb - 1, lo_bin, n_bin, right, dr.full(A3, -dr.inf, S),
             dr.full(A3, dr.inf, S), dr.zeros(U, S)),
            lambda hi_bin, i, *_: active & (i > 0), from_right, labels=names)

        def from_left(best, best_axis, best_bin, hi_bin, i, lo_bin, n_bin, right, run_hi,
                      run_lo, run_n, a=a):
            q = a * nbmax + i
            run_lo = lesser(run_lo, A3(lo_bin[0][q], lo_bin[1][q], lo_bin[2][q]))
            run_hi = greater(run_hi, A3(hi_bin[0][q], hi_bin[1][q], hi_bin[2][q]))
            run_n = run_n + n_bin[q]
            cost = _half_area_jit(run_lo, run_hi) * F(run_n) + right[i + 1]
            better = (scale[a] > 0) & (run_n > 0) & (run_n < cnt) & (cost < best)
            best = dr.select(better, cost, best)
            best_axis = dr.select(better, U(a), best_axis)
            best_bin = dr.select(better, i, best_bin)
            return (best, best_axis, best_bin, hi_bin, i + 1, lo_bin, n_bin, right, run_hi,
                    run_lo, run_n)

        best, best_axis, best_bin, hi_bin, _, lo_bin, n_bin, right, *_ = dr.while_loop(
            (best, best_axis, best_bin, hi_bin, dr.zeros(U, S), lo_bin, n_bin, right,
             dr.full(A3, -dr.inf, S), dr.full(A3, dr.inf, S), dr.zeros(U, S)),
            lambda best, best_axis, best_bin, hi_bin, i, *_: active & (i + 1 < nb),
            from_left, labels=("best", "best_axis", "best_bin", *names))
    return best, best_axis, best_bin, b_lo, b_hi, c_lo, c_hi


def _sweep(b_cnt, b_lo, b_hi, off, nb, cnt):
    """Per node, the cheapest binned split along one axis: (A_L n_L + A_R n_R, last left bin).

    The node's bins are b_*[off : off + nb]; the cost is inf where no split
    leaves triangles on both sides. First from the right: the box and count of
    bins i..nb-1, stored per bin; then from the left, adding bins 0..i.
    """
    F, U, A3 = jit.Float, jit.UInt32, jit.Array3f
    S = dr.width(off)
    right = dr.zeros(F, dr.width(b_cnt))
    names = ("i", "right", "run_hi", "run_lo", "run_n")

    def from_right(i, right, run_hi, run_lo, run_n):
        k = off + i
        run_lo = lesser(run_lo, dr.gather(A3, b_lo, k))
        run_hi = greater(run_hi, dr.gather(A3, b_hi, k))
        run_n = run_n + dr.gather(U, b_cnt, k)
        dr.scatter(right, _half_area_jit(run_lo, run_hi) * F(run_n), k)
        return i - 1, right, run_hi, run_lo, run_n

    _, right, *_ = dr.while_loop(
        (nb - 1, right, dr.full(A3, -dr.inf, S), dr.full(A3, dr.inf, S), dr.zeros(U, S)),
        lambda i, *_: (nb > 0) & (i > 0),  # nb = 0: a node not binned here
        from_right, labels=names)
    dr.eval(right)

    def from_left(at, best, i, right, run_hi, run_lo, run_n):
        k = off + i
        run_lo = lesser(run_lo, dr.gather(A3, b_lo, k))
        run_hi = greater(run_hi, dr.gather(A3, b_hi, k))
        run_n = run_n + dr.gather(U, b_cnt, k)
        cost = _half_area_jit(run_lo, run_hi) * F(run_n) + dr.gather(F, right, k + 1)
        better = (run_n > 0) & (run_n < cnt) & (cost < best)
        best = dr.select(better, cost, best)
        at = dr.select(better, i, at)
        return at, best, i + 1, right, run_hi, run_lo, run_n

    at, best, *_ = dr.while_loop(
        (dr.zeros(U, S), dr.full(F, dr.inf, S), dr.zeros(U, S), right,
         dr.full(A3, -dr.inf, S), dr.full(A3, dr.inf, S), dr.zeros(U, S)),
        lambda at, best, i, *_: i + 1 < nb, from_left, labels=("at", "best", *names))
    return best, at


def _depth_first(levels, order):
    """Renumber the nodes (built level by level) in depth-first order, left child first.

    Depth-first order puts a node's subtree in one block of memory, and the
    triangles of its leaves too, which the traversal reads with fewer cache
    misses than level order. The nodes of a level are the children of the
    previous level's inner nodes, two by two in order (:func:`_split_levels`),
    so both passes below work on slices of whole levels.
    """
    # Subtree sizes, bottom-up.
    sizes = [None] * len(levels)
    below = None
    for k in range(len(levels) - 1, -1, -1):
        inner = levels[k]["left"] >= 0
        size = np.ones(len(inner), np.int64)
        if below is not None:
            size[inner] += below[0::2] + below[1::2]
        sizes[k] = below = size
    # New indices, top-down: left child right after its parent, then the right subtree.
    news = [np.zeros(1, np.int64)]
    for k in range(len(levels) - 1):
        p = news[k][levels[k]["left"] >= 0] + 1
        child = np.empty(2 * len(p), np.int64)
        child[0::2] = p
        child[1::2] = p + sizes[k + 1][0::2]
        news.append(child)
    new = np.concatenate(news)
    inv = np.empty_like(new)
    inv[new] = np.arange(len(new))  # the old index of each new position
    # np.take rather than fancy indexing: about 2.5x faster on the knot's 625,779 nodes
    out = {key: np.take(np.concatenate([lv[key] for lv in levels]), inv, axis=0)
           for key in ("lo", "hi", "left", "right", "start", "count")}
    inner = out["left"] >= 0
    out["left"][inner] = new[out["left"][inner]]
    out["right"][inner] = new[out["right"][inner]]
    # Triangles leaf after leaf in depth-first order.
    leaves = np.flatnonzero(~inner)
    counts = out["count"][leaves]
    src = np.repeat(out["start"][leaves] - (np.cumsum(counts) - counts), counts)
    order = np.take(order, src + np.arange(len(src)))
    out["start"][leaves] = np.cumsum(counts) - counts
    return (out["lo"], out["hi"], out["left"], out["right"], out["start"], out["count"], order)


def pack_nodes(b: BVHArrays) -> tuple[np.ndarray, int, int]:
    """(records, root reference, stack size) of the traversal layout.

    One record of 16 float32 per inner node: the boxes of its two children as
    lo.x lo.y lo.z of the left, the same of the right, hi of the left, hi of
    the right, then the two child references (uint32 bits) and two unused
    slots: 64 bytes, one cache line once aligned (:func:`tracer.backend.upload`). Inner
    nodes keep their depth-first order, so a parent and its left child are
    neighbours in memory. Boxes are rounded outwards to float32 and widened by
    2^-20 of their largest coordinate, more than the float32 rounding of the
    corners. :func:`tracer.shapes.triangle.intersect` works in the ray's
    sheared space and may take a ray a few roundings of the ray's length
    beside its triangle; the widening of t_far in the slab test covers that
    (tests/tracer/test_watertight.py aims rays from far away at edges on box faces).

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
    rec = aligned_zeros((len(inner), 16), np.float32)   # uploaded without a copy
    ln, rn = b.left[inner], b.right[inner]
    rec[:, 0:3], rec[:, 3:6] = np.take(lo, ln, axis=0), np.take(lo, rn, axis=0)
    rec[:, 6:9], rec[:, 9:12] = np.take(hi, ln, axis=0), np.take(hi, rn, axis=0)
    rec[:, 12] = np.take(ref, ln).view(np.float32)
    rec[:, 13] = np.take(ref, rn).view(np.float32)
    root = int(ref[0]) if len(ref) else INVALID
    return rec, root, b.depth + 1


def _triangle_records(perm, corners) -> object:
    """jit.Float records of 16 floats, one a triangle in leaf order (``perm``: the
    original index of each): its corners p0, p1, p2, then 7 zeros.

    The corners are rounded once to float32, as tracer.geometry stores them: a vertex
    shared by two triangles is the same float32 point in both (the watertight test
    relies on it), and both modules give the same numbers. The records are gathered
    and written by one small kernel: numpy wrote a row of three numbers at a time into
    the 64-byte records, 40 ms for the 1,000,000-triangle knot, where the kernel and the
    corners' upload take about 10 ms (issue 33; a throwaway script)."""
    if len(corners[0]) == 0:
        return upload(jit.Float, np.zeros(0), np.float32)
    flats = [upload(jit.Float, p, np.float32) for p in corners]   # x y z of corner k
    i = dr.arange(jit.UInt32, 16 * dr.width(perm))   # record i >> 4, slot i & 15
    slot = i & 15
    k = slot // 3                       # the corner; 3 to 5 for the unused slots
    at = dr.gather(jit.UInt32, perm, i >> 4) * 3 + (slot - 3 * k)
    tris = dr.zeros(jit.Float, dr.width(i))
    for corner, flat in enumerate(flats):
        here = k == corner
        tris = dr.select(here, dr.gather(jit.Float, flat, at, here), tris)
    dr.eval(tris)   # one kernel; a scatter a slot would be one kernel each
    return tris


def _mesh_records(perm, p, faces) -> object:
    """:func:`_triangle_records` of the triangles of a mesh as uploaded: ``p`` its
    vertices (jit.Array3f, float32), ``faces`` three vertex indices a triangle
    (jit.UInt32). The same numbers bit for bit, since a vertex rounded to float32 once
    is the corner rounded to float32; gathered by one kernel from arrays the mesh
    uploads anyway, where the corners' way gathers (N, 3) float64 corners on the host
    and uploads them (issue 33)."""
    if dr.width(perm) == 0:
        return upload(jit.Float, np.zeros(0), np.float32)
    i = dr.arange(jit.UInt32, 16 * dr.width(perm))   # record i >> 4, slot i & 15
    slot = i & 15
    k = slot // 3                       # the corner; 3 to 5 for the unused slots
    axis = slot - 3 * k
    used = k < 3
    vertex = dr.gather(jit.UInt32, faces, dr.gather(jit.UInt32, perm, i >> 4) * 3 + k, used)
    tris = dr.zeros(jit.Float, dr.width(i))
    for a in range(3):
        here = used & (axis == a)
        tris = dr.select(here, dr.gather(jit.Float, p[a], vertex, here), tris)
    dr.eval(tris)
    return tris


def _outward(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """float32 boxes that contain the float64 ones, widened as :func:`pack_nodes` says.

    The padded corner is rounded to the nearest float32, then moved one float32 outwards
    where that rounding went inwards past the unpadded corner. Written column by column
    and with the step taken only where it is needed: the 1,000,000-triangle knot's
    625,779 boxes in about 9 ms rather than 39 ms with ``max(axis=1)`` and
    ``np.nextafter`` over every number, bit for bit the same boxes (issue 33)."""
    a = np.abs(lo)
    np.maximum(a, np.abs(hi), out=a)
    pad = np.maximum(np.maximum(a[:, 0], a[:, 1]), a[:, 2])
    pad *= 2.0**-20
    pad += 1e-30
    pad = pad[:, None]
    out = []
    for corner, padded, inward, towards in ((lo, lo - pad, np.greater, -np.inf),
                                            (hi, hi + pad, np.less, np.inf)):
        c32 = padded.astype(np.float32)
        step = np.flatnonzero(inward(c32, corner))
        if len(step):
            flat = c32.reshape(-1)
            flat[step] = np.nextafter(flat[step], np.float32(towards))
        out.append(c32)
    return out[0], out[1]


class BVH:
    """A BVH over triangles, uploaded to Dr.Jit, answering closest-hit and occlusion queries.

    Parameters
    ----------
    p0, p1, p2 : (N, 3) world-space triangle corners (float64 or anything numpy reads).
    arrays : a tree already built over these triangles (:func:`shared_bvh` reads one
        from its disk cache), else one is built.
    **build_options : passed to :func:`build_bvh`.

    Attributes
    ----------
    arrays : the :class:`BVHArrays` of the build.
    build_seconds : time of :func:`build_bvh` (not the upload of the records).
    node_count : nodes of the tree, leaves included.
    triangle_count : triangles.
    depth : levels below the root; the traversal stack has one entry more.
    perm : jit.UInt32 original index of each triangle in leaf order.
    nodes : jit.Float inner-node records (:func:`pack_nodes`).
    tris : jit.Float triangle records in leaf order, 16 floats each:
        p0 (3), p1 (3), p2 (3), unused (7).
    """

    def __init__(self, p0: np.ndarray, p1: np.ndarray, p2: np.ndarray, *,
                 arrays: BVHArrays | None = None, **build_options):
        p0, p1, p2 = (np.asarray(p, dtype=np.float64).reshape(-1, 3) for p in (p0, p1, p2))
        self._place(arrays if arrays is not None else build_bvh(p0, p1, p2, **build_options),
                    len(p0))
        self.tris = _triangle_records(self.perm, (p0, p1, p2))

    @classmethod
    def from_records(cls, arrays: BVHArrays, count: int, records) -> BVH:
        """The BVH of the tree ``arrays`` over ``count`` triangles whose records
        ``records(perm)`` gives (:func:`_triangle_records`' records, in the order of
        ``perm``, a jit.UInt32): for triangles a caller holds on the device already
        (:func:`shared_mesh_bvh`)."""
        bvh = cls.__new__(cls)
        bvh._place(arrays, count)
        bvh.tris = records(bvh.perm)
        return bvh

    def _place(self, arrays: BVHArrays, count: int) -> None:
        """Everything but the triangle records: the tree's nodes packed and uploaded."""
        self.arrays = arrays
        self.build_seconds = arrays.seconds
        self.node_count = len(arrays.left)
        self.triangle_count = count
        self.depth = arrays.depth
        rec, self._root, self._stack = pack_nodes(arrays)
        # Records start on a 64-byte boundary (backend.upload), so that a record of 16
        # floats fills one cache line instead of straddling two (measured: 1.7x faster
        # traversal than a random alignment).
        self.nodes = upload(jit.Float, rec if len(rec) else np.zeros((1, 16)), np.float32)
        self.perm = upload(jit.UInt32, arrays.order, np.uint32)

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
        return self._trace([(o, d, tmax, active)], shadow=False)[0]

    def occluded(self, o: jit.Array3f, d: jit.Array3f, tmax: jit.Float | float,
                 active: jit.Bool | bool = True) -> jit.Bool:
        """jit.Bool: some triangle lies on the ray at 0 < t < tmax (found as soon as any is)."""
        return self.occluded_group([(o, d, tmax, active)])[0]

    def closest_hit_group(self, rays: list) -> list:
        """:meth:`closest_hit` of K rays a lane: ``rays`` is a list of K (o, d, tmax,
        active), all of one width; the answer is a list of K (t, tri, beta, gamma).

        The K rays of a lane walk the tree together, as a packet (Wald, Slusallek,
        Benthin and Wagner, "Interactive Rendering with Coherent Ray Tracing",
        Eurographics 2001): each node is read once for the K rays and entered if
        any of them enters it, and each triangle of a leaf so reached is read once
        and tested against all K. Every ray still visits every node its own walk
        would, so each answer is the nearest hit, as :meth:`closest_hit` finds it
        (where two triangles meet a ray at the same t, as at a shared edge, either
        may be reported). The gain is in reads: a node step costs the CPU mostly
        the reads of its record, once per lane, while the slab tests are cheap
        vector arithmetic. Rays of one lane should be alike (samples of one
        pixel, their shadow rays to one light), or the packet visits the union of
        very different walks.
        """
        return self._trace(rays, shadow=False)

    def occluded_group(self, rays: list) -> list:
        """:meth:`occluded` of K rays a lane (see :meth:`closest_hit_group`): a list of
        K jit.Bool. The packet stops when each of its rays is blocked or done."""
        return [tri != INVALID for _, tri, _, _ in self._trace(rays, shadow=True)]

    # ---------------------------------------------------------------- traversal

    def _trace(self, rays, shadow):
        rays = [(jit.Array3f(o), jit.Array3f(d), tmax, active) for o, d, tmax, active in rays]
        n = max(max(dr.width(o), dr.width(d), dr.width(tmax), dr.width(a))
                for o, d, tmax, a in rays)
        ts = [jit.Float(tmax) + dr.zeros(jit.Float, n) for _, _, tmax, _ in rays]
        acts = [jit.Bool(a) | dr.zeros(jit.Bool, n) for _, _, _, a in rays]
        if self.triangle_count == 0:
            z = dr.zeros(jit.Float, n)
            return [(t, dr.full(jit.UInt32, INVALID, n), z, z) for t in ts]
        out = self._loop([o for o, _, _, _ in rays], [d for _, d, _, _ in rays], ts, acts,
                         shadow)
        # Back to the caller's triangle numbering.
        res = []
        for t, tri, beta, gamma in out:
            found = tri != INVALID
            orig = dr.gather(jit.UInt32, self.perm, tri, found)
            res.append((t, dr.select(found, orig, INVALID), beta, gamma))
        return res

    def _loop(self, os, ds, ts, acts, shadow):
        """The traversal of K rays a lane, "while-while" in the words of Aila and Laine
        (2009).

        Each pass of the outer loop walks inner nodes until the lane stands at a
        leaf, then tests the leaf's triangles, then pops the next deferred node.
        Dr.Jit runs a loop for a packet of lanes (16 on a CPU with AVX-512, a warp
        on a GPU) until all of them are done with it, so keeping the node steps and
        the triangle tests in separate loops lets the lanes of a packet do the same
        kind of work at the same time. With K = 1 a lane is one ray; with K > 1,
        ``acts`` says which rays still take part (a shadow ray leaves when blocked).

        The loops are ``drjit.while_loop`` calls (docs/extending.md, "Loops"): the same
        kernel, hash for hash, as the ``while`` statements that ``drjit.syntax`` turned
        into them, without parsing and recompiling this function's source in every
        process (about 10 ms).
        """
        K = len(os)
        n = dr.width(ts[0])
        invs = [inverse_direction(d) for d in ds]
        # The triangle test's per-ray part, once per ray.
        rss = [tri_f.ray_space(os[k], ds[k]) for k in range(K)]
        tris = [dr.full(jit.UInt32, INVALID, n) for _ in range(K)]
        betas = [dr.zeros(jit.Float, n) for _ in range(K)]
        gammas = [dr.zeros(jit.Float, n) for _ in range(K)]
        alive = any_mask(acts)
        if K == 1:
            acts = None  # alive is the one ray's state
        node = dr.full(jit.UInt32, self._root, n)
        sp = dr.zeros(jit.UInt32, n)
        # Initialised although never read before written: with an uninitialised
        # buffer, LLVM may treat the old contents in Dr.Jit's masked
        # read-modify-write of a slot as undefined and store all 16 lanes,
        # overwriting other rays' deferred nodes (seen as random crashes).
        stack = dr.alloc_local(jit.UInt32, self._stack, jit.UInt32(0))
        nodes, tri_data = self.nodes, self.tris

        def walk(acts, alive, betas, gammas, node, sp, stack, tris, ts):
            # Inner nodes, until this lane stands at a leaf or has nothing left to visit.
            def at_inner(acts, alive, node, sp, stack, ts):
                return alive & ((node & LEAF_FLAG) == 0)

            def step(acts, alive, node, sp, stack, ts):
                node, sp, alive = inner_step(nodes, node, sp, stack, alive, os, invs, ts,
                                             shadow, acts)
                return acts, alive, node, sp, stack, ts

            acts, alive, node, sp, stack, ts = dr.while_loop(
                (acts, alive, node, sp, stack, ts), at_inner, step,
                labels=("acts", "alive", "node", "sp", "stack", "ts"))

            # The leaf's triangles, one after the other.
            def in_leaf(acts, alive, betas, end, gammas, i, tris, ts):
                return alive & (i < end)

            def test(acts, alive, betas, end, gammas, i, tris, ts):
                # Floats 0-7 of the record in one packet gather, float 8 alone: gathering
                # all 16 (two packets) for the nine used took the camera rays of the
                # knot from 72.5 to 69-71 ms (a throwaway script, medians of 7).
                at = alive & (i < end)
                q = [*dr.gather(jit.ArrayXf, tri_data, i * 2, at, shape=(8, n)),
                     dr.gather(jit.Float, tri_data, i * 16 + 8, at)]
                p0 = jit.Array3f(q[0], q[1], q[2])
                p1 = jit.Array3f(q[3], q[4], q[5])
                p2 = jit.Array3f(q[6], q[7], q[8])
                for k in range(K):
                    tk, hk, bk, gk = tri_f.intersect(os[k], ds[k], p0, p1, p2, ts[k], rss[k])
                    hk = hk & (at if acts is None else at & acts[k])
                    ts[k] = dr.select(hk, tk, ts[k])
                    tris[k] = dr.select(hk, i, tris[k])
                    betas[k] = dr.select(hk, bk, betas[k])
                    gammas[k] = dr.select(hk, gk, gammas[k])
                    if shadow and acts is not None:
                        acts[k] = acts[k] & ~hk   # blocked: done
                i += 1
                if shadow:  # any hit will do
                    i = dr.select(hk if acts is None else ~any_mask(acts), end, i)
                return acts, alive, betas, end, gammas, i, tris, ts

            i = (node & (LEAF_FLAG - 1)) >> COUNT_BITS
            end = i + (node & ((1 << COUNT_BITS) - 1))
            acts, alive, betas, end, gammas, i, tris, ts = dr.while_loop(
                (acts, alive, betas, end, gammas, i, tris, ts), in_leaf, test,
                labels=("acts", "alive", "betas", "end", "gammas", "i", "tris", "ts"))

            pop = alive & (sp > 0)
            if shadow:
                pop &= (tris[0] == INVALID) if acts is None else any_mask(acts)
            sp = dr.select(pop, sp - 1, sp)
            node = dr.select(pop, stack.read(sp, pop), node)
            alive &= pop
            return acts, alive, betas, gammas, node, sp, stack, tris, ts

        acts, alive, betas, gammas, node, sp, stack, tris, ts = dr.while_loop(
            (acts, alive, betas, gammas, node, sp, stack, tris, ts),
            lambda acts, alive, *_: alive, walk,
            labels=("acts", "alive", "betas", "gammas", "node", "sp", "stack", "tris", "ts"))
        return list(zip(ts, tris, betas, gammas, strict=True))


def inverse_direction(d):
    """1 / d for the slab test (:func:`_slab`), per ray: a zero component becomes a tiny
    one of the same sign, so that (l - o) / d is +-huge rather than the NaN of 0 * inf."""
    tiny = 1e-30
    return 1.0 / jit.Array3f(*(dr.select(dr.abs(d[k]) < tiny, dr.copysign(tiny, d[k]), d[k])
                               for k in range(3)))


def inner_step(nodes, node, sp, stack, alive, os, invs, ts, far_first=False, acts=None):
    """One step of a lane at an inner node: (node, sp, alive) after it.

    ``os``, ``invs`` and ``ts`` are lists of the lane's K rays' origins, inverse
    directions (:func:`inverse_direction`) and nearest hits so far; ``acts``
    (K > 1) says which of them take part. The node's two child boxes
    (:func:`pack_nodes`) are tested with the slab test, for each ray; the lane
    enters a child if one of its rays does, goes on to the nearer child it
    enters (the farther with ``far_first``; as the first ray sees them), deferring
    the other on its ``stack`` (a Dr.Jit local array, ``sp`` its fill), or,
    entering neither, pops the node deferred last, or ends (``alive`` false).
    Lanes where ``alive`` is false or ``node`` is a leaf keep their state. Used by
    :class:`BVH` and by the instance hierarchy of :mod:`tracer.geometry`.
    """
    n = dr.width(ts[0])
    # Memory accesses carry the loop's condition as an explicit mask: lanes that wait (at a
    # leaf, or done) run the body too, with stale indices.
    step = alive & ((node & LEAF_FLAG) == 0)
    # The 14 floats used: 0-7 in one packet gather (16 loads of 8 floats and a transpose,
    # whose shuffles and pointer extractions share one port of the CPU), 8-13 in six
    # plain gathers (16 loads each, on the load ports). Two packets (all 16 floats) kept
    # the shuffle port the busiest; 14 plain gathers the load ports. The mix: the knot's
    # shadow rays 96.6-101 to 88.6-89.3 ms, its camera rays 73.3-73.7 to 65.2-66.9 ms
    # (a throwaway script tracing them alone, medians of 7, two runs); a packet of 8, one
    # of 4 and two plain gathers, or one of 4 and ten plain gathers, were no faster than
    # two packets.
    r = [*dr.gather(jit.ArrayXf, nodes, node * 2, step, shape=(8, n)),
         *(dr.gather(jit.Float, nodes, node * 16 + k, step) for k in range(8, 14))]
    # Entered before the nearest hit so far, and not only behind the origin. Widening
    # t_far makes the float32 slab test conservative (Pharr, Jakob and Humphreys,
    # "Physically Based Rendering", 3rd ed., section 3.9.2).
    widen = 1 + 2 * GAMMA3
    hit_l, hit_r, tn_l0, tn_r0 = step, step, None, None
    for k in range(len(os)):
        o, inv, t = os[k], invs[k], ts[k]
        tn_l, tf_l = _slab(o, inv, r[0], r[1], r[2], r[6], r[7], r[8])
        tn_r, tf_r = _slab(o, inv, r[3], r[4], r[5], r[9], r[10], r[11])
        hl = (tn_l <= tf_l * widen) & (tf_l > 0) & (tn_l < t)
        hr = (tn_r <= tf_r * widen) & (tf_r > 0) & (tn_r < t)
        if acts is not None:
            hl, hr = hl & acts[k], hr & acts[k]
        if k == 0:
            hit_l, hit_r, tn_l0, tn_r0 = step & hl, step & hr, tn_l, tn_r
        else:
            hit_l, hit_r = hit_l | (step & hl), hit_r | (step & hr)
    ref_l = dr.reinterpret_array(jit.UInt32, r[12])
    ref_r = dr.reinterpret_array(jit.UInt32, r[13])
    # Both entered: go on with the nearer, defer the other. With ``far_first`` (a
    # shadow ray, which needs any hit, not the nearest), the farther: a shadow ray
    # starts on a surface, inside the boxes of the triangles around its origin, which
    # seldom block it, while what blocks it lies further along. The knot's render
    # (bench_mesh.py's scene) 0.257 s to 0.238-0.240 s (a throwaway script, medians of
    # 7, alternating); an unblocked ray visits the same nodes in either order.
    r_first = (tn_r0 >= tn_l0) if far_first else (tn_r0 < tn_l0)
    near = dr.select(hit_l & ~(hit_r & r_first), ref_l, ref_r)
    both = hit_l & hit_r
    # In a branch that a SIMD packet where no ray defers a node skips (with the write
    # unconditional, each step paid for Dr.Jit's test of whether the packet's stack
    # pointers agree, a dozen shuffles): the knot's shadow rays 95.2 to 92.7 ms (a
    # throwaway script, medians of 7, two runs).
    def push(both, r_first, ref_l, ref_r, sp, stack):
        stack.write(dr.select(r_first, ref_l, ref_r), sp, both)
        return both, r_first, ref_l, ref_r, sp, stack

    names = ("both", "r_first", "ref_l", "ref_r", "sp", "stack")
    *_, stack = dr.if_stmt((both, r_first, ref_l, ref_r, sp, stack), both, push,
                           lambda *state: state, arg_labels=names, rv_labels=names)
    sp = dr.select(both, sp + 1, sp)
    # Neither: the deferred node pushed last, or the end of the ray.
    descend = hit_l | hit_r
    pop = step & ~descend & (sp > 0)
    sp = dr.select(pop, sp - 1, sp)
    node = dr.select(descend, near, node)
    # The pop in a branch too (a ray pops or descends, never both): the knot's shadow rays
    # 88.5-93.5 to 80.4-84.9 ms, its camera rays 67.7-70.6 to 60.0-64.3 ms (a throwaway
    # script, medians of 7, four runs).
    def read(node, pop, sp, stack):
        return dr.select(pop, stack.read(sp, pop), node), pop, sp, stack

    names = ("node", "pop", "sp", "stack")
    node, *_ = dr.if_stmt((node, pop, sp, stack), pop, read, lambda *state: state,
                          arg_labels=names, rv_labels=names)
    alive &= ~step | descend | pop
    return node, sp, alive


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
    # No t is NaN (inv is finite, the boxes and origins are finite), so the selects of
    # backend.lesser/greater give the same t_near and t_far as drjit.minimum/maximum.
    tn = greater(greater(lesser(t0x, t1x), lesser(t0y, t1y)), lesser(t0z, t1z))
    tf = lesser(lesser(greater(t0x, t1x), greater(t0y, t1y)), greater(t0z, t1z))
    return tn, tf


#: The BVHs built last, by content (see :func:`shared_bvh`), newest last.
_RECENT: OrderedDict = OrderedDict()
#: How many :func:`shared_bvh` keeps, and the largest mesh it keeps one of (triangles).
RECENT_COUNT = 4
RECENT_MAX_TRIANGLES = 1 << 18


def shared_bvh(p0: np.ndarray, p1: np.ndarray, p2: np.ndarray, key: str | None = None
               ) -> BVH:
    """``BVH(p0, p1, p2)``, or the one built for the same triangles a little earlier.

    A process that builds one scene many times, as the formula-bug sweep does (a build
    for each of the 17 bugs that reach the mesh_knot scene), builds each tree once.
    A BVH is never changed after its build, so the tree is shared as it is. Kept: the
    last RECENT_COUNT trees of at most RECENT_MAX_TRIANGLES triangles, by the corners'
    key (below) and the backend. Its ``build_seconds`` stay those of its build.
    Trees of :data:`DISK_MIN_TRIANGLES` triangles or more are also kept on disk
    (:func:`_kept_on_disk`), for the next process.

    The corners' key is a SHA-256 of them, or ``key``, where the caller has a hash of
    what determines them (a mesh's placed file, or :func:`tracer.cache.content_key` of its
    vertices and faces: :func:`tracer.shapes.mesh._tree`, which comes through
    :func:`shared_mesh_bvh`); different corners must never share a key.
    """
    from whitted.tracer.cache import content_key

    p0, p1, p2 = (np.ascontiguousarray(p, dtype=np.float64).reshape(-1, 3)
                  for p in (p0, p1, p2))
    # one key of the corners serves both caches
    return _shared(_Triangles(len(p0), lambda: (p0, p1, p2),
                              lambda perm: _triangle_records(perm, (p0, p1, p2))),
                   content_key(p0, p1, p2) if key is None else key)


def shared_mesh_bvh(vertices: np.ndarray, faces: np.ndarray, key: str, p, face_ids) -> BVH:
    """:func:`shared_bvh` of a mesh's triangles ``vertices[faces[:, k]]`` (k = 0, 1, 2),
    under ``key`` (their corners' key, as there), whose vertices and faces the caller
    has uploaded (``p``, jit.Array3f; ``face_ids``, jit.UInt32, three a triangle). The
    float64 corners are gathered only where a tree is built; the records come from the
    uploads (:func:`_mesh_records`)."""
    faces = np.asarray(faces).reshape(-1, 3)
    return _shared(_Triangles(len(faces),
                              lambda: tuple(np.take(vertices, faces[:, k], axis=0)
                                            for k in range(3)),
                              lambda perm: _mesh_records(perm, p, face_ids)), key)


@dataclass
class _Triangles:
    """The triangles of a tree: how many, their corners (p0, p1, p2), each (N, 3) float64,
    asked for only to build a tree, and their records in the order of a permutation."""
    count: int
    corners: object   # () -> (p0, p1, p2)
    records: object   # perm (jit.UInt32) -> jit.Float, as _triangle_records


def _shared(tris: _Triangles, key: str) -> BVH:
    """:func:`shared_bvh`'s two caches, the corners' ``key`` given."""
    if tris.count > RECENT_MAX_TRIANGLES:
        return _kept_on_disk(tris, key)
    recent = (backend.name(), key)
    if recent in _RECENT:
        _RECENT.move_to_end(recent)
        return _RECENT[recent]
    bvh = _RECENT[recent] = _kept_on_disk(tris, key)
    while len(_RECENT) > RECENT_COUNT:
        _RECENT.popitem(last=False)
    return bvh


# ------------------------------------------------------------------ the cache on disk

#: Meshes of at least this many triangles keep their tree on disk, in
#: ``$XDG_CACHE_HOME/whitted/bvh`` (smaller ones build in milliseconds).
DISK_MIN_TRIANGLES = 1 << 15
#: The disk cache's bound, all trees together; the least recently used go first.
DISK_MAX_BYTES = 2 << 30
#: What an entry holds: the boxes, each node's right child (-1 for a leaf), its count,
#: ``order`` and the depth. A left child (the node after its parent) and a leaf's start
#: (the counts before it) follow from the depth-first layout (:func:`_stored`), so they
#: are neither stored nor read: the 1,000,000-triangle knot's entry is 22 MB, not 43.
_ARRAY_KINDS = {"lo": "<f4", "hi": "<f4", "right": "<i4", "count": "|u1", "order": "<i4",
                "depth": "<i8"}


def disk_folder():
    """``$XDG_CACHE_HOME/whitted/bvh``: trees of large meshes (:mod:`tracer.cache`'s rules)."""
    from whitted.tracer import cache

    return cache.home() / "bvh"


def _kept_on_disk(tris: _Triangles, corners: str) -> BVH:
    """The BVH of ``tris``, its tree read from the disk cache when one was kept for the
    same corners (``corners``: their key, :func:`shared_bvh`'s) by the same builder
    (this module's source) and it passes :func:`valid_arrays`; else built, and kept."""
    from whitted.tracer import cache

    n = tris.count
    if n < DISK_MIN_TRIANGLES:
        return BVH.from_records(build_bvh(*tris.corners()), n, tris.records)
    key = cache.content_key(cache.source_digest(__file__), corners)
    entry = disk_folder() / f"{key}.arrays"
    t0 = time.perf_counter()
    a = cache.read_entry(entry, _ARRAY_KINDS)
    if a is not None and a["depth"].shape == (1,) and a["right"].shape == a["count"].shape:
        arrays = _stored(a, time.perf_counter() - t0)
        # valid_arrays' two steps, the boxes checked on the records the BVH reads
        if _tree_holds(arrays, n, (1 << COUNT_BITS) - 1):
            bvh = BVH.from_records(arrays, n, tris.records)
            if _boxes_hold(arrays, bvh.tris):
                cache.touch(entry)
                return bvh
    bvh = BVH.from_records(build_bvh(*tris.corners()), n, tris.records)
    b = bvh.arrays
    cache.keep_entry(entry, {"lo": b.lo, "hi": b.hi, "right": b.right.astype(np.int32),
                             "count": b.count.astype(np.uint8),
                             "order": b.order.astype(np.int32),
                             "depth": np.array([b.depth])}, DISK_MAX_BYTES)
    return bvh


def _stored(a: dict, seconds: float) -> BVHArrays:
    """The :class:`BVHArrays` of an entry's arrays (``_ARRAY_KINDS``, of one length each),
    laid out depth-first as :func:`build_bvh` lays a tree out: an inner node's left child
    is the node after it, a leaf's triangles start where the leaves before it end (an
    inner node's start is 0). Not yet checked (:func:`_tree_holds`)."""
    right = a["right"].astype(np.int64)
    count = a["count"].astype(np.int64)
    m = len(right)
    inner = right >= 0
    left = np.where(inner, np.arange(1, m + 1), -1)
    start = np.cumsum(count)
    start -= count
    start[inner] = 0
    return BVHArrays(a["lo"], a["hi"], left, right, start, count, a["order"],
                     int(a["depth"][0]), seconds)


def valid_arrays(b: BVHArrays, p0: np.ndarray, p1: np.ndarray, p2: np.ndarray,
                 max_leaf: int = (1 << COUNT_BITS) - 1) -> bool:
    """Whether ``b`` is a tree over these triangles that the traversal may walk: what a
    tree read from disk must show before it is used (:func:`_tree_holds`, then
    :func:`_boxes_hold` on the float32 records the traversal reads)."""
    if not _tree_holds(b, len(p0), max_leaf):
        return False
    perm = upload(jit.UInt32, b.order, np.uint32)
    return _boxes_hold(b, _triangle_records(perm, (p0, p1, p2)))


def _tree_holds(b: BVHArrays, n: int, max_leaf: int) -> bool:
    """Whether ``b`` is a tree of ``n`` triangles in :func:`build_bvh`'s layout, its boxes
    finite: :func:`valid_arrays`' checks but the boxes' contents.

    Shapes agree; nodes are in depth-first order, as the builders number them: a left
    child right after its parent, the right one after it, each node but the root the
    child of exactly one inner node (so a walk from the root ends, and meets every node
    once); a leaf holds 1 to ``max_leaf`` triangles and the leaves' ranges follow each
    other in node order from 0 to ``n``; ``order`` is a permutation of the triangles;
    ``depth`` is the tree's. The layout is asked for because it makes the check cheap
    (no sort of the leaves' ranges, no gather of a node's children): the
    1,000,000-triangle knot's tree in 18 ms, where the layout-free check took 36 ms
    (and 75 ms in a process's first check, beside the boxes' on a second thread; a
    throwaway script, issue 33)."""
    m = len(b.left)
    shapes = [(b.lo, (m, 3)), (b.hi, (m, 3)), (b.right, (m,)), (b.start, (m,)),
              (b.count, (m,)), (b.order, (n,))]
    if n == 0 or m == 0 or any(a.shape != s for a, s in shapes) or b.depth < 0:
        return False
    if not (np.isfinite(b.lo).all() and np.isfinite(b.hi).all()):
        return False
    inner = b.left >= 0
    leaf = ~inner
    ii = np.flatnonzero(inner)
    li, ri = b.left[ii], b.right[ii]
    if (li != ii + 1).any() or (ri <= li).any() or (ri >= m).any() \
            or (b.left[leaf] != -1).any() or (b.right[leaf] != -1).any():
        return False
    parents = np.bincount(ri, minlength=m)   # the left children are ii + 1: one each
    parents[li] += 1
    if parents[0] != 0 or (parents[1:] != 1).any():
        return False
    cnt, start = b.count[leaf], b.start[leaf]
    if (b.count[ii] != 0).any() or (cnt < 1).any() or (cnt > max_leaf).any():
        return False
    ends = np.cumsum(cnt)
    if ends[-1] != n or (start != ends - cnt).any():
        return False
    o = b.order
    if o.min() < 0 or o.max() >= n or (np.bincount(o, minlength=n) != 1).any():
        return False
    # depth: the deepest leaf's level, found level by level from the root (each node is
    # met once, as the child of its one parent)
    frontier, levels = np.zeros(1, np.int64), -1
    while len(frontier):
        levels += 1
        if levels > b.depth:
            return False
        frontier = frontier[inner[frontier]]
        frontier = np.concatenate([frontier + 1, b.right[frontier]])
    return levels == b.depth


def _boxes_hold(b: BVHArrays, tris) -> bool:
    """Whether each leaf's box holds its triangles' corners and each child's box lies in
    its parent's, on a tree :func:`_tree_holds` has passed (so that every index below is
    in range). The corners are the float32 ones the traversal tests (``tris``, the
    records of :func:`_triangle_records`, in leaf order): the boxes it reads
    (:func:`pack_nodes`) are these boxes widened, so that a box that holds them lets no
    hit be missed.

    One Dr.Jit kernel, a lane a triangle (and, in the first lanes, an inner node):
    numpy's comparisons of rows of three took about 48 ms for the 1,000,000-triangle
    knot, 88 ms in a process's first check (a throwaway script, issue 33)."""
    n = len(b.order)
    leaves = np.flatnonzero(b.left < 0)
    inner = np.flatnonzero(b.left >= 0)
    lo, hi = (upload(jit.Float, x, np.float32) for x in (b.lo, b.hi))
    j = dr.arange(jit.UInt32, n)
    owner = dr.gather(jit.UInt32, upload(jit.UInt32, np.repeat(leaves, b.count[leaves]),
                                         np.uint32), j)
    # lanes below the number of inner nodes also check inner node j's two children (an
    # opaque count, so that the kernel is the same for every tree)
    # (a tree of one leaf gathers from one dummy entry, in no lane)
    q = j < dr.opaque(jit.UInt32, len(inner))
    node, right = (dr.gather(jit.UInt32, upload(jit.UInt32, x if len(x) else [0], np.uint32),
                             j, q) for x in (inner, b.right[inner]))
    wrong = []
    for a in range(3):
        box_lo = dr.gather(jit.Float, lo, owner * 3 + a)
        box_hi = dr.gather(jit.Float, hi, owner * 3 + a)
        for k in range(3):
            x = dr.gather(jit.Float, tris, j * 16 + (3 * k + a))
            wrong.append(~((box_lo <= x) & (x <= box_hi)))   # NaN fails too
        p_lo, p_hi = (dr.gather(jit.Float, x, node * 3 + a, q) for x in (lo, hi))
        for child in (node + 1, right):
            c_lo, c_hi = (dr.gather(jit.Float, x, child * 3 + a, q) for x in (lo, hi))
            wrong.append(q & ~((p_lo <= c_lo) & (c_hi <= p_hi)))
    return not bool(dr.any(any_mask(wrong))[0])
