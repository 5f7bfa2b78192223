"""Area lights: sampling a sphere by solid angle, a rectangle by area, and converting between them.

Each estimator is checked against the irradiance it must converge to, in
closed form, within 5 standard errors of the Monte Carlo mean (a 6e-7
two-sided false-alarm rate under the normal approximation).
"""

import math

import drjit as dr
import numpy as np
import pytest

from whitted.tracer import lights
from whitted.tracer.emitters.area import Emitter as AreaLight
from whitted.tracer.scene import AreaEmitter, Rectangle, Sphere
from whitted.tracer.transform import rotate, scale, translate

N = 1 << 20


def _u(jit, n=N, seed=0):
    rng = np.random.default_rng(seed)
    return jit.Array2f(rng.random(n, dtype=np.float32), rng.random(n, dtype=np.float32))


def _irradiance(jit, light, p, normal):
    """Monte Carlo estimate of E = integral L cos(theta) d(omega) at p with normal n."""
    pp = jit.Array3f(*(np.full(N, c, np.float32) for c in p))
    wi, _, value = light.sample(pp, pp, _u(jit))
    x = np.asarray(value)[0] * np.maximum(np.asarray(wi).T @ np.asarray(normal), 0)
    return x.mean(), x.std() / math.sqrt(N)


@pytest.mark.parametrize("dist", [1.5, 4.0, 20.0])
def test_sphere_light_sampled_by_solid_angle_gives_its_irradiance(jit, dist):
    # On the axis, facing the sphere: E = L pi sin^2(theta_max), sin(theta_max) = r / d.
    sphere = Sphere((0, 0, dist), 1.0, None, AreaEmitter((2.0, 2.0, 2.0)))
    est, se = _irradiance(jit, AreaLight(sphere, 0), (0, 0, 0), (0, 0, 1))
    expected = 2.0 * math.pi * (1 / dist) ** 2
    assert abs(est - expected) < 5 * se + 1e-6 * expected, (est, expected, se)


def test_cone_sampling_pdf_is_uniform_in_the_subtended_solid_angle(jit):
    cos_max = math.cos(math.radians(25))
    x, y, z, pdf = lights.sample_cone(_u(jit), jit.Float(cos_max))
    z = np.asarray(z)
    assert z.min() >= cos_max - 1e-6 and z.max() <= 1 + 1e-6
    assert np.asarray(pdf)[0] == pytest.approx(1 / (2 * math.pi * (1 - cos_max)), rel=1e-5)
    # Uniform in solid angle: cos(theta) is uniform on [cos_max, 1].
    hist, _ = np.histogram(z, bins=10, range=(cos_max, 1))
    assert np.all(np.abs(hist / len(z) - 0.1) < 5 * math.sqrt(0.1 * 0.9 / len(z)))


def _corner_irradiance(x, y, h):
    """Irradiance under a corner of an x-by-y rectangle of radiance 1 at height h (facing it).

    The configuration factor of a parallel rectangle seen from a point under
    its corner (Howell's catalogue, "A Catalog of Radiation Heat Transfer
    Configuration Factors", case B-3), times pi.
    """
    a, b = x / h, y / h
    return 0.5 * (a / math.sqrt(1 + a * a) * math.atan(b / math.sqrt(1 + a * a)) +
                  b / math.sqrt(1 + b * b) * math.atan(a / math.sqrt(1 + b * b)))


@pytest.mark.parametrize("h", [0.5, 2.0])
def test_rectangle_light_sampled_by_area_gives_its_irradiance(jit, h):
    # A 2 x 1.2 rectangle at height h facing down; the point below its centre sees
    # four corner rectangles of 1 x 0.6.
    m = translate((0, 0, h)) @ rotate((1, 0, 0), 180) @ scale((1.0, 0.6, 1))
    rect = Rectangle(tuple(map(tuple, m)), None, AreaEmitter((3.0, 3.0, 3.0)))
    est, se = _irradiance(jit, AreaLight(rect, 0), (0, 0, 0), (0, 0, 1))
    expected = 3.0 * 4 * _corner_irradiance(1.0, 0.6, h)
    assert abs(est - expected) < 5 * se, (est, expected, se)


def test_rectangle_light_emits_only_from_its_front(jit):
    m = translate((0, 0, 2)) @ scale((1.0, 1.0, 1))  # faces +z, away from the point below
    rect = Rectangle(tuple(map(tuple, m)), None, AreaEmitter((3.0, 3.0, 3.0)))
    est, _ = _irradiance(jit, AreaLight(rect, 0), (0, 0, 0), (0, 0, 1))
    assert est == 0


def test_area_and_solid_angle_measures_convert_by_r2_over_cos(jit):
    # The same sphere light by uniform area sampling, converted to solid angle by
    # pdf_omega = pdf_A r^2 / |cos theta_l|, gives the same irradiance as cone sampling.
    center, radius, dist, L = np.array([0.0, 0, 3.0]), 1.0, 3.0, 2.0
    pts, normals = lights.sample_sphere_uniform(_u(jit, seed=3),
                                                jit.Array3f(*center.tolist()), radius)
    y, n = np.asarray(pts).T.astype(np.float64), np.asarray(normals).T.astype(np.float64)
    to = y                                         # from the shading point at the origin
    r = np.linalg.norm(to, axis=1)
    wi = to / r[:, None]
    cos_l = -np.sum(n * wi, axis=1)                # the light faces the point: cos_l > 0
    pdf_a = 1 / (4 * math.pi * radius ** 2)
    pdf_w = np.asarray(lights.area_to_solid_angle_pdf(
        jit.Float(np.full(N, pdf_a, np.float32)), jit.Float(r.astype(np.float32)),
        jit.Float(cos_l.astype(np.float32))))
    x = np.where(cos_l > 0, L * np.maximum(wi[:, 2], 0) / pdf_w, 0)
    est, se = x.mean(), x.std() / math.sqrt(N)
    cone_est, cone_se = _irradiance(jit, AreaLight(
        Sphere(tuple(center), radius, None, AreaEmitter((L, L, L))), 0), (0, 0, 0), (0, 0, 1))
    expected = L * math.pi * (radius / dist) ** 2
    assert abs(est - expected) < 5 * se
    assert abs(cone_est - expected) < 5 * cone_se + 1e-6
    # Solid angle sampling has far less variance for a small, distant sphere.
    assert cone_se < se


def test_flat_area_light_never_shadows_its_own_sample_at_grazing_angles(jit):
    # A triangle light tilted so that its plane meets the floor along a line: floor points
    # just in front of that line see the light at grazing angles. The shadow ray starts
    # off the floor (the ray offset); aimed along wi from there, it would cross the
    # light's plane short of the sample, on the light itself, and the light would shadow
    # its own light (the tracer did, before shadow_ray aimed at the sample). Aimed at the
    # sample from the offset origin, as Mitsuba's spawn_ray_to does, it never is.
    from whitted.tracer.geometry import Geometry, spawn_offset
    from whitted.tracer.integrator import SHADOW_EPSILON
    from whitted.tracer.scene import parse_scene

    scene = parse_scene({
        "camera": {"origin": [0, 1, 5], "target": [0, 0, 0]},
        "shapes": [{"type": "triangle", "emitter": {"radiance": [1, 1, 1]},
                    "vertices": [[1.097, 1.626, -0.749], [1.813, 2.187, -0.466],
                                 [0.99, 2.187, 0.014]]}]})
    light = AreaLight(scene.shapes[0], 0)
    geo = Geometry(scene)
    n = 4096
    rng = np.random.default_rng(1)
    # Floor points (y = 0) near where the light's plane meets the floor, on its front side.
    c, nl = np.array([1.3, 2.0, -0.4]), np.array([0.3425, -0.73337, 0.58725])
    pts = []
    while len(pts) < n:
        q = np.array([rng.uniform(-1, 6), 0.0, rng.uniform(-8, 2)])
        if 0 < np.dot(q - c, nl) < 0.3:
            pts.append(q)
    p = jit.Array3f(*np.asarray(pts, np.float32).T)
    origin = p + jit.Array3f(0, 1, 0) * spawn_offset(p)
    wi, dist, value = light.sample(p, origin, _u(jit, n))
    lit = np.asarray(value)[0] > 0
    assert lit.mean() > 0.9            # the light's front side faces these points
    d, length = light.shadow_ray(p, origin, wi, dist)
    blocked = np.asarray(geo.occluded(origin, d, length * (1 - SHADOW_EPSILON)))
    # Below cos(theta_l) ~ 1e-4 the point p + dist wi, recomputed in float32 (an error of
    # ~1e-6), may lie beyond the ray's end margin of 1e-3 x length x cos(theta_l); such
    # samples carry under 1e-3 of a head-on sample's light, which no check can see.
    cos_l = -np.asarray(wi).T.astype(np.float64) @ nl
    clear = lit & (cos_l > 1e-3)
    assert clear.mean() > 0.8
    assert not blocked[clear].any()
    # The configuration is the grazing one: along wi, as far as the sample, the ray
    # would have met the light itself for a good part of the points.
    along = np.asarray(geo.occluded(origin, wi, dist * (1 - SHADOW_EPSILON)))
    assert along[clear].mean() > 0.2


@pytest.mark.parametrize("name", ["area_lights", "shape_lights", "three_lights", "mesh_knot"])
def test_the_geometry_says_which_primitives_emit(jit, name):
    """Geometry.emitting(): the primitives of the shapes that carry an area emitter, and
    no others. A geometry with none keeps one zero radiance rather than a row a
    primitive (issue 33: the 1,000,000-triangle knot placed twice made 3,000,000 rows of
    zeros), and its answer still has a row a primitive."""
    from conftest import SCENES

    from whitted.tracer.geometry import Geometry
    from whitted.tracer.scene import load_scene

    scene = load_scene(SCENES / f"{name}.toml")
    geo = Geometry(scene)
    emits = geo.emitting()
    assert emits.shape == (max(geo.count, 1),)
    emitting = [s for s in scene.shapes if getattr(s, "emitter", None) is not None]
    assert emits.sum() == sum(s.primitive_count() for s in emitting)
    if emitting:
        assert dr.width(geo.radiance) == geo.count
    else:
        assert dr.width(geo.radiance) == 1
