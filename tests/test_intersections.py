"""Ray-shape intersection formulas against analytic values (lectures 1 and 2)."""

import math

import numpy as np
import pytest

from tracer.shapes import rectangle, sphere, triangle


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
