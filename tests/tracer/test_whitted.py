"""Whitted recursion: depth counting, Fresnel-weighted branches, radiance scaling, compaction.

Most cases have a closed form: an orthographic camera looks straight at an
area light (radiance 1) through glass, so every ray meets every boundary at
normal incidence, where R = R0 = ((n - 1) / (n + 1))^2.
"""

import tomllib

import numpy as np
import pytest

from whitted.tracer.integrator import Integrator
from whitted.tracer.scene import parse_scene

HEAD = """
[film]
width = 4
height = 4
spp = 1
max_depth = {depth}

[camera]
type = "orthographic"
origin = [0, 0, 5]
target = [0, 0, 0]
up = [0, 1, 0]
width = 0.5

[materials.glass]
type = "dielectric"
ior = {ior}

[materials.chrome]
type = "mirror"
reflectance = {mirror}

# The light: a rectangle at z = 0 facing the camera (+z), radiance 1.
[[shapes]]
type = "rectangle"
emitter = {{ radiance = 1 }}
to_world = [ {{ scale = 2 }} ]
"""

SLAB = """
# A glass slab between z = 0.5 and z = 1: front face normal +z, back face normal -z.
[[shapes]]
type = "rectangle"
material = "glass"
to_world = [ { scale = 2 }, { translate = [0, 0, 1] } ]

[[shapes]]
type = "rectangle"
material = "glass"
to_world = [ { scale = 2 }, { rotate = { axis = [1, 0, 0], angle = 180 } },
             { translate = [0, 0, 0.5] } ]
"""


def scene(text: str, depth: int, ior: float = 1.5, mirror: float = 1.0):
    return parse_scene(tomllib.loads(HEAD.format(depth=depth, ior=ior, mirror=mirror) + text))


def pixel(s) -> float:
    img = Integrator(s).render().image
    assert np.allclose(img, img[0, 0])  # every pixel sees the same thing
    return float(img[0, 0, 0])


def test_max_depth_one_sees_only_emitters():
    assert pixel(scene("", 1)) == pytest.approx(1.0)
    # Behind glass, the light needs three segments: camera-front, front-back, back-light.
    assert pixel(scene(SLAB, 1)) == 0 and pixel(scene(SLAB, 2)) == 0


@pytest.mark.parametrize("k", [0, 1, 2, 5])
def test_each_internal_round_trip_adds_two_segments(k):
    # max_depth = 3 + 2k follows k round trips inside the slab: the light arrives
    # attenuated by (1 - R)^2 sum_{j <= k} R^(2j); the (1/n)^2 and n^2 weights of
    # entering and leaving cancel.
    r = ((1.5 - 1) / (1.5 + 1)) ** 2
    expected = (1 - r) ** 2 * sum(r ** (2 * j) for j in range(k + 1))
    assert pixel(scene(SLAB, 3 + 2 * k)) == pytest.approx(expected, rel=1e-5)
    # One segment more does not complete another round trip.
    assert pixel(scene(SLAB, 4 + 2 * k)) == pytest.approx(expected, rel=1e-5)


def test_deep_recursion_converges_to_the_geometric_series():
    r = ((2.42 - 1) / (2.42 + 1)) ** 2  # diamond: R0 = 0.17, slow to converge
    assert pixel(scene(SLAB, 41, ior=2.42)) == pytest.approx((1 - r) / (1 + r), rel=1e-5)


def test_radiance_entering_glass_is_scaled_by_n1_over_n2_squared():
    # Only the front face: the light sits inside the glass. One crossing 1 -> n
    # seen from the camera weighs (1 - R0) (1/n)^2, and the light is seen once.
    front = SLAB.split("[[shapes]]")[1]
    r = 0.04
    assert pixel(scene("[[shapes]]" + front, 2)) == pytest.approx((1 - r) / 1.5 ** 2, rel=1e-5)


def test_light_seen_in_a_mirror_is_scaled_by_its_reflectance():
    # Camera looks down -z at a mirror; the light faces the mirror from behind the camera.
    text = HEAD.format(depth=2, ior=1.5, mirror=0.7).replace(
        "to_world = [ { scale = 2 } ]",
        "to_world = [ { scale = 2 }, { rotate = { axis = [1, 0, 0], angle = 180 } },"
        " { translate = [0, 0, 8] } ]") + """
[[shapes]]
type = "rectangle"
material = "chrome"
to_world = [ { scale = 2 } ]
"""
    s = parse_scene(tomllib.loads(text))
    # camera -> mirror -> light is two segments: max_depth 1 cannot see it, 2 can.
    assert pixel(s.with_overrides(max_depth=1)) == 0
    assert pixel(s) == pytest.approx(0.7, rel=1e-6)


def test_zero_weight_branches_are_dropped():
    # Equal indices: R = 0, so only the refracted branch survives each crossing.
    s = scene(SLAB, 6, ior=1.0)
    res = Integrator(s).render()
    assert res.rays_per_level == [16, 16, 16]
    assert float(res.image[0, 0, 0]) == pytest.approx(1.0)


TIR = """
[film]
width = 4
height = 4
spp = 1
max_depth = 2

[camera]
type = "orthographic"
origin = [0, 0, 5]
target = [0, 0, 0]
width = 0.5

[materials.glass]
type = "dielectric"
ior = 1.5

# A glass boundary whose normal points away from the camera: the camera is inside the
# glass. Its rays meet it at {incidence} degrees.
[[shapes]]
type = "rectangle"
material = "glass"
to_world = [ {{ scale = 2 }}, {{ rotate = {{ axis = [1, 0, 0], angle = {angle} }} }} ]

# A light above, facing down, where the mirrored rays go.
[[shapes]]
type = "rectangle"
emitter = {{ radiance = 1 }}
to_world = [ {{ scale = 20 }}, {{ rotate = {{ axis = [1, 0, 0], angle = 90 }} }},
             {{ translate = [0, 3, 0] }} ]
"""


@pytest.mark.parametrize("incidence", [60, 30])
def test_total_internal_reflection_spawns_no_refracted_ray(incidence):
    s = parse_scene(tomllib.loads(TIR.format(incidence=incidence, angle=180 - incidence)))
    res = Integrator(s).render()
    value = float(res.image[0, 0, 0])
    n = 1.5
    if incidence == 60:  # beyond asin(1/1.5) = 41.8 degrees: all light reflected
        assert res.rays_per_level == [16, 16]
        assert value == pytest.approx(1.0, rel=1e-6)
    else:                # below it: both branches reach the light
        assert res.rays_per_level == [16, 32]
        c = np.cos(np.radians(30))
        ct = np.sqrt(1 - (n * np.sin(np.radians(30))) ** 2)
        rs = (n * c - ct) / (n * c + ct)
        rp = (c - n * ct) / (c + n * ct)
        r = (rs ** 2 + rp ** 2) / 2
        # Reflected: weight R. Refracted out of the glass, n -> 1: (1 - R) (n / 1)^2.
        assert value == pytest.approx(r + (1 - r) * n ** 2, rel=1e-5)


def test_shadow_rays_are_blocked_by_glass():
    text = """
[film]
width = 8
height = 8
spp = 1
max_depth = 6

[camera]
type = "orthographic"
origin = [0, 5, 0]
target = [0, 0, 0]
up = [0, 0, -1]
width = 0.2

[materials.glass]
type = "dielectric"
ior = 1.5

[materials.white]
type = "diffuse"
reflectance = 1

[[lights]]
type = "directional"
direction = [0, -1, 0]
irradiance = 3.14159265

[[shapes]]
type = "rectangle"
material = "white"
to_world = [ { scale = 5 }, { rotate = { axis = [1, 0, 0], angle = -90 } } ]
"""
    open_sky = parse_scene(tomllib.loads(text))
    # Reflectance 1 under irradiance pi: radiance E / pi = 1.
    assert pixel(open_sky) == pytest.approx(1.0, rel=1e-6)
    # The same floor seen through a glass plate above it, which also stands in the
    # light's way: Whitted's shadow rays stop at glass, so no direct light remains.
    plate = text + """
[[shapes]]
type = "rectangle"
material = "glass"
to_world = [ { scale = 5 }, { rotate = { axis = [1, 0, 0], angle = -90 } },
             { translate = [0, 1, 0] } ]
"""
    assert pixel(parse_scene(tomllib.loads(plate))) == 0


def test_cost_follows_the_rays_traced_not_two_to_the_depth():
    from conftest import SCENES

    from whitted.tracer import load_scene

    s = load_scene(SCENES / "glass_sphere.toml").with_overrides(size=(40, 30), spp=4,
                                                                max_depth=25)
    res = Integrator(s).render()
    camera = 40 * 30 * 4
    # A depth of 25 finishes. The scene has no area light or environment, so the rays of
    # the 25th segment could only bring back nothing and are not traced: 24 levels.
    assert len(res.rays_per_level) == 24
    for a, b in zip(res.rays_per_level, res.rays_per_level[1:], strict=False):
        assert b <= 2 * a                          # at most two children per ray
    assert sum(res.rays_per_level) < 25 * camera   # nowhere near 2^25 x camera rays
    assert np.isfinite(res.image).all()
