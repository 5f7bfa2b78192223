"""The BVH finds what testing every triangle finds, and its tree keeps its invariants.

The reference is brute force: every ray against every triangle with
tracer.shapes.triangle.intersect, the same test on the same float32 numbers
as the BVH's leaves. Both take the minimum of the same per-triangle t
values, so they agree exactly unless the BVH wrongly skips a triangle; the
tolerance below only absorbs a compiler contracting a product and a sum into
one fused multiply-add in one kernel and not the other.
"""

import math

import drjit as dr
import numpy as np
import pytest
from conftest import MINIMAL, jit_kernels

from whitted.tracer.bvh import BVH, INVALID, build_bvh, sah_cost
from whitted.tracer.shapes import triangle as tri_f

#: Relative tolerance on t: a few float32 roundings (2^-24 each) that may differ
#: between the two kernels, times the condition of the solve for non-grazing hits.
T_REL = 1e-5


def v3(jit, a):
    a = np.asarray(a, dtype=np.float32).reshape(-1, 3)
    return jit.Array3f(a[:, 0], a[:, 1], a[:, 2])


@dr.syntax
def _brute_loop(jit, o, d, p0, p1, p2, t, tri, count):
    i = jit.UInt32(0)
    while i < count:
        ti, hit, _, _ = tri_f.intersect(o, d, dr.gather(jit.Array3f, p0, i),
                                        dr.gather(jit.Array3f, p1, i),
                                        dr.gather(jit.Array3f, p2, i), t)
        t = dr.select(hit, ti, t)
        tri = dr.select(hit, i, tri)
        i += 1
    return t, tri


def brute_force(jit, p0, p1, p2, o, d, tmax):
    """(t, tri) of the nearest hit of each ray over all triangles, lowest index on ties."""
    n = len(o)
    t = jit.Float(np.broadcast_to(np.float32(tmax), (n,)).copy())
    tri = dr.full(jit.UInt32, INVALID, n)
    # The corners as BVH stores them: float64 rounded once.
    t, tri = _brute_loop(jit, v3(jit, o), v3(jit, d), v3(jit, p0), v3(jit, p1),
                         v3(jit, p2), t, tri, dr.opaque(jit.UInt32, len(p0)))
    return t.numpy(), tri.numpy()


def trace(jit, bvh, o, d, tmax, active=True):
    t, tri, beta, gamma = bvh.closest_hit(v3(jit, o), v3(jit, d), jit.Float(tmax), active)
    return t.numpy(), tri.numpy(), beta.numpy(), gamma.numpy()


def assert_same_hits(t, tri, t_ref, tri_ref):
    """Same nearest hit: the same triangle, or a tie (equal t) with another one."""
    hit, hit_ref = tri != INVALID, tri_ref != INVALID
    np.testing.assert_array_equal(hit, hit_ref)
    np.testing.assert_allclose(t[hit], t_ref[hit], rtol=T_REL, atol=0)
    differ = hit & (tri != tri_ref)
    # Ties are rare (a ray through a shared edge or vertex, or coincident triangles).
    assert differ.sum() <= max(3, hit.sum() // 1000), f"{differ.sum()} different triangles"


def random_rays(rng, n, lo, hi, spread=0.3):
    """Origins in the box [lo, hi] widened by ``spread`` of its size (inside and outside
    the geometry), random directions of random length."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    size = hi - lo
    o = lo - spread * size + rng.random((n, 3)) * (1 + 2 * spread) * size
    d = rng.normal(size=(n, 3)) * rng.uniform(0.2, 5.0, (n, 1))
    return o, d


def soup(rng, n, scale=0.3):
    c = rng.uniform(-1, 1, (n, 3))
    return tuple(c + rng.normal(size=(n, 3)) * scale for _ in range(3))


def torus(nu, nv, big=1.0, small=0.35):
    """A torus of 2 nu nv triangles (shared vertices), counter-clockwise seen from outside."""
    u = np.linspace(0, 2 * np.pi, nu, endpoint=False)
    v = np.linspace(0, 2 * np.pi, nv, endpoint=False)
    uu, vv = np.meshgrid(u, v, indexing="ij")
    p = np.stack([(big + small * np.cos(vv)) * np.cos(uu),
                  (big + small * np.cos(vv)) * np.sin(uu),
                  small * np.sin(vv)], -1).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(nu), np.arange(nv), indexing="ij")
    a, b = i * nv + j, ((i + 1) % nu) * nv + j
    c, e = ((i + 1) % nu) * nv + (j + 1) % nv, i * nv + (j + 1) % nv
    f = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3),
                        np.stack([a, c, e], -1).reshape(-1, 3)])
    return p, f


def check_tree(b, p0, p1, p2, max_leaf):
    """The invariants of a BVHArrays for triangles (p0, p1, p2)."""
    n = len(p0)
    leaf = b.left < 0
    inner = ~leaf
    # Every triangle in exactly one leaf: the leaves' ranges tile order[0:n], a permutation.
    np.testing.assert_array_equal(np.sort(b.order), np.arange(n))
    starts, counts = b.start[leaf], b.count[leaf]
    ranges = np.sort(np.stack([starts, starts + counts], 1), axis=0)
    assert ranges[0, 0] == 0 and ranges[-1, 1] == n
    np.testing.assert_array_equal(ranges[1:, 0], ranges[:-1, 1])
    assert counts.min() >= 1 and counts.max() <= max_leaf
    assert (b.count[inner] == 0).all()
    # Every node but the root is the child of exactly one inner node; depth-first order.
    kids = np.concatenate([b.left[inner], b.right[inner]])
    np.testing.assert_array_equal(np.sort(kids), np.arange(1, len(b.left)))
    np.testing.assert_array_equal(b.left[inner], np.flatnonzero(inner) + 1)
    # Every child box inside its parent box, every triangle inside its leaf's box.
    for child in (b.left[inner], b.right[inner]):
        assert (b.lo[child] >= b.lo[inner]).all() and (b.hi[child] <= b.hi[inner]).all()
    owner = np.repeat(np.flatnonzero(leaf), counts)
    tri = b.order[np.concatenate([np.arange(s, s + c) for s, c in zip(starts, counts,
                                                                      strict=True)])]
    for p in (p0, p1, p2):
        assert (p[tri] >= b.lo[owner]).all() and (p[tri] <= b.hi[owner]).all()
    # The root holds everything, and no more than float32 rounding outwards adds: the
    # smallest float32 box around the float64 corners. The depth is the longest
    # root-to-leaf path.
    lo, hi = np.minimum(np.minimum(p0, p1), p2).min(0), np.maximum(np.maximum(p0, p1), p2).max(0)
    assert b.lo.dtype == b.hi.dtype == np.float32
    np.testing.assert_array_equal(b.lo[0], np.where(lo.astype(np.float32) > lo, np.nextafter(
        lo.astype(np.float32), np.float32(-np.inf)), lo.astype(np.float32)))
    np.testing.assert_array_equal(b.hi[0], np.where(hi.astype(np.float32) < hi, np.nextafter(
        hi.astype(np.float32), np.float32(np.inf)), hi.astype(np.float32)))
    depth = np.zeros(len(b.left), int)
    for i in np.flatnonzero(inner):  # parents come before children (depth-first order)
        depth[b.left[i]] = depth[b.right[i]] = depth[i] + 1
    assert depth.max() == b.depth


# --------------------------------------------------------------------------- tree


@pytest.mark.parametrize("n", [1, 2, 5, 64, 3000])
def test_tree_invariants_every_triangle_in_one_leaf_children_inside_parents(n):
    rng = np.random.default_rng(n)
    p0, p1, p2 = soup(rng, n)
    b = build_bvh(p0, p1, p2, max_leaf=4)
    check_tree(b, p0, p1, p2, 4)


def test_tree_invariants_hold_for_coincident_triangles_split_by_median():
    # All centroids equal: no SAH split exists, the median of the list is used.
    p0 = np.zeros((50, 3))
    p1 = np.tile([1.0, 0, 0], (50, 1))
    p2 = np.tile([0, 1.0, 0], (50, 1))
    b = build_bvh(p0, p1, p2, max_leaf=3)
    check_tree(b, p0, p1, p2, 3)


def test_boxes_are_the_smallest_float32_boxes_around_the_corners():
    # Corners on float32 values, between them, either side of zero and far from the
    # origin: each leaf's box is the nearest float32 rounded outwards, never inwards
    # (numpy's nextafter decides). Dr.Jit's CPU kernels treat subnormal floats as zero,
    # so a bound below the smallest normal float32 in size is 0 or +-2^-126 outwards.
    vals = np.array([0.0, 1.0, -1.0, 0.1, -0.1, 1e-50, -1e-50, 3e38, -3e38, 1 + 2.0**-30,
                     -(1 + 2.0**-30), 16777217.0, 2.0**-140 / 3])
    rng = np.random.default_rng(5)
    p0, p1, p2 = (rng.choice(vals, size=(40, 3)) for _ in range(3))
    b = build_bvh(p0, p1, p2, max_leaf=1)
    leaf = b.left < 0
    tri = b.order[b.start[leaf]]
    lo = np.minimum(np.minimum(p0, p1), p2)[tri]
    hi = np.maximum(np.maximum(p0, p1), p2)[tri]
    lo32, hi32 = lo.astype(np.float32), hi.astype(np.float32)
    lo32 = np.where(lo32 > lo, np.nextafter(lo32, np.float32(-np.inf)), lo32)
    hi32 = np.where(hi32 < hi, np.nextafter(hi32, np.float32(np.inf)), hi32)
    tiny = np.float32(2.0**-126)
    lo32 = np.where(np.abs(lo32) < tiny, np.where(lo < 0, -tiny, 0), lo32)
    hi32 = np.where(np.abs(hi32) < tiny, np.where(hi > 0, tiny, 0), hi32)
    np.testing.assert_array_equal(b.lo[leaf], lo32)
    np.testing.assert_array_equal(b.hi[leaf], hi32)
    assert (b.lo[leaf] <= lo).all() and (b.hi[leaf] >= hi).all()


def median_tree_cost(p0, p1, p2, max_leaf=4):
    """The same cost of the object-median tree: each node split at the median centroid
    along its widest centroid extent, down to max_leaf triangles."""
    lo, hi = np.minimum(np.minimum(p0, p1), p2), np.maximum(np.maximum(p0, p1), p2)
    c = (lo + hi) / 2
    boxes, counts, inner = [], [], []
    stack = [np.arange(len(p0))]
    while stack:
        idx = stack.pop()
        boxes.append((lo[idx].min(0), hi[idx].max(0)))
        counts.append(len(idx))
        inner.append(len(idx) > max_leaf)
        if len(idx) > max_leaf:
            axis = int(np.argmax(c[idx].max(0) - c[idx].min(0)))
            o = idx[np.argsort(c[idx, axis], kind="stable")]
            stack += [o[:len(o) // 2], o[len(o) // 2:]]
    b_lo, b_hi = (np.array([b[k] for b in boxes]) for k in (0, 1))
    return sah_cost(b_lo, b_hi, np.array(counts), np.array(inner))


@pytest.mark.parametrize("shape", ["torus", "soup"])
def test_sah_tree_costs_less_than_the_median_tree(shape):
    # The builder's whole point: by the SAH's own measure its tree beats the plain
    # object-median tree (here by 16 % on the torus, 8 % on the soup); a builder that
    # split in the wrong bin, on the wrong axis or at the median would not.
    if shape == "torus":
        p, f = torus(80, 40)
        p0, p1, p2 = p[f[:, 0]], p[f[:, 1]], p[f[:, 2]]
    else:
        p0, p1, p2 = soup(np.random.default_rng(3), 6000)
    b = build_bvh(p0, p1, p2)
    assert sah_cost(b.lo, b.hi, b.count, b.left >= 0) < median_tree_cost(p0, p1, p2)


def test_the_build_is_deterministic():
    p0, p1, p2 = soup(np.random.default_rng(4), 5000)
    a, b = build_bvh(p0, p1, p2), build_bvh(p0, p1, p2)
    for k in ("lo", "hi", "left", "right", "start", "count", "order"):
        np.testing.assert_array_equal(getattr(a, k), getattr(b, k))


@pytest.mark.parametrize("chunk", [32, 100])
def test_the_tree_does_not_depend_on_the_chunk_size(monkeypatch, chunk):
    """A node binned as chunks whose bins are summed gets the bins it gets in one lane:
    the same tree whatever tracer.bvh.CHUNK is, from 32 up (a node of 32 triangles or
    fewer bins into fewer bins, which the chunked path does not): a CHUNK chosen for
    speed changes nothing else. 12,800 triangles: one lane a node at the default, many
    chunks at 32 or 100."""
    import whitted.tracer.bvh as bvh_module

    p, f = torus(80, 80)
    p0, p1, p2 = p[f[:, 0]], p[f[:, 1]], p[f[:, 2]]
    a = build_bvh(p0, p1, p2)
    monkeypatch.setattr(bvh_module, "CHUNK", chunk)
    monkeypatch.setattr(bvh_module, "CHUNK_GPU", chunk)
    b = build_bvh(p0, p1, p2)
    for k in ("lo", "hi", "left", "right", "start", "count", "order"):
        np.testing.assert_array_equal(getattr(b, k), getattr(a, k))


def test_torus_tree_invariants_and_build_time(record_property):
    p, f = torus(320, 160)  # 102,400 triangles
    p0, p1, p2 = p[f[:, 0]], p[f[:, 1]], p[f[:, 2]]
    b = build_bvh(p0, p1, p2)
    check_tree(b, p0, p1, p2, 4)
    print(f"BVH build: {len(f)} triangles in {b.seconds:.2f} s, {len(b.left)} nodes, "
          f"depth {b.depth}")
    record_property("bvh_build_seconds_102400", round(b.seconds, 3))


# --------------------------------------------------------------------------- queries


@pytest.mark.parametrize("seed,n", [(0, 1), (1, 7), (2, 60), (3, 500)])
def test_closest_hit_equals_brute_force_on_random_soups(jit, seed, n):
    rng = np.random.default_rng(seed)
    p0, p1, p2 = soup(rng, n)
    bvh = BVH(p0, p1, p2)
    o, d = random_rays(rng, 4000, [-1.3] * 3, [1.3] * 3)
    t, tri, _, _ = trace(jit, bvh, o, d, math.inf)
    t_ref, tri_ref = brute_force(jit, p0, p1, p2, o, d, math.inf)
    assert (tri_ref != INVALID).any() and (tri_ref == INVALID).any()  # hits and misses
    assert_same_hits(t, tri, t_ref, tri_ref)


def test_closest_hit_equals_brute_force_on_a_100k_triangle_torus(jit):
    p, f = torus(320, 160)
    p0, p1, p2 = p[f[:, 0]], p[f[:, 1]], p[f[:, 2]]
    bvh = BVH(p0, p1, p2)
    rng = np.random.default_rng(7)
    # Origins around and inside the torus's bounds (many inside the tube or the hole).
    o, d = random_rays(rng, 1536, [-1.35, -1.35, -0.35], [1.35, 1.35, 0.35], spread=0.2)
    t, tri, _, _ = trace(jit, bvh, o, d, math.inf)
    t_ref, tri_ref = brute_force(jit, p0, p1, p2, o, d, math.inf)
    assert 0.2 < (tri_ref != INVALID).mean() < 0.95
    assert_same_hits(t, tri, t_ref, tri_ref)
    assert bvh.triangle_count == len(f) and bvh.node_count == len(bvh.arrays.left)
    print(f"BVH build: {len(f)} triangles in {bvh.build_seconds:.2f} s")


def test_closest_hit_respects_tmax_and_returns_tmax_on_a_miss(jit):
    rng = np.random.default_rng(11)
    p0, p1, p2 = soup(rng, 200)
    bvh = BVH(p0, p1, p2)
    o, d = random_rays(rng, 3000, [-1] * 3, [1] * 3)
    tmax = rng.uniform(0.0, 2.0, len(o)).astype(np.float32)
    t, tri, _, _ = trace(jit, bvh, o, d, tmax)
    t_ref, tri_ref = brute_force(jit, p0, p1, p2, o, d, tmax)
    assert_same_hits(t, tri, t_ref, tri_ref)
    miss = tri == INVALID
    np.testing.assert_array_equal(t[miss], tmax[miss])
    assert (t[~miss] > 0).all() and (t[~miss] < tmax[~miss]).all()


def test_barycentrics_are_those_of_the_triangle_test(jit):
    rng = np.random.default_rng(5)
    p0, p1, p2 = soup(rng, 300)
    bvh = BVH(p0, p1, p2)
    o, d = random_rays(rng, 2000, [-1] * 3, [1] * 3)
    t, tri, beta, gamma = trace(jit, bvh, o, d, math.inf)
    hit = np.flatnonzero(tri != INVALID)
    k = tri[hit]
    t2, ok, b2, g2 = tri_f.intersect(v3(jit, o[hit]), v3(jit, d[hit]), v3(jit, p0[k]),
                                     v3(jit, p1[k]), v3(jit, p2[k]), jit.Float(math.inf))
    assert ok.numpy().all()
    np.testing.assert_allclose(beta[hit], b2.numpy(), rtol=T_REL, atol=1e-6)
    np.testing.assert_allclose(gamma[hit], g2.numpy(), rtol=T_REL, atol=1e-6)
    assert (beta[hit] >= 0).all() and (gamma[hit] >= 0).all()
    assert (beta[hit] + gamma[hit] <= 1).all()


def test_inactive_rays_report_a_miss(jit):
    rng = np.random.default_rng(2)
    p0, p1, p2 = soup(rng, 100)
    bvh = BVH(p0, p1, p2)
    o, d = random_rays(rng, 1000, [-1] * 3, [1] * 3)
    active = rng.random(len(o)) < 0.5
    t, tri, _, _ = trace(jit, bvh, o, d, math.inf, jit.Bool(active))
    t_all, tri_all, _, _ = trace(jit, bvh, o, d, math.inf)
    assert (tri[~active] == INVALID).all() and np.isinf(t[~active]).all()
    np.testing.assert_array_equal(tri[active], tri_all[active])
    np.testing.assert_array_equal(t[active], t_all[active])


def test_axis_parallel_rays_hit_axis_aligned_triangles(jit):
    # Flat boxes and direction components of exactly zero: the slab test's hard cases.
    n = 10
    x, y = np.meshgrid(np.arange(n, dtype=float), np.arange(n, dtype=float))
    x, y = x.ravel(), y.ravel()
    z = np.zeros_like(x)
    p0 = np.stack([x, y, z], 1)
    p1 = np.stack([x + 1, y, z], 1)
    p2 = np.stack([x, y + 1, z], 1)
    bvh = BVH(p0, p1, p2)
    rng = np.random.default_rng(3)
    m = 2000
    o = np.stack([rng.uniform(0, n, m), rng.uniform(0, n, m), np.full(m, 2.0)], 1)
    d = np.tile([0.0, 0.0, -1.0], (m, 1))
    t, tri, _, _ = trace(jit, bvh, o, d, math.inf)
    t_ref, tri_ref = brute_force(jit, p0, p1, p2, o, d, math.inf)
    assert_same_hits(t, tri, t_ref, tri_ref)
    # Rays in the plane of the triangles (along x, z = 0) and beside them.
    o2 = np.stack([np.full(m, -1.0), rng.uniform(0, n, m), rng.choice([0.0, 1e-3], m)], 1)
    d2 = np.tile([1.0, 0.0, 0.0], (m, 1))
    t, tri, _, _ = trace(jit, bvh, o2, d2, math.inf)
    t_ref, tri_ref = brute_force(jit, p0, p1, p2, o2, d2, math.inf)
    assert_same_hits(t, tri, t_ref, tri_ref)


def test_occluded_agrees_with_closest_hit(jit):
    p, f = torus(60, 30)
    p0, p1, p2 = p[f[:, 0]], p[f[:, 1]], p[f[:, 2]]
    bvh = BVH(p0, p1, p2)
    rng = np.random.default_rng(9)
    o, d = random_rays(rng, 5000, [-1.35, -1.35, -0.35], [1.35, 1.35, 0.35])
    tmax = jit.Float(rng.uniform(0.0, 3.0, len(o)).astype(np.float32))
    occ = bvh.occluded(v3(jit, o), v3(jit, d), tmax).numpy()
    _, tri, _, _ = bvh.closest_hit(v3(jit, o), v3(jit, d), tmax)
    np.testing.assert_array_equal(occ, tri.numpy() != INVALID)
    assert occ.any() and not occ.all()
    active = rng.random(len(o)) < 0.5
    occ_a = bvh.occluded(v3(jit, o), v3(jit, d), tmax, jit.Bool(active)).numpy()
    np.testing.assert_array_equal(occ_a, occ & active)


def test_empty_bvh_misses_everything(jit):
    empty = np.zeros((0, 3))
    bvh = BVH(empty, empty, empty)
    t, tri, _, _ = trace(jit, bvh, np.zeros((4, 3)), np.ones((4, 3)), 5.0)
    assert (tri == INVALID).all() and (t == 5.0).all()
    assert not bvh.occluded(v3(jit, np.zeros((4, 3))), v3(jit, np.ones((4, 3))),
                            jit.Float(5.0)).numpy().any()


def test_bad_input_is_refused():
    p = np.zeros((2, 3))
    with pytest.raises(ValueError, match="same number"):
        build_bvh(p, p, np.zeros((3, 3)))
    with pytest.raises(ValueError, match="finite"):
        build_bvh(p, p, np.full((2, 3), np.nan))
    with pytest.raises(ValueError, match="max_leaf"):
        build_bvh(p, p, p, max_leaf=8)


def test_a_scenes_occlusion_agrees_with_its_closest_hit(jit):
    """Geometry.occluded, where a mesh stops at its first hit and later blocks test only
    the rays not yet blocked, answers as the closest hit does: two meshes and a floor
    (mesh_knot), rays from points all over the scene, active lanes or not."""
    from whitted.reference.cli import resolve_scene
    from whitted.tracer import load_scene
    from whitted.tracer.geometry import Geometry

    geo = Geometry(load_scene(resolve_scene("mesh_knot")))
    assert sum(b.any_hit for b in geo.blocks) == 2 and len(geo.blocks) == 3
    _assert_occlusion_is_the_closest_hits(jit, geo, np.random.default_rng(4), [-3, -0.5, -3],
                                          [3, 3, 3], 6.0, 0.05)


def _assert_occlusion_is_the_closest_hits(jit, geo, rng, lo, hi, longest, least):
    """Geometry.occluded of 20,000 segments (from points in the box lo-hi, up to ``longest``
    long) equals whether the closest hit exists, with every lane active and with half;
    at least the fraction ``least`` of them is blocked, and as many are not."""
    o, d = random_rays(rng, 20000, lo, hi)
    d /= np.linalg.norm(d, axis=1, keepdims=True)  # the geometry's rays are unit vectors
    tmax = jit.Float(rng.uniform(0.0, longest, len(o)).astype(np.float32))
    occ = geo.occluded(v3(jit, o), v3(jit, d), tmax).numpy()
    ref = geo.closest_hit(v3(jit, o), v3(jit, d), tmax).valid.numpy()
    np.testing.assert_array_equal(occ, ref)
    assert least < occ.mean() < 1 - least
    active = rng.random(len(o)) < 0.5
    occ_a = geo.occluded(v3(jit, o), v3(jit, d), tmax, jit.Bool(active)).numpy()
    np.testing.assert_array_equal(occ_a, ref & active)


def test_the_same_triangles_share_a_tree_and_different_ones_do_not(jit):
    """shared_bvh: a mesh built again (the formula-bug sweep builds a scene once per bug)
    gets the tree already built for the same corners; a mesh that differs in one
    coordinate gets a tree of its own, which finds that triangle where it now is."""
    from whitted.tracer.bvh import shared_bvh

    p0, p1, p2 = soup(np.random.default_rng(11), 500)
    first = shared_bvh(p0, p1, p2)
    assert shared_bvh(p0.copy(), p1.copy(), p2.copy()) is first
    moved = p0.copy()
    moved[7] += 0.25
    other = shared_bvh(moved, p1, p2)
    assert other is not first
    rng = np.random.default_rng(12)
    o, d = random_rays(rng, 4000, -1.5, 1.5)
    tmax = np.full(len(o), 1e30)
    t, tri = trace(jit, other, o, d, tmax)[:2]
    t_ref, tri_ref = brute_force(jit, moved, p1, p2, o, d, tmax)[:2]
    assert_same_hits(t, tri, t_ref, tri_ref)


#: Beside conftest.MINIMAL's sphere: a mesh and a ball, each a group.
KNOT_AND_BALL = """
[groups.knot]
[[groups.knot.shapes]]
type = "mesh"
file = "{knot}"
material = "white"

[groups.ball]
[[groups.ball.shapes]]
type = "sphere"
radius = 0.3
material = "white"
{places}
"""


def knots_and_ball(knot, fourth: str) -> str:
    """conftest.MINIMAL with :data:`KNOT_AND_BALL`: the knot (the PLY file ``knot``)
    instanced three times, a fourth knot instancing the group ``fourth``, and the ball
    instanced once, scaled."""
    places = "".join(
        f'\n[[shapes]]\ntype = "instance"\ngroup = "{g}"\nto_world = [ {{ scale = {s} }}, '
        f'{{ rotate = {{ axis = [0, 1, 0], angle = {a} }} }}, '
        f'{{ translate = [{x}, 0, {z}] }} ]\n'
        for g, s, a, x, z in (("knot", 0.5, 0, -1, -1), ("knot", 0.7, 40, 1, -1),
                              ("knot", 0.5, 80, -1, 1), (fourth, 0.6, 120, 0.8, 0.9),
                              ("ball", 1.5, 0, 0, 0)))
    return MINIMAL + KNOT_AND_BALL.format(knot=knot, places=places)


def _instanced_scene(tmp_path, name: str):
    """A built-in scene by name, or "knots": :func:`knots_and_ball` with the knot's mesh."""
    from whitted.reference.cli import resolve_scene
    from whitted.tracer import load_scene

    if name != "knots":
        return load_scene(resolve_scene(name))
    path = tmp_path / "knots.toml"
    path.write_text(knots_and_ball(resolve_scene("mesh_knot").parent / "meshes" / "knot.ply",
                                   "knot"))
    return load_scene(path)


@pytest.mark.parametrize("name", ["instances_scaled", "shapes_zoo", "knots"])
def test_instances_occlusion_agrees_with_their_closest_hit(jit, tmp_path, name):
    """Where instances block a segment (tracer/geometry.py: a hierarchy of instances walked
    farther child first and left at the first that blocks, or one instance asking its
    group), the answer is the closest hit's: groups of spheres and cylinders instanced
    three times (instances_scaled, shapes_zoo, one a non-uniform scale), and a mesh
    instanced four times beside one ball instanced once, scaled (knots)."""
    from whitted.tracer.geometry import Geometry, _InstanceBlock, _InstanceSetBlock

    scene = _instanced_scene(tmp_path, name)
    geo = Geometry(scene)
    kinds = {type(b) for b in geo.blocks}
    assert _InstanceSetBlock in kinds and (name != "knots" or _InstanceBlock in kinds)
    _assert_occlusion_is_the_closest_hits(jit, geo, np.random.default_rng(5), [-2.5, -1, -2.5],
                                          [2.5, 2.5, 2.5], 5.0, 0.02)


def _box_sets(rng):
    """(lo, hi) float64 box sets of 1 to SMALL_BOX_SET boxes: ordinary, all one box, points,
    flat boxes, and boxes whose float32 bounds would be subnormal."""
    from whitted.tracer.bvh import SMALL_BOX_SET

    for trial in range(120):
        n = int(rng.integers(1, SMALL_BOX_SET + 1))
        lo = rng.normal(size=(n, 3)) * (1e-40, 1e-3, 1.0, 1e5)[trial % 4]
        if trial % 7 == 0:
            lo[:] = lo[0]
        size = np.abs(rng.normal(size=(n, 3))) * (0.0, 1e-3, 1.0)[trial % 3]
        if trial % 5 == 0:
            size[:, trial % 3] = 0.0
        yield lo, lo + size


@pytest.mark.parametrize("max_leaf", [1, 4])
def test_a_few_boxes_make_their_tree_on_the_host_rounded_as_the_device_rounds(jit, monkeypatch,
                                                                            max_leaf):
    """Up to SMALL_BOX_SET boxes (an instance hierarchy), build_box_bvh builds on the host:
    a tree that passes the check a tree read from disk must pass (valid_arrays: a tree over
    the boxes, each held by its leaf's float32 box), with the device builder's root box bit
    for bit (the same outward rounding to float32, subnormal bounds included), and of a
    SAH cost near its (exact splits against binned ones, both greedy: within 10 % on
    these sets; measured at most 6.6 % above, median equal)."""
    from whitted.tracer import bvh

    costs = []
    for lo, hi in _box_sets(np.random.default_rng(31)):
        host = bvh.build_box_bvh(lo, hi, max_leaf=max_leaf)
        with monkeypatch.context() as m:
            m.setattr(bvh, "SMALL_BOX_SET", 0)
            device = bvh.build_box_bvh(lo, hi, max_leaf=max_leaf)
        assert bvh.valid_arrays(host, lo, hi, hi, max_leaf=max_leaf)
        np.testing.assert_array_equal(host.lo[0], device.lo[0])
        np.testing.assert_array_equal(host.hi[0], device.hi[0])
        assert np.array_equal(np.sort(host.order), np.arange(len(lo)))
        costs.append(sah_cost(host.lo, host.hi, host.count, host.left >= 0)
                     / sah_cost(device.lo, device.hi, device.count, device.left >= 0))
    assert max(costs) < 1.1


def test_meshes_sharing_vertices_but_not_faces_get_trees_of_their_own(jit):
    """A mesh without a key of its own (a file not kept parsed on disk) has its tree keyed
    by a hash of its vertices and faces (shapes.mesh._tree_key): a mesh with the same
    vertices and other faces, or the same faces and a vertex moved, gets its own tree,
    over its own corners; the same mesh again gets the first one's."""
    from whitted.tracer.shapes import mesh

    rng = np.random.default_rng(21)
    v = rng.normal(size=(120, 3))
    f = rng.integers(0, len(v), size=(300, 3))
    f2 = f.copy()
    f2[5] = f2[5][::-1]                         # one face wound the other way
    v2 = v.copy()
    v2[f[9, 0], 2] += 1e-9                      # one vertex moved a little

    def block(v, f):
        return mesh.Block(mesh.Mesh("m.obj", False, v, f, None, None,
                                    tuple(map(tuple, np.eye(4))), None))

    first = block(v, f)
    assert block(v.copy(), f.copy()).bvh is first.bvh
    for vv, ff in ((v, f2), (v2, f)):
        other = block(vv, ff)
        assert other.bvh is not first.bvh
        corners = [vv[ff[:, k]] for k in range(3)]
        order = other.bvh.perm.numpy()
        for got, want in zip(other.bvh.triangles(), corners, strict=True):
            np.testing.assert_array_equal(np.stack([c.numpy() for c in got], axis=1),
                                          want[order].astype(np.float32))


@pytest.mark.parametrize("name", ["instances_scaled", "knots"])
def test_instances_hit_the_same_whichever_builder_made_their_hierarchy(jit, tmp_path,
                                                                       monkeypatch, name):
    """The instances' hierarchy built on the host (a few instances) or on the device: each
    ray finds the same nearest hit (t and primitive: the same instances' answers, in
    another order) and the same occlusion."""
    from whitted.tracer import bvh
    from whitted.tracer.geometry import Geometry, _InstanceSetBlock

    scene = _instanced_scene(tmp_path, name)
    host = Geometry(scene)
    monkeypatch.setattr(bvh, "SMALL_BOX_SET", 0)
    device = Geometry(scene)
    assert any(isinstance(b, _InstanceSetBlock) for b in host.blocks)
    rng = np.random.default_rng(41)
    o, d = random_rays(rng, 20000, [-2.5, -1, -2.5], [2.5, 2.5, 2.5])
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    tmax = jit.Float(rng.uniform(0.0, 5.0, len(o)).astype(np.float32))
    a, b = (g.closest_hit(v3(jit, o), v3(jit, d), tmax) for g in (host, device))
    np.testing.assert_array_equal(a.t.numpy(), b.t.numpy())
    np.testing.assert_array_equal(a.prim.numpy(), b.prim.numpy())
    assert 0.01 < a.valid.numpy().mean() < 0.99   # hits and misses (knots: about 5 % hit)
    np.testing.assert_array_equal(host.occluded(v3(jit, o), v3(jit, d), tmax).numpy(),
                                  device.occluded(v3(jit, o), v3(jit, d), tmax).numpy())


def test_builds_of_two_mesh_sizes_launch_the_same_kernels(jit):
    """The BVH build's kernels take the count of a level's large nodes as an input, not a
    constant: a build of 40,000 triangles and one of 90,000 (levels of other counts)
    launch the same kernels. Before, each count compiled its own (issue 33)."""
    def kernels(nu, nv):
        p, f = torus(nu, nv)
        return {k["hash"] for k in jit_kernels(lambda: build_bvh(p[f[:, 0]], p[f[:, 1]],
                                                                 p[f[:, 2]]))}

    assert kernels(300, 150) == kernels(200, 100)


def _clusters(big: int, small: int):
    """Triangles in two unit cubes far apart, ``big`` in one and ``small`` in the other (as
    build_bvh's p0, p1, p2): the root splits them."""
    rng = np.random.default_rng(5)
    def cluster(n, at):
        return [(rng.random((n, 3)) + at).astype(np.float32) for _ in range(3)]
    b, s = cluster(big, 0.0), cluster(small, 100.0)
    return tuple(np.concatenate([u, v]) for u, v in zip(b, s, strict=True))


def test_a_levels_small_nodes_run_their_loop_in_one_kernel(jit):
    """The small nodes' loop (box, bins and three sweeps: the build's one kernel of several
    hundred operations; the next largest, the sum of a large node's chunk bins, has about
    260) is traced as one kernel for all its results, also on a level that mixes large
    and small nodes. Left lazy, its results were evaluated one by one by the large nodes'
    scatters, and folded into the leaf test on the other levels: four variants (issue 33).
    Two clusters: the root's children are one large node (more than a chunk of
    triangles) and one small."""
    from whitted.tracer.bvh import _chunk

    p = _clusters(5 * _chunk(), _chunk() // 2)
    ops = {k["hash"]: k["operation_count"] for k in jit_kernels(lambda: build_bvh(*p))}
    second, largest = sorted(ops.values())[-2:]
    assert largest > 2 * second, sorted(ops.values())   # one loop kernel, none like it


def _strip(n: int):
    """``n`` triangles side by side along x, each in its own plane x = const: binned splits
    fall near the middle of a node, so its halves hold about as many triangles."""
    x = ((np.arange(n) + 0.5) / n).astype(np.float32)
    o, one = np.zeros(n, np.float32), np.ones(n, np.float32)
    return (np.stack([x, o, o], 1), np.stack([x, one, o], 1), np.stack([x, o, one], 1))


@pytest.mark.parametrize("case", ["large root", "large root over a mixed level", "small root"])
def test_the_root_level_launches_the_kernels_of_the_levels_below(jit, monkeypatch, case):
    """Dr.Jit reads an array of one entry as a scalar, so the root's level (one node) traced
    kernels of its own, each compiled once more in a cold process; its arrays now hold
    an empty second node (bvh._padded), and every kernel it launches is launched again
    by a level below. A large root: a strip of six chunks of triangles, whose levels
    below hold two large nodes, then four, then only small ones; one whose next level
    holds one large node and one small (two clusters); a small root (a quarter of a
    chunk)."""
    from whitted.tracer import backend, bvh

    levels = []
    new_scope = backend.new_scope

    def next_level():  # _split_levels opens each level with a scope; the history so far
        levels.append({k["hash"] for k in dr.kernel_history() if k["type"] == dr.KernelType.JIT})
        new_scope()

    monkeypatch.setattr(backend, "new_scope", next_level)
    chunk = bvh._chunk()
    p = {"large root": lambda: _strip(6 * chunk),
         "large root over a mixed level": lambda: _clusters(5 * chunk, chunk // 2),
         "small root": lambda: _clusters(chunk // 4, 0)}[case]()
    levels.append({k["hash"] for k in jit_kernels(lambda: build_bvh(*p))})  # the last level
    root, below = levels[1], set().union(*levels[2:])
    assert len(levels) > 4 and root   # the triangles' boxes, the root, three levels below
    assert root <= below, f"{len(root - below)} of the root level's {len(root)} kernels"


def test_a_build_reads_within_its_arrays(jit, capfd):
    """Dr.Jit's debug mode checks each gather's index against its array and reports a read
    out of bounds. The empty node that pads the root's level has no last triangle: the
    partition reads its first instead (a read at 2^32 - 1 before)."""
    from whitted.tracer.bvh import _chunk

    dr.set_flag(dr.JitFlag.Debug, True)
    try:
        for p in (_strip(3 * _chunk()), _clusters(_chunk() // 4, 0), _clusters(3, 2)):
            build_bvh(*p)
    finally:
        dr.set_flag(dr.JitFlag.Debug, False)
    assert "out-of-bounds" not in capfd.readouterr().err


def test_packed_boxes_are_the_plain_rounding_of_the_padded_boxes_bit_for_bit():
    """pack_nodes' float32 boxes (bvh._outward, written column by column and stepping
    outwards only where rounding went inwards, issue 33) are, number for number, what
    the plain formula gives: pad by 2^-20 of the box's largest coordinate (and 1e-30),
    round to the nearest float32, step one float32 outwards where that lies inside the
    unpadded box; and they hold the float64 boxes."""
    from whitted.tracer.bvh import _outward

    rng = np.random.default_rng(8)
    for scale in (1e-38, 1e-30, 1e-3, 1.0, 1e6, 1e30):
        lo = rng.normal(size=(4000, 3)) * scale
        hi = lo + np.abs(rng.normal(size=(4000, 3))) * scale
        lo[::7], hi[::11] = 0.0, 0.0                     # zeros, and float32 values
        lo[::13], hi[::17] = np.float32(1.5) * scale, np.float32(2.5) * scale
        hi = np.maximum(hi, lo)
        pad = np.maximum(np.abs(lo), np.abs(hi)).max(axis=1, keepdims=True) * 2.0**-20 + 1e-30
        want_lo, want_hi = (lo - pad).astype(np.float32), (hi + pad).astype(np.float32)
        want_lo = np.where(want_lo > lo, np.nextafter(want_lo, np.float32(-np.inf)), want_lo)
        want_hi = np.where(want_hi < hi, np.nextafter(want_hi, np.float32(np.inf)), want_hi)
        got_lo, got_hi = _outward(lo, hi)
        assert got_lo.dtype == got_hi.dtype == np.float32
        np.testing.assert_array_equal(got_lo, want_lo)
        np.testing.assert_array_equal(got_hi, want_hi)
        assert (got_lo <= lo).all() and (got_hi >= hi).all()
