"""Ray-shape intersection formulas against analytic values (lectures 1 and 2)."""

import math

import numpy as np
import pytest

from whitted.tracer.shapes import rectangle, sphere, triangle


def v3(jit, *rows):
    a = np.asarray(rows, dtype=np.float32).reshape(-1, 3)
    return jit.Array3f(a[:, 0], a[:, 1], a[:, 2])


def test_ray_sphere_two_roots_are_entry_and_exit(jit):
    # Ray along +z from z = -5 through a unit sphere at the origin: t = 4 and t = 6.
    t0, t1, real = sphere.roots(v3(jit, (0, 0, -5)), v3(jit, (0, 0, 1)), v3(jit, (0, 0, 0)),
                                jit.Float(1.0))
    assert bool(real[0]) and t0[0] == pytest.approx(4) and t1[0] == pytest.approx(6)


def test_ray_sphere_off_centre_roots_solve_the_quadratic(jit):
    # Offset 0.6 from the axis: half-chord sqrt(1 - 0.36) = 0.8.
    t0, t1, real = sphere.roots(v3(jit, (0.6, 0, -5)), v3(jit, (0, 0, 1)), v3(jit, (0, 0, 0)),
                                jit.Float(1.0))
    assert t0[0] == pytest.approx(5 - 0.8, rel=1e-6) and t1[0] == pytest.approx(5 + 0.8, rel=1e-6)


def test_ray_sphere_tangent_ray_has_one_root(jit):
    t0, t1, real = sphere.roots(v3(jit, (1, 0, -5)), v3(jit, (0, 0, 1)), v3(jit, (0, 0, 0)),
                                jit.Float(1.0))
    assert bool(real[0])
    assert t0[0] == pytest.approx(5, abs=1e-3) and t1[0] == pytest.approx(t0[0], abs=1e-3)


def test_ray_sphere_miss_has_no_real_root(jit):
    _, _, real = sphere.roots(v3(jit, (1.01, 0, -5)), v3(jit, (0, 0, 1)), v3(jit, (0, 0, 0)),
                              jit.Float(1.0))
    t, hit = sphere.intersect(v3(jit, (1.01, 0, -5)), v3(jit, (0, 0, 1)), v3(jit, (0, 0, 0)),
                              jit.Float(1.0), jit.Float(math.inf))
    assert not bool(real[0]) and not bool(hit[0])


def test_sphere_hit_from_inside_returns_far_root(jit):
    # Origin inside: one root is behind the origin (negative t), the hit is the other.
    o, d = v3(jit, (0, 0, 0.5)), v3(jit, (0, 0, 1))
    t0, t1, real = sphere.roots(o, d, v3(jit, (0, 0, 0)), jit.Float(2.0))
    assert t0[0] == pytest.approx(-2.5) and t1[0] == pytest.approx(1.5)
    t, hit = sphere.intersect(o, d, v3(jit, (0, 0, 0)), jit.Float(2.0), jit.Float(math.inf))
    assert bool(hit[0]) and t[0] == pytest.approx(1.5)


def test_sphere_behind_the_ray_is_not_hit(jit):
    t, hit = sphere.intersect(v3(jit, (0, 0, 5)), v3(jit, (0, 0, 1)), v3(jit, (0, 0, 0)),
                              jit.Float(1.0), jit.Float(math.inf))
    assert not bool(hit[0])


def test_ray_sphere_roots_stay_accurate_far_away(jit):
    # 1e4 units away, a naive b^2 - ac loses every digit of a unit sphere's chord in float32.
    t0, t1, real = sphere.roots(v3(jit, (0.6, 0, -1e4)), v3(jit, (0, 0, 1)), v3(jit, (0, 0, 0)),
                                jit.Float(1.0))
    assert bool(real[0]) and (t1[0] - t0[0]) == pytest.approx(1.6, rel=2e-3)


def test_sphere_normal_is_normalised_gradient(jit):
    # grad(|p - c|^2 - r^2) = 2 (p - c); normalised it is (p - c) / r.
    n = sphere.normal(v3(jit, (1, 2, 2 + 3)), v3(jit, (1, 2, 2)), jit.Float(3.0))
    assert np.allclose(np.asarray(n).ravel(), [0, 0, 1])


def test_ray_plane_parameter(jit):
    # Plane z = 2 (normal +z through (0,0,2)); ray from origin along (0, 0.6, 0.8): t = 2 / 0.8.
    t = rectangle.plane_t(v3(jit, (0, 0, 0)), v3(jit, (0, 0.6, 0.8)), v3(jit, (0, 0, 2)),
                          v3(jit, (0, 0, 1)))
    assert t[0] == pytest.approx(2.5)


def test_ray_rectangle_local_coordinates_with_shear(jit):
    c, u, v = np.array([1.0, 0, 0]), np.array([2.0, 0, 0]), np.array([1.0, 1.0, 0])
    n, ud, vd = rectangle.frame(c, u, v)
    p = c + 0.25 * u - 0.5 * v  # local (0.25, -0.5)
    t, hit, a, b = rectangle.intersect(v3(jit, p + [0, 0, 3]), v3(jit, (0, 0, -1)), v3(jit, c),
                                       v3(jit, n), v3(jit, ud), v3(jit, vd), jit.Float(math.inf))
    assert bool(hit[0]) and t[0] == pytest.approx(3)
    assert a[0] == pytest.approx(0.25, abs=1e-6) and b[0] == pytest.approx(-0.5, abs=1e-6)
    q = c + 1.01 * u  # just outside |a| <= 1
    _, hit, _, _ = rectangle.intersect(v3(jit, q + [0, 0, 3]), v3(jit, (0, 0, -1)), v3(jit, c),
                                       v3(jit, n), v3(jit, ud), v3(jit, vd), jit.Float(math.inf))
    assert not bool(hit[0])


def test_ray_triangle_barycentrics_solve_the_ray_plane_system(jit):
    p0, p1, p2 = np.array([0.0, 0, 0]), np.array([2.0, 0, 0]), np.array([0.0, 3, 0])
    bary = np.array([0.2, 0.5, 0.3])                       # (1 - beta - gamma, beta, gamma)
    target = bary[0] * p0 + bary[1] * p1 + bary[2] * p2
    o = target + np.array([0.3, -0.2, 4.0])
    d = (target - o) / np.linalg.norm(target - o)
    t, hit, beta, gamma = triangle.intersect(v3(jit, o), v3(jit, d), v3(jit, p0),
                                             v3(jit, p1), v3(jit, p2), jit.Float(math.inf))
    # The same 3x3 system solved by numpy: [e1 e2 -d] (beta, gamma, t) = o - p0.
    m = np.column_stack([p1 - p0, p2 - p0, -d])
    ref = np.linalg.solve(m, o - p0)
    assert bool(hit[0])
    assert beta[0] == pytest.approx(0.5, abs=1e-6) and gamma[0] == pytest.approx(0.3, abs=1e-6)
    assert np.allclose([beta[0], gamma[0], t[0]], ref, atol=1e-5)
    interp = triangle.interpolate(beta, gamma, jit.Float(10), jit.Float(20), jit.Float(30))
    assert interp[0] == pytest.approx(0.2 * 10 + 0.5 * 20 + 0.3 * 30, rel=1e-6)


def test_ray_triangle_outside_barycentric_range_misses(jit):
    p0, p1, p2 = v3(jit, (0, 0, 0)), v3(jit, (1, 0, 0)), v3(jit, (0, 1, 0))
    # beta + gamma = 1.2 > 1, beta < 0 and a ray parallel to the plane: all miss.
    o = v3(jit, (0.6, 0.6, 1), (-0.1, 0.5, 1), (0.2, 0.2, 1))
    d = v3(jit, (0, 0, -1), (0, 0, -1), (1, 0, 0))
    _, hit, _, _ = triangle.intersect(o, d, p0, p1, p2, jit.Float(math.inf))
    assert not np.any(np.asarray(hit))


def test_triangle_face_normal_follows_counter_clockwise_order(jit):
    n = triangle.normal(v3(jit, (1, 0, 0)), v3(jit, (0, 1, 0)))
    assert np.allclose(np.asarray(n).ravel(), [0, 0, 1])


# --- the sphere tests without a division: occludes (shadow rays) and nearest_fraction ------


def _sphere_rays(n: int, seed: int):
    """Unit rays about a sphere of radius 1.5 at (0.3, -0.2, 0.1): origins outside, inside,
    on the surface moved off it by a spawn offset to either side, and tangent; a third
    of them aimed at the sphere. Float32 numpy arrays (o, d, centre, radius)."""
    rng = np.random.default_rng(seed)
    centre, radius = np.array([0.3, -0.2, 0.1], np.float32), np.float32(1.5)
    kind = rng.integers(0, 4, n)
    u = rng.normal(size=(n, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    dist = np.where(kind == 0, rng.uniform(1.6, 20, n),             # outside
                    np.where(kind == 1, rng.uniform(0, 1.4, n),      # inside
                             1.5 * (1 + rng.choice([-1, 1], n) * 1500 * 2.0 ** -24 * 3)))
    o = centre + u * dist[:, None]
    d = rng.normal(size=(n, 3))
    aim = rng.random(n) < 1 / 3
    d[aim] = (centre + rng.normal(scale=0.8, size=(aim.sum(), 3))) - o[aim]
    tangent = kind == 3   # d perpendicular to the radius through o: grazing
    w = np.cross(u[tangent], rng.normal(size=(tangent.sum(), 3)))
    d[tangent] = w
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return o.astype(np.float32), d.astype(np.float32), centre, radius


def _vec(jit, a):
    return jit.Array3f(a[:, 0], a[:, 1], a[:, 2])


@pytest.mark.parametrize("seed", [7, 8])
def test_occludes_answers_as_the_nearest_hit_does(jit, seed):
    # The shadow rays' test (no division, no square root) must say "blocked" exactly where
    # intersect() finds a root in (0, tmax), for tmax infinite, far, and close to a root.
    # It may differ only where a root lies within rounding of tmax (documented in
    # occludes): such rays are left out, with a margin of 1e-5 relative, far above float32
    # rounding (6e-8) and far below the shadow rays' own 1e-3 (SHADOW_EPSILON).
    o, d, centre, radius = _sphere_rays(60_000, seed=seed)
    c, r = jit.Array3f(*(float(x) for x in centre)), jit.Float(float(radius))
    t_all, _ = sphere.intersect(_vec(jit, o), _vec(jit, d), c, r, jit.Float(math.inf))
    t_all = np.asarray(t_all.numpy(), np.float64)
    rng = np.random.default_rng(3)
    choices = [np.full(len(o), np.inf), rng.uniform(0.01, 30, len(o)),
               np.where(np.isfinite(t_all) & (t_all > 0),
                        t_all * (1 + rng.choice([-1, 1], len(o)) * 1e-3), 1.0)]
    for tmax in choices:
        tmax = tmax.astype(np.float32)
        _, hit = sphere.intersect(_vec(jit, o), _vec(jit, d), c, r, jit.Float(tmax))
        blocked = sphere.occludes(_vec(jit, o), _vec(jit, d), c, r, jit.Float(tmax))
        t0, t1, real = (np.asarray(x.numpy(), np.float64) for x in
                        sphere.roots(_vec(jit, o), _vec(jit, d), c, r, unit=True))
        near_tmax = real.astype(bool) & np.isfinite(tmax) & ((np.abs(t0 - tmax) <= 1e-5 * tmax) |
                                         (np.abs(t1 - tmax) <= 1e-5 * tmax))
        hit, blocked = hit.numpy(), blocked.numpy()
        assert hit.any() and (~hit).any()
        assert np.array_equal(hit[~near_tmax], blocked[~near_tmax])
        assert near_tmax.mean() < 0.01


def test_nearest_fraction_is_the_nearest_positive_of_both_roots(jit):
    # intersect() (and a block of spheres) take the root nearest_fraction picks by signs,
    # never comparing two quotients: it must be the lecture's rule applied to both roots
    # of roots(), t0 if t0 > 0 else t1, to the bit, on rays from outside, inside, near the
    # surface and grazing. Where the two roots are equal within rounding (tangent rays)
    # either is right, and those rays are left out.
    o, d, centre, radius = _sphere_rays(60_000, seed=11)
    c, r = jit.Array3f(*(float(x) for x in centre)), jit.Float(float(radius))
    t0, t1, real = (x.numpy() for x in sphere.roots(_vec(jit, o), _vec(jit, d), c, r,
                                                     unit=True))
    want = np.where(t0 > 0, t0, t1)
    want_hit = real & (want > 0)
    num, den, found = sphere.nearest_fraction(_vec(jit, o), _vec(jit, d), c, r)
    t, hit = sphere.intersect(_vec(jit, o), _vec(jit, d), c, r, jit.Float(math.inf))
    found, hit = found.numpy(), hit.numpy()
    assert want_hit.mean() > 0.3 and (~want_hit).any()
    assert np.array_equal(found, want_hit) and np.array_equal(hit, want_hit)
    assert (den.numpy() > 0).all()
    apart = want_hit & (np.abs(t1 - t0) > 1e-6 * np.abs(t1))
    assert apart.mean() > 0.25
    assert np.array_equal((num / den).numpy()[apart], want[apart])
    assert np.array_equal(t.numpy()[apart], want[apart])


@pytest.mark.parametrize("count", [8, 20])
def test_spheres_nearest_hit_and_occlusion_against_each_sphere_alone(jit, count):
    # Overlapping spheres in one block: the block's nearest hit must be the nearest of each
    # sphere's own intersect(), and the shadow test blocked where that nearest hit lies
    # before tmax. 8 spheres are written into the kernel (roots compared as fractions, one
    # division), 20 are looped over (more than tracer.geometry.UNROLL).
    from whitted.tracer.geometry import UNROLL

    assert (count > UNROLL) == (count == 20)
    from whitted.tracer.geometry import _SphereBlock
    from whitted.tracer.scene import Sphere

    rng = np.random.default_rng(5)
    centres = rng.uniform(-2, 2, size=(count, 3))
    radii = rng.uniform(0.4, 1.2, count)
    block = _SphereBlock([Sphere(material="m", center=tuple(map(float, p)), radius=float(q))
                          for p, q in zip(centres, radii, strict=True)])
    n = 40_000
    o = rng.uniform(-4, 4, size=(n, 3)).astype(np.float32)
    d = rng.normal(size=(n, 3))
    d[: n // 2] = rng.uniform(-2, 2, size=(n // 2, 3)) - o[: n // 2]   # half aimed inside
    d = (d / np.linalg.norm(d, axis=1, keepdims=True)).astype(np.float32)
    tmax = rng.uniform(0.1, 8, n).astype(np.float32)
    each = []
    for p, q in zip(centres, radii, strict=True):
        ti, hi = sphere.intersect(_vec(jit, o), _vec(jit, d),
                                  jit.Array3f(*(float(x) for x in p)), jit.Float(float(q)),
                                  jit.Float(math.inf))
        each.append(np.where(hi.numpy(), ti.numpy(), np.inf))
    each = np.array(each)
    nearest, which = each.min(axis=0), each.argmin(axis=0)
    every = jit.Bool(np.ones(n, bool))
    t, prim = block.intersect(_vec(jit, o), _vec(jit, d), jit.Float(np.full(n, np.inf)),
                              jit.UInt32(np.full(n, 0xFFFFFFFF, np.uint32)), every)
    t, prim = t.numpy(), prim.numpy()
    hit = np.isfinite(nearest)
    assert 0.2 < hit.mean() < 0.9
    assert np.array_equal(prim != 0xFFFFFFFF, hit)
    second = np.sort(each, axis=0)[1]
    clear = hit & (second > nearest * (1 + 1e-6))   # no other sphere within rounding
    assert np.array_equal(prim[clear], which[clear])
    assert np.array_equal(t[clear], nearest[clear])
    blocked = block.occluded(_vec(jit, o), _vec(jit, d), jit.Float(tmax), every).numpy()
    sure = np.abs(nearest - tmax) > 1e-5 * tmax
    assert np.array_equal(blocked[sure], (nearest < tmax)[sure])
