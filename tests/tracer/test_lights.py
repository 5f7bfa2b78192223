"""Light sources: inverse-square law, Lambert's cosine, Mitsuba's spot profile."""

import math

import numpy as np

from whitted.tracer import lights


def v3(jit, *rows):
    a = np.asarray(rows, dtype=np.float32).reshape(-1, 3)
    return jit.Array3f(a[:, 0], a[:, 1], a[:, 2])


def test_inverse_square_falloff(jit):
    # Doubling the distance quarters the irradiance: E = I / r^2.
    p = v3(jit, (0, 0, 1), (0, 0, 2), (0, 0, 4))
    wi, dist, e = lights.point(p, v3(jit, (0, 0, 0)), jit.Array3f(8.0))
    assert np.allclose(np.asarray(dist), [1, 2, 4])
    assert np.allclose(np.asarray(e)[0], [8, 2, 0.5])
    assert np.allclose(np.asarray(wi).T, [[0, 0, -1]] * 3)


def test_lamberts_cosine_law_with_clamping(jit):
    n = v3(jit, (0, 0, 1), (0, 0, 1), (0, 0, 1), (0, 0, 1))
    angles = np.radians([0, 60, 90, 120])
    wi = v3(jit, *[(math.sin(a), 0, math.cos(a)) for a in angles])
    c = np.asarray(lights.lambert_cosine(n, wi))
    assert np.allclose(c, [1, 0.5, 0, 0], atol=1e-7)  # negative cosines clamp to 0


def test_spot_falloff_is_linear_in_angle_between_beam_width_and_cutoff(jit):
    deg = np.array([0, 10, 15, 20, 25, 29.9, 30, 40], dtype=np.float64)
    f = np.asarray(lights.spot_falloff(jit.Float(np.cos(np.radians(deg)).astype(np.float32)),
                                       30, 15))
    expected = np.clip((30 - deg) / (30 - 15), 0, 1)
    expected[deg >= 30] = 0
    assert np.allclose(f, expected, atol=2e-4)


def test_spot_falloff_matches_mitsubas_spot_emitter(jit, mi):
    # Mitsuba's spot light, pointing down -y from (0, 4, 0): compare I falloff / r^2.
    from whitted.reference.renderers.mitsuba.scene import emitter_tree, to_dict
    from whitted.tracer.scene import SpotLight

    spot = SpotLight((0, 4, 0), (0, 0, 0), (5, 5, 5), cutoff_angle=30, beam_width=12)
    emitter = mi.load_dict(to_dict(emitter_tree(spot), mi))
    xs = np.tan(np.radians(np.arange(0, 35, 1.0))) * 4  # points on the floor y = 0
    it = mi.SurfaceInteraction3f()
    it.p = mi.Point3f(mi.Float(xs.astype(np.float32)), 0, 0)
    ds, value = emitter.sample_direction(it, mi.Point2f(0.5))
    theirs = np.asarray(value)[0]
    _, _, ours = lights.spot(v3(jit, *[(x, 0, 0) for x in xs]), v3(jit, spot.position),
                             v3(jit, spot.axis), jit.Array3f(5.0), 30, 12)
    assert np.allclose(np.asarray(ours)[0], theirs, rtol=1e-4, atol=1e-6)


def test_point_light_matches_mitsubas_point_emitter(jit, mi):
    emitter = mi.load_dict({"type": "point", "position": [1, 2, 3],
                            "intensity": {"type": "rgb", "value": [3, 4, 5]}})
    pts = np.array([[0, 0, 0], [4, -1, 2], [1, 2, 10]], dtype=np.float32)
    it = mi.SurfaceInteraction3f()
    it.p = mi.Point3f(*[mi.Float(pts[:, k]) for k in range(3)])
    _, value = emitter.sample_direction(it, mi.Point2f(0.5))
    _, _, ours = lights.point(v3(jit, *pts), v3(jit, (1, 2, 3)), jit.Array3f(3, 4, 5))
    assert np.allclose(np.asarray(ours), np.asarray(value), rtol=1e-6)


def test_directional_light_delivers_its_irradiance_from_the_opposite_direction(jit):
    d = v3(jit, (0, -1, 0))
    wi, dist, e = lights.directional(v3(jit, (1, 2, 3), (4, 5, 6)), d, jit.Array3f(1.5))
    assert np.allclose(np.asarray(wi).T, [[0, 1, 0], [0, 1, 0]])
    assert np.all(np.isinf(np.asarray(dist)))
    assert np.allclose(np.asarray(e), 1.5)
