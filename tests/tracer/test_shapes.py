"""The second lecture's shapes: polygons, disks, cylinders, the paraboloid, instancing, textures."""

import math
import tomllib

import numpy as np
import pytest

from whitted.tracer.geometry import INVALID, Geometry
from whitted.tracer.scene import parse_scene
from whitted.tracer.shapes import paraboloid, polygon
from whitted.tracer.texture import checkerboard

STAR = [(math.cos(math.radians(90 + 36 * k)) * (1.0 if k % 2 == 0 else 0.4),
         math.sin(math.radians(90 + 36 * k)) * (1.0 if k % 2 == 0 else 0.4)) for k in range(10)]


def _scene(shapes: str, extra: str = ""):
    text = ("[camera]\norigin = [0, 0, 5]\ntarget = [0, 0, 0]\n[materials.m]\ntype = 'diffuse'\n"
            + extra + shapes)
    return parse_scene(tomllib.loads(text))


def _cast(jit, scene, o, d):
    geo = Geometry(scene)
    o = jit.Array3f(*np.asarray(o, dtype=np.float32).T)
    d = np.asarray(d, dtype=np.float64)
    d = d / np.linalg.norm(d, axis=-1, keepdims=True)
    dd = jit.Array3f(*d.astype(np.float32).T)
    hit = geo.closest_hit(o, dd, jit.Float(math.inf))
    s = geo.surface(hit, o, dd)
    return (np.asarray(hit.t), np.asarray(hit.prim), np.asarray(s.p).T, np.asarray(s.n).T,
            np.asarray(s.uv).T)


def _inside_reference(x, y, poly):
    """Winding number (a different rule from the tracer's crossing count)."""
    wn = 0
    n = len(poly)
    for i in range(n):
        (x0, y0), (x1, y1) = poly[i], poly[(i + 1) % n]
        cross = (x1 - x0) * (y - y0) - (x - x0) * (y1 - y0)
        if y0 <= y < y1 and cross > 0:
            wn += 1
        elif y1 <= y < y0 and cross < 0:
            wn -= 1
    return wn != 0


def test_point_in_polygon_for_a_non_convex_star(jit):
    rng = np.random.default_rng(4)
    pts = rng.uniform(-1.1, 1.1, size=(4000, 2))
    xs, ys = [p[0] for p in STAR], [p[1] for p in STAR]
    inside = np.asarray(polygon.inside(jit.Float(pts[:, 0].astype(np.float32)),
                                       jit.Float(pts[:, 1].astype(np.float32)), xs, ys))
    expected = np.array([_inside_reference(x, y, STAR) for x, y in pts])
    assert np.array_equal(inside, expected)
    assert 0.2 < inside.mean() < 0.5  # the star's tips and notches are both sampled


def test_ray_polygon_hits_inside_the_notches_only(jit):
    verts = ", ".join(f"[{x:.6f}, {y:.6f}, 0]" for x, y in STAR)
    s = _scene(f"[[shapes]]\ntype = 'polygon'\nmaterial = 'm'\nvertices = [{verts}]\n")
    # Straight down onto the star's centre, into a notch between two tips, onto a tip.
    tip = STAR[0]
    notch = (0.75 * math.cos(math.radians(108)), 0.75 * math.sin(math.radians(108)))
    o = [(0, 0, 3), (notch[0], notch[1], 3), (tip[0] * 0.95, tip[1] * 0.95, 3)]
    t, prim, p, n, _ = _cast(jit, s, o, [(0, 0, -1)] * 3)
    assert prim[0] != INVALID and prim[1] == INVALID and prim[2] != INVALID
    assert t[0] == pytest.approx(3) and np.allclose(np.abs(n[0]), [0, 0, 1])


def test_paraboloid_normal_is_its_normalised_gradient(jit):
    a, b = 0.7, 0.5
    p = np.array([0.3, -0.2, (0.3 / a) ** 2 + (0.2 / b) ** 2])
    g = np.asarray(paraboloid.gradient(jit.Array3f(*(float(x) for x in p)), 1 / a ** 2,
                                       1 / b ** 2)).ravel()
    # Central differences of F = x^2/a^2 + y^2/b^2 - z.
    def F(q):
        return q[0] ** 2 / a ** 2 + q[1] ** 2 / b ** 2 - q[2]
    h = 1e-6
    num = np.array([(F(p + h * e) - F(p - h * e)) / (2 * h) for e in np.eye(3)])
    assert np.allclose(g, num, atol=1e-5)


def test_ray_paraboloid_roots_lie_on_the_surface(jit):
    s = _scene("[[shapes]]\ntype = 'paraboloid'\na = 0.7\nb = 0.5\nheight = 1.2\n"
               "material = 'm'\n")
    rng = np.random.default_rng(5)
    o = np.column_stack([rng.uniform(-0.5, 0.5, 200), rng.uniform(-0.5, 0.5, 200),
                         np.full(200, 3.0)])
    d = np.column_stack([rng.normal(0, 0.1, 200), rng.normal(0, 0.1, 200), -np.ones(200)])
    t, prim, p, n, _ = _cast(jit, s, o, d)
    hit = prim != INVALID
    assert hit.sum() > 100
    q = p[hit]
    assert np.allclose(q[:, 0] ** 2 / 0.49 + q[:, 1] ** 2 / 0.25, q[:, 2], atol=2e-5)
    assert np.all((q[:, 2] >= -1e-6) & (q[:, 2] <= 1.2 + 1e-6))
    # A vertical ray through the axis meets the bowl's bottom at its apex.
    t, prim, p, n, _ = _cast(jit, s, [(0, 0, 3)], [(0, 0, -1)])
    assert t[0] == pytest.approx(3, abs=1e-5) and np.allclose(n[0], [0, 0, -1], atol=1e-6)


def test_disk_under_non_uniform_scale_is_an_ellipse(jit):
    s = _scene("[[shapes]]\ntype = 'disk'\nmaterial = 'm'\nto_world = [ { scale = [2, 1, 1] } ]\n")
    o = [(1.9, 0, 1), (0, 0.9, 1), (1.5, 0.8, 1), (0, 1.1, 1)]
    _, prim, _, n, uv = _cast(jit, s, o, [(0, 0, -1)] * 4)
    assert list(prim != INVALID) == [True, True, False, False]
    # Mitsuba's disk uv: (r, phi / 2 pi) in the disk's own coordinates.
    assert uv[0][0] == pytest.approx(0.95, abs=1e-5) and uv[1][1] == pytest.approx(0.25, abs=1e-5)


def test_cylinder_is_open_and_seen_from_inside(jit):
    s = _scene("[[shapes]]\ntype = 'cylinder'\np0 = [0, 0, -1]\np1 = [0, 0, 1]\nradius = 0.5\n"
               "material = 'm'\n")
    # Along the axis: no cap to hit. From inside, sideways: the wall at the radius.
    t, prim, p, n, _ = _cast(jit, s, [(0, 0, 3), (0, 0, 0), (3, 0, 0)],
                             [(0, 0, -1), (1, 0, 0), (-1, 0, 0)])
    assert prim[0] == INVALID
    assert t[1] == pytest.approx(0.5, abs=1e-6) and np.allclose(n[1], [1, 0, 0], atol=1e-6)
    assert t[2] == pytest.approx(2.5, abs=1e-6) and np.allclose(n[2], [1, 0, 0], atol=1e-6)


GROUP = ("[groups.g]\n[[groups.g.shapes]]\ntype = 'sphere'\ncenter = [0, 0, 0]\nradius = 1\n"
         "material = 'm'\n")


def test_instanced_sphere_under_non_uniform_scale_is_an_ellipsoid(jit):
    # x^2/4 + y^2 + z^2/0.25 = 1: hits, and normals by the inverse transpose M^-T n.
    s = _scene("[[shapes]]\ntype = 'instance'\ngroup = 'g'\n"
               "to_world = [ { scale = [2, 1, 0.5] }, { translate = [0, 0, -1] } ]\n", GROUP)
    rng = np.random.default_rng(6)
    o = np.column_stack([rng.uniform(-1.5, 1.5, 300), rng.uniform(-0.8, 0.8, 300),
                         np.full(300, 3.0)])
    t, prim, p, n, _ = _cast(jit, s, o, [(0, 0.05, -1)] * 300)
    hit = prim != INVALID
    q = p[hit] - np.array([0, 0, -1])
    assert hit.sum() > 150
    assert np.allclose(q[:, 0] ** 2 / 4 + q[:, 1] ** 2 + q[:, 2] ** 2 / 0.25, 1, atol=1e-4)
    grad = np.column_stack([q[:, 0] / 4, q[:, 1], q[:, 2] / 0.25])  # the ellipsoid's gradient
    grad /= np.linalg.norm(grad, axis=1, keepdims=True)
    assert np.allclose(n[hit], grad, atol=1e-4)


def test_instancing_round_trip_keeps_the_ray_parameter(jit):
    # The same sphere placed directly and through an instance gives the same hits.
    direct = _scene("[[shapes]]\ntype = 'sphere'\ncenter = [0.3, -0.2, -1]\nradius = 1.5\n"
                    "material = 'm'\n")
    inst = _scene("[[shapes]]\ntype = 'instance'\ngroup = 'g'\nto_world = [ { scale = 1.5 }, "
                  "{ rotate = { axis = [1, 1, 0], angle = 40 } }, "
                  "{ translate = [0.3, -0.2, -1] } ]\n", GROUP)
    rng = np.random.default_rng(7)
    o = np.column_stack([rng.uniform(-1, 1, 100), rng.uniform(-1, 1, 100), np.full(100, 4.0)])
    d = np.column_stack([rng.normal(0, 0.05, 100), rng.normal(0, 0.05, 100), -np.ones(100)])
    a, b = _cast(jit, direct, o, d), _cast(jit, inst, o, d)
    assert np.array_equal(a[1] != INVALID, b[1] != INVALID)
    hit = a[1] != INVALID
    assert np.allclose(a[0][hit], b[0][hit], rtol=1e-5)
    assert np.allclose(a[2][hit], b[2][hit], atol=1e-5)
    assert np.allclose(a[3][hit], b[3][hit], atol=1e-5)


def test_checkerboard_lookup_follows_mitsubas_rule(jit, mi):
    uv = np.array([[0.25, 0.25], [0.75, 0.75], [0.25, 0.75], [0.75, 0.25], [0.05, 0.55]])
    scale = (3.0, 2.0)
    ours = np.asarray(checkerboard(jit.Array2f(*uv.T.astype(np.float32)),
                                   jit.Array2f(*scale), jit.Array3f(1, 0, 0),
                                   jit.Array3f(0, 0, 1))).T
    tex = mi.load_dict({"type": "checkerboard", "color0": {"type": "rgb", "value": [1, 0, 0]},
                        "color1": {"type": "rgb", "value": [0, 0, 1]},
                        "to_uv": mi.ScalarTransform3f().scale(mi.ScalarPoint2f(*scale))})
    si = mi.SurfaceInteraction3f()
    si.uv = mi.Point2f(*uv.T.astype(np.float32))
    theirs = np.asarray(tex.eval(si)).T
    assert np.array_equal(ours, theirs)
    unit = np.asarray(checkerboard(jit.Array2f(*uv[:4].T.astype(np.float32)),
                                   jit.Array2f(1, 1), jit.Array3f(1, 0, 0),
                                   jit.Array3f(0, 0, 1))).T
    assert unit[:, 0].tolist() == [1, 1, 0, 0]  # color0 on the diagonal squares


def test_a_mesh_of_over_100000_triangles_renders_and_agrees_with_mitsuba(tmp_path):
    # Generated here (the built-in scenes keep small files): a torus knot of
    # 2 x 1000 x 52 = 104,000 triangles, smooth, through the BVH on our side and
    # Embree on Mitsuba's; compared by the exact-strata rule at a small size.
    import sys

    from conftest import SCENES

    from whitted.reference.verdicts.compare import compare_scene
    from whitted.tracer import load_scene

    sys.path.insert(0, str(SCENES / "meshes"))
    from generate import torus_knot, write_ply

    v, f = torus_knot(1000, 52)
    assert len(f) >= 100_000
    write_ply(tmp_path / "big.ply", v, f)
    text = (SCENES / "mesh_knot.toml").read_text().replace(
        'file = "meshes/knot.ply"', f'file = "{tmp_path / "big.ply"}"').replace(
        'file = "meshes/', f'file = "{SCENES / "meshes"}/')
    (tmp_path / "big.toml").write_text(text)
    scene = load_scene(tmp_path / "big.toml").with_overrides(size=(96, 64), spp=4)
    result, img, _ = compare_scene(scene)
    assert img.max() > 0
    assert result.test == "exact-strata" and result.passed, result.checks
