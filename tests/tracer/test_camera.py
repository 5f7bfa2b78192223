"""Camera rays: the lecture's construction, and Mitsuba's sensors for the same film positions."""

import math

import numpy as np
import pytest

from whitted.tracer.camera import frame, generate_rays
from whitted.tracer.scene import Camera


def _rays(jit, cam, w, h, xs, ys):
    o, d, tmax = generate_rays(cam, w, h, jit.Float(np.asarray(xs, np.float32)),
                               jit.Float(np.asarray(ys, np.float32)))
    return np.asarray(o).T, np.asarray(d).T, np.asarray(tmax)


def test_perspective_bottom_left_and_upper_right_rays(jit):
    # Lecture 1: the bottom-left ray is f - tan(fov/2) r - tan(fov/2)/aspect u,
    # the upper-right ray f + tan r + tan/aspect u (normalised here).
    cam = Camera("perspective", (0, 0, 0), (0, 0, -1), (0, 1, 0), fov=90)
    w, h = 200, 100
    _, d, _ = _rays(jit, cam, w, h, [0, w], [h, 0])
    tan = math.tan(math.radians(45))
    bl = np.array([-tan, -tan / 2, -1.0])
    ur = np.array([tan, tan / 2, -1.0])
    assert np.allclose(d[0], bl / np.linalg.norm(bl), atol=1e-6)
    assert np.allclose(d[1], ur / np.linalg.norm(ur), atol=1e-6)


def test_world_plus_x_appears_on_the_right_and_row_zero_on_top(jit):
    cam = Camera("perspective", (0, 0, 5), (0, 0, 0), (0, 1, 0), fov=40)
    r, up, f = frame(cam)
    assert np.allclose(r, [1, 0, 0]) and np.allclose(up, [0, 1, 0]) and np.allclose(f, [0, 0, -1])
    _, d, _ = _rays(jit, cam, 10, 10, [9.5, 5], [5, 0.5])
    assert d[0, 0] > 0 and d[1, 1] > 0


def test_perspective_ray_starts_on_near_plane(jit):
    cam = Camera("perspective", (1, 2, 3), (1, 2, 0), (0, 1, 0), fov=60, near_clip=0.5,
                 far_clip=100)
    o, d, tmax = _rays(jit, cam, 4, 4, [0.5], [3.5])
    # Distance along the view axis from the eye is near_clip, along the ray it is near/cos.
    assert (3 - o[0, 2]) == pytest.approx(0.5, rel=1e-5)
    cos = -d[0, 2]
    assert tmax[0] == pytest.approx((100 - 0.5) / cos, rel=1e-5)


def test_orthographic_rays_are_parallel(jit):
    cam = Camera("orthographic", (3, 4, 5), (0, 0, 0), (0, 1, 0), width=6)
    o, d, _ = _rays(jit, cam, 30, 20, [0, 15, 30, 7.5], [0, 10, 20, 3])
    f = -np.array([3, 4, 5]) / np.linalg.norm([3, 4, 5])
    assert np.allclose(d, f, atol=1e-6)
    # The view is `width` wide: left and right edges 6 units apart, across the view axis.
    assert np.linalg.norm(o[2] - o[0] - np.dot(o[2] - o[0], f) * f) == pytest.approx(
        math.hypot(6, 6 * 20 / 30), rel=1e-5)


@pytest.mark.parametrize("kind, fov_axis", [
    ("perspective", "x"), ("orthographic", "x"),
    # the film is not square, so each axis gives another horizontal field of view; Mitsuba
    # is given fov and fov_axis as written and converts them itself (parse_fov)
    ("perspective", "y"), ("perspective", "diagonal"), ("perspective", "smaller"),
    ("perspective", "larger")])
def test_camera_rays_match_mitsubas_sensor(jit, mi, kind, fov_axis):
    from whitted.reference.renderers.mitsuba.scene import sensor_tree, to_dict
    from whitted.tracer.scene import Film, Scene

    cam = Camera(kind, (0.3, 1.5, 4), (0.1, 0.4, 0), (0, 1, 0), fov=50, width=3,
                 fov_axis=fov_axis)
    w, h = 40, 30
    scene = Scene("x", Film(w, h, 1, 2), cam, {}, (), ())
    sensor = mi.load_dict(to_dict(sensor_tree(scene), mi))
    xs = np.array([0.5, 13.25, 39.5, 20.0], np.float32)
    ys = np.array([0.5, 7.75, 29.5, 15.0], np.float32)
    ray, _ = sensor.sample_ray(0.0, 0.5, mi.Point2f(xs / w, ys / h), mi.Point2f(0.5))
    o, d, _ = _rays(jit, cam, w, h, xs, ys)
    assert np.allclose(np.asarray(ray.d).T, d, atol=2e-6)
    assert np.allclose(np.asarray(ray.o).T, o, atol=2e-5)
