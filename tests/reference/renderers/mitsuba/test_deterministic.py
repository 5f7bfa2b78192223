"""The deterministic reference: Mitsuba's own lobe weights along the whole ray tree.

Each delta lobe is taken from Mitsuba's plugin through a ``BSDFContext`` that
keeps that lobe alone; these tests check what that returns against the
Fresnel equations from the literature (Hecht, "Optics", 4.6.2, evaluated in
float64 by :func:`reference.teaching.fresnel_curves.exact64`), against the tracer's
weights, and, through whole renders, against closed forms. Area lights are
sampled at the tracer's own points: the sample maps of
:data:`reference.renderers.mitsuba.deterministic.SAMPLE_MAPS` must give the same point and the
same L / pdf on both sides.
"""

import math
import tomllib

import drjit as dr
import numpy as np
import pytest
from conftest import SCENES, jit_kernels

from whitted.reference.renderers.mitsuba.deterministic import SAMPLE_MAPS, render_deterministic
from whitted.reference.teaching.fresnel_curves import exact64, float32_tolerance
from whitted.reference.verdicts.compare import compare_scene
from whitted.tracer import load_scene
from whitted.tracer.integrator import Integrator
from whitted.tracer.scene import Disk, Rectangle, Sphere, Triangle, parse_scene


def _one_lobe(mi, bsdf, cos_i, flag):
    """(weight, pdf, wo) of ``bsdf`` sampled with a context that keeps only ``flag``."""
    n = len(cos_i)
    c = cos_i.astype(np.float32)
    s = np.sqrt(np.maximum(1 - c.astype(np.float64) ** 2, 0)).astype(np.float32)
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.wi = mi.Vector3f(mi.Float(s), mi.Float(np.zeros(n, np.float32)), mi.Float(c))
    si.sh_frame = mi.Frame3f(mi.Vector3f(0, 0, 1))
    ctx = mi.BSDFContext()
    ctx.type_mask = flag
    bs, w = bsdf.sample(ctx, si, 0.5, mi.Point2f(0.5, 0.5))
    return np.asarray(w)[0].astype(np.float64), np.asarray(bs.pdf), np.asarray(bs.wo)


@pytest.mark.parametrize("ior", [1.33, 1.5, 2.42])
@pytest.mark.parametrize("side", [1.0, -1.0], ids=["outside", "inside"])
def test_one_lobe_context_returns_the_lobe_with_its_fresnel_weight(mi, jit, ior, side):
    # Reflection alone: weight R, pdf 1. Transmission alone: weight (1 - R) (n_i / n_t)^2
    # (radiance is compressed into the smaller solid angle of the denser side), 0 under
    # total internal reflection. Mitsuba's plugin, our tracer's formula and the textbook
    # formula in float64 agree within float32 rounding at every angle, both sides.
    from whitted.tracer import fresnel

    bsdf = mi.load_dict({"type": "dielectric", "int_ior": ior, "ext_ior": 1.0})
    theta = np.radians(np.arange(0.0, 89.6, 0.5))
    cos_i = (side * np.cos(theta)).astype(np.float32).astype(np.float64)
    r64 = exact64(cos_i, ior)
    scale = np.where(cos_i >= 0, 1 / ior, ior) ** 2      # (n_i / n_t)^2
    tol = float32_tolerance(cos_i, ior)
    w_r, pdf_r, wo_r = _one_lobe(mi, bsdf, cos_i, mi.BSDFFlags.DeltaReflection)
    w_t, pdf_t, _ = _one_lobe(mi, bsdf, cos_i, mi.BSDFFlags.DeltaTransmission)
    assert np.all(pdf_r == 1) and np.allclose(wo_r[2], cos_i, atol=1e-6)  # mirror direction
    assert np.all(np.abs(w_r - r64) <= tol)
    # 1 - R and its (n_i / n_t)^2 scale add their own roundings: 16 ulp of T on top.
    tol_t = (tol + 16 * 2.0 ** -24 * (1 - r64)) * scale
    assert np.all(np.abs(w_t - (1 - r64) * scale) <= tol_t)
    tir = r64 == 1
    assert (side > 0) == (not tir.any())                     # only from inside
    assert np.all(w_t[tir] == 0)
    ours = np.asarray(fresnel.fresnel_exact(jit.Float(cos_i.astype(np.float32)),
                                            jit.Float(np.float32(ior))), dtype=np.float64)
    assert np.all(np.abs(ours - r64) <= tol)


def test_one_lobe_context_of_a_twosided_mirror_reflects_from_both_sides(mi):
    bsdf = mi.load_dict({"type": "twosided", "material": {
        "type": "conductor", "material": "none", "specular_reflectance": 0.7}})
    cos_i = np.array([0.9, 0.3, -0.3, -0.9])
    w_r, pdf_r, wo = _one_lobe(mi, bsdf, cos_i, mi.BSDFFlags.DeltaReflection)
    assert np.allclose(w_r, 0.7, rtol=1e-6) and np.all(pdf_r == 1)
    assert np.allclose(wo[2], cos_i, atol=1e-6)               # back to the side it came from
    w_t, _, _ = _one_lobe(mi, bsdf, cos_i, mi.BSDFFlags.DeltaTransmission)
    assert np.all(w_t == 0)


SLAB = """
[film]
width = 4
height = 4
spp = 1
max_depth = {depth}

[camera]
type = "orthographic"
origin = [0, 0, 5]
target = [0, 0, 0]
width = 0.5

[materials.glass]
type = "dielectric"
ior = 1.5

[[shapes]]
type = "rectangle"
emitter = {{ radiance = 1 }}
to_world = [ {{ scale = 2 }} ]

[[shapes]]
type = "rectangle"
material = "glass"
to_world = [ {{ scale = 2 }}, {{ translate = [0, 0, 1] }} ]

[[shapes]]
type = "rectangle"
material = "glass"
to_world = [ {{ scale = 2 }}, {{ rotate = {{ axis = [1, 0, 0], angle = 180 }} }},
             {{ translate = [0, 0, 0.5] }} ]
"""


@pytest.mark.parametrize("k", [0, 1, 3])
def test_reference_sums_every_internal_reflection_of_a_glass_slab(k):
    # Normal incidence through a slab before a light of radiance 1: max_depth 3 + 2k
    # follows k round trips, (1 - R)^2 sum_{j <= k} R^(2j), the entering and leaving
    # (n_i / n_t)^2 cancelling; Mitsuba's plugin gives each lobe's weight. No noise.
    r = ((1.5 - 1) / (1.5 + 1)) ** 2
    scene = parse_scene(tomllib.loads(SLAB.format(depth=3 + 2 * k)))
    img = render_deterministic(scene).image
    expected = (1 - r) ** 2 * sum(r ** (2 * j) for j in range(k + 1))
    assert np.allclose(img, expected, rtol=1e-5)


def test_reference_scales_radiance_entering_glass_by_n1_over_n2_squared():
    # Only the front face: the light sits inside the glass, seen through one boundary.
    text = SLAB.format(depth=2)
    text = text[:text.rindex("[[shapes]]")]
    img = render_deterministic(parse_scene(tomllib.loads(text))).image
    assert np.allclose(img, (1 - 0.04) / 1.5 ** 2, rtol=1e-5)


LIGHTS = """
[film]
width = 48
height = 36
spp = 16
max_depth = 2

[camera]
origin = [0, 2.5, 5]
target = [0, 0.4, 0]
fov = 50

[materials.floor]
type = "diffuse"
reflectance = 0.7

[materials.clay]
type = "diffuse"
reflectance = [0.8, 0.5, 0.3]

[[shapes]]
type = "sphere"
center = [0, 0.5, 0]
radius = 0.5
material = "clay"

[[shapes]]
type = "rectangle"
material = "floor"
to_world = [ { scale = 5 }, { rotate = { axis = [1, 0, 0], angle = -90 } } ]
"""

EMITTERS = {
    Rectangle: """
[[shapes]]
type = "rectangle"
emitter = { radiance = [8, 7, 6] }
to_world = [ { scale = [0.6, 0.3, 1] }, { rotate = { axis = [1, 0, 0], angle = 100 } },
             { translate = [-0.8, 2.2, 0.4] } ]
""",
    Disk: """
[[shapes]]
type = "disk"
emitter = { radiance = [6, 7, 9] }
to_world = [ { scale = [0.5, 0.3, 1] }, { rotate = { axis = [0, 0, 1], angle = 30 } },
             { rotate = { axis = [1, 0, 0], angle = 80 } }, { translate = [0.9, 2.0, 0.3] } ]
""",
    Triangle: """
[[shapes]]
type = "triangle"
emitter = { radiance = [9, 8, 5] }
vertices = [[-0.6, 2.1, -0.5], [0.7, 2.3, -0.2], [0.1, 2.0, 0.9]]
""",
    Sphere: """
[[shapes]]
type = "sphere"
center = [1.2, 1.4, 0.6]
radius = 0.2
emitter = { radiance = [9, 9, 12] }
""",
}


def _emitter_scene(kind):
    return parse_scene(tomllib.loads(LIGHTS + EMITTERS[kind]))


def _points(scene, mi, sample_map, n=4096, seed=1):
    """(wi, value) of the tracer's area light and of Mitsuba's emitter for the same samples."""
    from whitted.reference.renderers.mitsuba.scene import load
    from whitted.tracer.backend import jit
    from whitted.tracer.emitters import area

    rng = np.random.default_rng(seed)
    u = rng.random((n, 2)).astype(np.float32)
    # Shading points on the floor and on the ball's upper half.
    p = np.stack([rng.uniform(-1.5, 1.5, n), rng.choice([0.0, 0.9], n),
                  rng.uniform(-1.5, 1.5, n)], axis=1).astype(np.float32)
    shape = next(s for s in scene.shapes if s.emitter is not None)
    ours = area.Emitter(shape)
    pj = jit.Array3f(*p.T)
    wi, _, value = ours.sample(pj, pj, jit.Array2f(*u.T))
    ms = load(scene, mi)
    (emitter,) = ms.emitters()
    it = dr.zeros(mi.Interaction3f, n)
    it.p = mi.Point3f(*p.T)
    ds, weight = emitter.sample_direction(it, sample_map(mi.Point2f(*u.T), mi))
    return (np.asarray(wi), np.asarray(value)), (np.asarray(ds.d), np.asarray(weight))


@pytest.mark.parametrize("kind", list(EMITTERS), ids=[k.__name__ for k in EMITTERS])
def test_shared_light_samples_land_on_the_same_point_with_the_same_weight(mi, kind):
    # The tracer's L cos_l / (r^2 pdf_A) (or L / pdf_omega for the sphere's cone) is
    # Mitsuba's L / pdf_omega: at the same points they agree to float precision.
    (wi, value), (d, weight) = _points(_emitter_scene(kind), mi, SAMPLE_MAPS[kind])
    lit = value[0] > 0
    assert lit.mean() > 0.3
    assert np.allclose(wi[:, lit], d[:, lit], atol=2e-5)
    assert np.allclose(value[:, lit], weight[:, lit], rtol=2e-4)
    assert np.all(weight[:, ~lit] == 0)


@pytest.mark.parametrize("kind", [Triangle, Sphere], ids=["Triangle", "Sphere"])
def test_without_its_sample_map_a_light_lands_elsewhere(mi, kind):
    # Mitsuba warps triangles with sqrt(1 - u.x) and orients its cone's azimuth the other
    # way: handed the tracer's sample as it is, it picks other points.
    (wi, value), (d, _) = _points(_emitter_scene(kind), mi, lambda u, mi: u)
    lit = value[0] > 0
    assert not np.allclose(wi[:, lit], d[:, lit], atol=1e-3)


@pytest.mark.parametrize("kind", [Disk, Triangle], ids=["Disk", "Triangle"])
def test_disk_and_triangle_lights_compare_at_float_precision(kind):
    scene = _emitter_scene(kind)
    result, _, _ = compare_scene(scene, second_opinion=False)
    assert result.reference == "deterministic" and result.test == "exact-strata"
    assert result.passed, result.checks


def test_the_reference_reads_the_tracers_light_samples_of_its_seed():
    scene = load_scene(SCENES / "area_lights.toml").with_overrides(size=(48, 36), spp=16)
    ref0 = render_deterministic(scene, seed=0).image
    ref1 = render_deterministic(scene, seed=1).image
    tr1 = Integrator(scene, seed=1).render().image
    rel = np.abs(tr1 - ref1).sum(-1) / np.maximum(np.abs(ref1).sum(-1), 1e-3 * ref1.mean())
    assert np.median(rel) < 1e-5                       # the same seed: the same samples
    rel0 = np.abs(tr1 - ref0).sum(-1) / np.maximum(np.abs(ref0).sum(-1), 1e-3 * ref0.mean())
    assert np.mean(rel0 > 1e-3) > 0.05                 # another seed: other soft shadows


@pytest.mark.parametrize("name,untraced", [
    # An area light seen through glass: the last segment's rays can meet it on both sides.
    ("emitter_in_glass", 0),
    # Point and directional lights only: a ray of the last segment is never shaded and
    # meets nothing that emits, so neither side traces it.
    ("whitted_mix", 1),
    # The classic model: its glow and backdrop are hit terms, counted only at shaded hits,
    # so DEPTH = max_depth - 1 levels of rays, as minray traces them.
    ("heckbert_minray", 1)])
def test_reference_follows_as_many_rays_per_level_as_the_tracer(name, untraced):
    # Levels: max_depth path segments, less the last where its rays could add nothing.
    scene = load_scene(SCENES / f"{name}.toml").with_overrides(size=(48, 32), spp=4)
    ours = Integrator(scene).render().rays_per_level
    ref = render_deterministic(scene).rays_per_level
    assert len(ours) == len(ref) == scene.film.max_depth - untraced
    # Both sides drop the same zero-weight branches; a grazing ray may fall either way.
    assert all(abs(a - b) <= max(2, 1e-3 * a) for a, b in zip(ours, ref, strict=True))
    assert math.prod(ref) > 0


def test_a_light_without_a_sample_map_is_judged_by_the_one_lobe_reference(monkeypatch):
    # A future emitting shape whose warp the reference cannot match: the comparison
    # falls back to the statistical verdict and says why, rather than failing.
    import whitted.reference.renderers.mitsuba.deterministic as det

    monkeypatch.setattr(det, "SAMPLE_MAPS", {k: v for k, v in SAMPLE_MAPS.items()
                                             if k is not Disk})
    result, _, _ = compare_scene(_emitter_scene(Disk).with_overrides(size=(32, 24)))
    assert result.reference == "onelobe" and result.test == "z-test"
    assert "no shared light samples" in result.reason and result.passed


def test_levels_larger_than_a_chunk_are_split_without_changing_the_image(monkeypatch):
    import whitted.reference.renderers.mitsuba.deterministic as det

    scene = load_scene(SCENES / "whitted_mix.toml").with_overrides(size=(48, 32), spp=4)
    whole = render_deterministic(scene)
    monkeypatch.setattr(det, "CHUNK_SAMPLES", 1000)   # 250 pixels; levels split too
    parts = render_deterministic(scene)
    assert parts.rays_per_level == whole.rays_per_level
    assert np.allclose(parts.image, whole.image, rtol=1e-6, atol=1e-9)


def test_new_rays_start_where_mitsubas_start_them(mi, jit):
    # The two ray trees are the same only if secondary rays leave each surface at the
    # same point: the tracer's offset (spawn_offset, RAY_EPSILON_ULPS) must be Mitsuba's
    # Interaction::offset_p, 1500 float32 ulps of 1 + max |p| along the normal, on the
    # side the new ray goes to. Bit for bit, at every scale of the position.
    from whitted.tracer.geometry import RAY_EPSILON_ULPS, spawn_offset

    assert RAY_EPSILON_ULPS * 2.0 ** -24 == mi.math.RayEpsilon
    rng = np.random.default_rng(7)
    n_pts = 4096
    p = (rng.normal(size=(3, n_pts)) * 10.0 ** rng.uniform(-3, 4, n_pts)).astype(np.float32)
    nrm = rng.normal(size=(3, n_pts))
    nrm = (nrm / np.linalg.norm(nrm, axis=0)).astype(np.float32)
    d = rng.normal(size=(3, n_pts))
    d = (d / np.linalg.norm(d, axis=0)).astype(np.float32)
    si = dr.zeros(mi.SurfaceInteraction3f, n_pts)
    si.p, si.n = mi.Point3f(p), mi.Normal3f(nrm)
    theirs = np.asarray(si.spawn_ray(mi.Vector3f(d)).o)
    P, N, D = (jit.Array3f(a) for a in (p, nrm, d))
    side = dr.select(dr.dot(N, D) >= 0, N, -N)
    ours = np.asarray(dr.fma(side, spawn_offset(P), P))
    assert np.array_equal(ours, theirs)


@pytest.mark.parametrize("ior", [1.33, 1.5, 2.42])
@pytest.mark.parametrize("side", [1.0, -1.0], ids=["outside", "inside"])
def test_schlick_model_gives_schlicks_reflectance_and_snells_direction(mi, jit, ior, side):
    # The harness's own model of a declared Schlick dielectric (whitted_schlick): R from
    # Schlick's formula with the cosine on the less dense side, computed here in float64,
    # and the refracted direction and (n_i / n_t)^2 scale of Mitsuba's own dielectric.
    # The tracer's Schlick (tracer.fresnel) must agree with the same float64 formula.
    from whitted.tracer import fresnel

    schlick = mi.load_dict({"type": "whitted_schlick", "int_ior": ior, "ext_ior": 1.0})
    exact = mi.load_dict({"type": "dielectric", "int_ior": ior, "ext_ior": 1.0})
    theta = np.radians(np.arange(0.0, 89.6, 0.5))
    cos_i = (side * np.cos(theta)).astype(np.float32).astype(np.float64)
    rel = np.where(cos_i > 0, ior, 1 / ior)                      # n_t / n_i
    sin2_t = (1 - cos_i ** 2) / rel ** 2
    tir = sin2_t > 1
    cos_t = np.sqrt(np.maximum(1 - sin2_t, 0))
    r0 = ((ior - 1) / (ior + 1)) ** 2
    r64 = np.where(tir, 1.0, r0 + (1 - r0) * (1 - np.where(rel >= 1, np.abs(cos_i), cos_t)) ** 5)
    w_r, pdf_r, wo_r = _one_lobe(mi, schlick, cos_i, mi.BSDFFlags.DeltaReflection)
    w_t, pdf_t, wo_t = _one_lobe(mi, schlick, cos_i, mi.BSDFFlags.DeltaTransmission)
    _, _, wo_exact = _one_lobe(mi, exact, cos_i, mi.BSDFFlags.DeltaTransmission)
    # Near the critical angle cos_t = sqrt(1 - sin^2) magnifies float32 rounding: the same
    # bound as for the exact equations (reference.teaching.fresnel_curves.float32_tolerance).
    tol = float32_tolerance(cos_i, ior)
    assert np.all(pdf_r == 1) and np.all(np.abs(w_r - r64) <= tol)
    assert np.allclose(wo_r[2], cos_i, atol=1e-6)
    ok = ~tir
    assert np.all(pdf_t[ok] == 1) and np.all(w_t[tir] == 0)
    assert np.all(np.abs(w_t[ok] - (1 - r64[ok]) / rel[ok] ** 2) <= tol[ok] / rel[ok] ** 2 +
                  16 * 2.0 ** -24)
    assert np.allclose(wo_t[:, ok], wo_exact[:, ok], atol=1e-5)
    ours = np.asarray(fresnel.fresnel_schlick(jit.Float(cos_i.astype(np.float32)),
                                              jit.Float(np.float32(ior))), dtype=np.float64)
    assert np.all(np.abs(ours - r64) <= tol)


@pytest.mark.skipif("config.getoption('--backend') == 'cuda'", reason="LLVM kernels")
@pytest.mark.parametrize("name", ["glass_sphere", "area_lights"])
def test_the_reference_traces_every_film_size_with_the_same_ray_tree_kernels(name):
    """At two film sizes, the kernels of the reference's ray trees hold the same
    operations on the same constants: only the camera rays' small kernel (Mitsuba's
    sensor writes the film's size into it) and bookkeeping kernels of a few dozen
    operations are compiled per size. A quick report renders each scene at three sizes
    (the comparison, the formula-bug sweep, LuxCore's vote); before, each compiled the
    whole reference again (issue 33).

    Compared as the multiset of each kernel's lines, registers unnamed, not by hash:
    Dr.Jit orders the outputs of Mitsuba's indirect calls (its BSDFs) by variable
    numbers, which depend on what the process freed before, so the same kernel can come
    with its lines in another order, and another hash, from one render to the next."""
    import re
    from collections import Counter

    from whitted.reference.verdicts.compare import at_strata_centres

    base = at_strata_centres(load_scene(SCENES / f"{name}.toml"))

    def big_kernels(size):
        kernels = [k["ir"].getvalue() for k in jit_kernels(
            lambda: render_deterministic(base.with_overrides(size=size, spp=16)))
            if k["operation_count"] > 200]
        return sorted(sorted(Counter(re.sub(r"%[A-Za-z_]+\d*|@drjit_\w+", "%", line)
                                     for line in ir.splitlines()).items())
                      for ir in kernels)

    small = big_kernels((64, 48))
    assert small and big_kernels((96, 70)) == small
