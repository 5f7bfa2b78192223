"""Primary rays of the perspective and orthographic cameras.

The camera frame is Mitsuba's ``look_at(origin, target, up)``: forward
f = normalize(target - origin), right r = normalize(f x up), up' = r x f.
A film position (x, y) in pixels, with (0, 0) the top-left corner of the
image and (width, height) the bottom-right, maps to normalised coordinates
u = x / width in [0, 1] (left to right) and v = y / height in [0, 1] (top to
bottom), so that world +x appears on the right of a camera that looks down -z
with +y up, and row 0 is the top row.

Perspective (lecture 1, "Perspective camera construction"): with the
horizontal field of view fov and aspect = width / height, the image plane at
distance 1 spans tan(fov / 2) to either side horizontally and
tan(fov / 2) / aspect vertically; the ray through (u, v) has direction

    d = f + (2u - 1) tan(fov/2) r + (1 - 2v) tan(fov/2) / aspect up'.

Its bottom-left ray (u, v) = (0, 1) is f - tan r - tan/aspect up', its
upper-right ray (1, 0) is f + tan r + tan/aspect up'. As in Mitsuba, the ray
starts on the near plane (near_clip along f) and ends on the far plane.

``pixel_offset`` (dx, dy) moves every film position by that many pixels
before the mapping: (-0.5, -0.5) puts the one sample of a pixel on its
upper-left corner, as Heckbert's minray does (its ray for pixel (x, y) goes
through (x - W/2, W/2 / tan(fov/2), H/2 - y) on an image plane that spans
the field of view, i.e. through film position (x, y)).

``fov_axis`` other than "x" is converted to the horizontal field of view as
Mitsuba does (:meth:`tracer.scene.Camera.fov_x`); Mitsuba's principal point
offset (ppx, ppy), in fractions of the film, moves every film position by
(ppx W, ppy H) pixels, as its ``perspective`` sensor adds it to the sample.

A camera given by ``to_world`` (a 4x4 matrix M) takes its frame from M's
columns: local +x is the image's left, +y its top, +z the view direction,
the fourth column the eye (Mitsuba's camera space). An orthographic camera
then spans [-1, 1] x [-1/aspect, 1/aspect] of its local xy plane, scaled by
M, so that its rays start at M (x, y, near_clip) and run along M's +z.

Orthographic: all rays are parallel to f; the view is ``width`` wide in
world units and width / aspect high, and a ray starts at
origin + (2u - 1) width/2 r + (1 - 2v) width/2 / aspect up' + near_clip f.

The camera's numbers and the film's size enter the kernel as opaque values
(:func:`_number`), not as constants written into it: one compiled kernel then
serves a scene at every film size and every pixel offset (a quick report renders
each scene at three sizes, LuxCore's vote at eight offsets; issue 33;
tests/tracer/test_kernel_cache.py). A division by such a number is written as
the product with its float32 reciprocal, which is what Dr.Jit makes of a
division by a constant: the operations are those of the constants' kernel,
though LLVM, no longer folding the constants, may round a value differently
in its last bit.
"""

import math

import drjit as dr
import numpy as np

from whitted.tracer import faults
from whitted.tracer.backend import jit
from whitted.tracer.scene import Camera


def frame(camera: Camera) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(right, up', forward) unit vectors of the camera, float64."""
    if camera.matrix is not None:
        m = np.asarray(camera.matrix, dtype=np.float64)[:3, :3]
        cols = [-m[:, 0], m[:, 1], m[:, 2]]  # local +x is the image's left
        return tuple(c / np.linalg.norm(c) for c in cols)
    f = np.subtract(camera.target, camera.origin).astype(np.float64)
    f /= np.linalg.norm(f)
    r = np.cross(f, camera.up)
    r /= np.linalg.norm(r)
    return r, np.cross(r, f), f


def _number(x):
    """A float32 kernel input of value ``x``, not written into the kernel (see above)."""
    return dr.opaque(jit.Float, float(x))


def _reciprocal(x):
    """1 / x as Dr.Jit divides by a constant: the float32 reciprocal of float32(x)."""
    return _number(np.float32(1) / np.float32(x))


def _vec(v):
    return jit.Array3f(*(_number(v[k]) for k in range(3)))


def generate_rays(camera: Camera, width: int, height: int, film_x, film_y):
    """(origin, unit direction, tmax) of the rays through film positions (pixels)."""
    r, up, f = (_vec(x) for x in frame(camera))
    aspect = width / height
    dx, dy = camera.pixel_offset
    ppx, ppy = camera.principal_point
    dx, dy = dx + ppx * width, dy + ppy * height
    if dx or dy:
        film_x, film_y = film_x + _number(dx), film_y + _number(dy)
    inv_w, inv_h, inv_aspect = _reciprocal(width), _reciprocal(height), _reciprocal(aspect)
    sx = 2 * (film_x * inv_w) - 1          # -1 left .. +1 right
    sy = 1 - 2 * (film_y * inv_h)          # +1 top .. -1 bottom
    sy = faults.pick("camera-y-not-flipped", lambda: 2 * (film_y * inv_h) - 1, sy)
    eye = _vec(camera.origin)
    near, far = _number(camera.near_clip), _number(camera.far_clip)
    if camera.type == "perspective":
        tan_half = _number(math.tan(math.radians(camera.fov_x(aspect)) / 2))
        d = f + (sx * tan_half) * r + (sy * tan_half * inv_aspect) * up
        d = faults.pick("fov-vertical-for-horizontal",
                        lambda: f + (sx * tan_half * _number(aspect)) * r
                        + (sy * tan_half) * up, d)
        length = dr.norm(d)               # = 1 / cos(angle to the axis)
        d = d / length
        near_t = near * length
        o = eye + d * near_t
        tmax = far * length - near_t
    elif camera.matrix is not None:
        m = np.asarray(camera.matrix, dtype=np.float64)
        left, top, ahead = (_vec(m[:3, i]) for i in range(3))
        o = eye - sx * left + (sy * inv_aspect) * top + near * ahead
        d = dr.normalize(ahead) + dr.zeros(jit.Array3f, dr.width(film_x))
        tmax = _number(camera.far_clip - camera.near_clip) + dr.zeros(jit.Float, dr.width(film_x))
    else:
        half = _number(camera.width / 2)
        half = faults.pick("ortho-width-as-half", lambda: _number(camera.width), half)
        o = eye + (sx * half) * r + (sy * half * inv_aspect) * up + near * f
        d = f + dr.zeros(jit.Array3f, dr.width(film_x))
        tmax = _number(camera.far_clip - camera.near_clip) + dr.zeros(jit.Float, dr.width(film_x))
    return o, d, tmax
