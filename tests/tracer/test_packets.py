"""K rays a lane: a packet walks the BVH together and finds what each ray finds alone.

:meth:`tracer.bvh.BVH.closest_hit_group` reads each node and triangle once for
the K rays of a lane; each ray must still get the hit :meth:`BVH.closest_hit`
gives it (the same t; the same triangle unless two meet the ray at the same t),
and :meth:`BVH.occluded_group` the answer of :meth:`BVH.occluded`. The
integrator traces the camera rays of a scene with a mesh K to a lane
(:attr:`Integrator.group`); its images and ray counts must equal those of one
ray a lane: the same operations on the same numbers for every ray, so equal
exactly, not to a tolerance.
"""

from pathlib import Path

import numpy as np
import pytest
from test_bvh import assert_same_hits, knots_and_ball, random_rays, torus, v3

from whitted import tracer  # noqa: F401  (chooses libLLVM before drjit loads)
from whitted.tracer import load_scene
from whitted.tracer.bvh import BVH, INVALID
from whitted.tracer.geometry import Geometry, _InstanceBlock, _InstanceSetBlock
from whitted.tracer.integrator import GROUP_ELSEWHERE, GROUPS, Integrator, default_group


def _rays(rng, n, k, coherent):
    """n lanes of k rays: near copies of one ray (a pixel's samples) or unrelated ones."""
    o, d = random_rays(rng, n * k, [-1.35, -1.35, -0.35], [1.35, 1.35, 0.35])
    if coherent:
        o = np.repeat(o[:n], k, axis=0) + rng.normal(scale=1e-3, size=(n * k, 3))
        d = np.repeat(d[:n], k, axis=0) + rng.normal(scale=1e-2, size=(n * k, 3))
    return o, d


@pytest.mark.parametrize("k", [2, 3, 4])
@pytest.mark.parametrize("coherent", [True, False])
def test_a_packet_finds_each_rays_own_closest_hit(jit, k, coherent):
    p, f = torus(60, 30)
    bvh = BVH(p[f[:, 0]], p[f[:, 1]], p[f[:, 2]])
    rng = np.random.default_rng(k + 10 * coherent)
    n = 3000
    o, d = _rays(rng, n, k, coherent)
    tmax = rng.uniform(0.5, 4.0, n * k).astype(np.float32)
    tmax[rng.random(n * k) < 0.5] = np.inf
    active = rng.random(n * k) < 0.8
    t1, tri1, b1, g1 = (x.numpy() for x in bvh.closest_hit(
        v3(jit, o), v3(jit, d), jit.Float(tmax), jit.Bool(active)))
    # Ray j of lane i is ray i k + j of the flat list.
    found = bvh.closest_hit_group([(v3(jit, o[j::k]), v3(jit, d[j::k]), jit.Float(tmax[j::k]),
                                    jit.Bool(active[j::k])) for j in range(k)])
    hits = 0
    for j, (t, tri, beta, gamma) in enumerate(found):
        t, tri = t.numpy(), tri.numpy()
        assert_same_hits(t, tri, t1[j::k], tri1[j::k])
        # The same t exactly (the same triangle test on the same numbers), tmax on a miss.
        np.testing.assert_array_equal(t, t1[j::k])
        assert (tri[~active[j::k]] == INVALID).all()
        same = tri == tri1[j::k]
        np.testing.assert_array_equal(beta.numpy()[same], b1[j::k][same])
        np.testing.assert_array_equal(gamma.numpy()[same], g1[j::k][same])
        hits += (tri != INVALID).sum()
    assert 0.05 * n * k < hits < 0.95 * n * k   # rays that hit and rays that miss


@pytest.mark.parametrize("k", [2, 4])
@pytest.mark.parametrize("coherent", [True, False])
def test_a_packet_finds_each_rays_own_occlusion(jit, k, coherent):
    p, f = torus(60, 30)
    bvh = BVH(p[f[:, 0]], p[f[:, 1]], p[f[:, 2]])
    rng = np.random.default_rng(100 + k + 10 * coherent)
    n = 3000
    o, d = _rays(rng, n, k, coherent)
    tmax = rng.uniform(0.0, 3.0, n * k).astype(np.float32)
    active = rng.random(n * k) < 0.8
    occ = bvh.occluded(v3(jit, o), v3(jit, d), jit.Float(tmax), jit.Bool(active)).numpy()
    got = bvh.occluded_group([(v3(jit, o[j::k]), v3(jit, d[j::k]), jit.Float(tmax[j::k]),
                               jit.Bool(active[j::k])) for j in range(k)])
    for j, g in enumerate(got):
        np.testing.assert_array_equal(g.numpy(), occ[j::k])
    # Lanes where some rays are blocked and others not: a packet must not stop early.
    blocked = occ.reshape(n, k)
    assert (blocked.any(axis=1) & ~blocked.all(axis=1)).sum() > 0.05 * n


def test_the_geometry_answers_a_group_as_it_answers_each_ray(jit):
    """A mesh with a rectangle beside it: the packet through the BVH, the rectangle ray
    by ray, the nearest of both kept."""
    geo = Geometry(load_scene(KNOT))
    assert geo.has_mesh and len(geo.blocks) > 1
    rng = np.random.default_rng(5)
    n, k = 2000, 4
    o = np.repeat(rng.uniform(-3, 3, (n, 3)) + [0, 2.5, 6], k, axis=0)
    target = rng.uniform(-1.2, 1.2, (n * k, 3)) + [0, 0.8, 0]
    d = target - o
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    tmax = rng.uniform(2, 12, n * k).astype(np.float32)
    group = [(v3(jit, o[j::k]), v3(jit, d[j::k]), jit.Float(tmax[j::k]), True)
             for j in range(k)]
    hits = geo.closest_hit_group(group)
    occ = geo.occluded_group(group)
    for j, (oj, dj, tj, _) in enumerate(group):
        one = geo.closest_hit(oj, dj, tj)
        np.testing.assert_array_equal(hits[j].t.numpy(), one.t.numpy())
        np.testing.assert_array_equal(hits[j].prim.numpy(), one.prim.numpy())
        np.testing.assert_array_equal(occ[j].numpy(), geo.occluded(oj, dj, tj).numpy())
    prims = np.concatenate([h.prim.numpy() for h in hits])
    mesh = next(b for b in geo.blocks if hasattr(b, "bvh"))
    assert (prims >= mesh.base).any() and (prims < mesh.base).any()



def _instanced_knots(tmp_path):
    """conftest.MINIMAL's sphere, the knot instanced three times (a hierarchy of
    instances) and once more as a group of its own (one instance), and a ball instanced
    once: every kind of instance block, with a mesh in its group or not."""
    knot = KNOT.parent / "meshes" / "knot.ply"
    path = tmp_path / "knots.toml"
    path.write_text(knots_and_ball(knot, "other") + '\n[groups.other]\n'
                    f'[[groups.other.shapes]]\ntype = "mesh"\nfile = "{knot}"\n'
                    'material = "white"\n')
    return load_scene(path)


@pytest.mark.parametrize("coherent", [True, False])
def test_instances_answer_a_group_as_they_answer_each_ray(jit, tmp_path, coherent):
    """Instanced meshes walk K rays a lane together: the hierarchy of instances once for
    the K rays, each instance asking its group (a mesh's tree) with all of them. Each
    ray gets the hit and the occlusion it gets alone: the same t and primitive (the
    same operations on the same numbers), with some rays of a lane inactive."""
    geo = Geometry(_instanced_knots(tmp_path))
    kinds = [type(b) for b in geo.blocks]
    assert geo.has_mesh and _InstanceSetBlock in kinds and kinds.count(_InstanceBlock) == 2
    rng = np.random.default_rng(7 + coherent)
    n, k = 3000, 4
    o, d = _rays(rng, n, k, coherent)
    o = o * 1.5 + [0, 0.5, 0]
    d /= np.linalg.norm(d, axis=1, keepdims=True)  # the geometry's rays are unit vectors
    tmax = rng.uniform(0.5, 5.0, n * k).astype(np.float32)
    active = rng.random(n * k) < 0.8
    group = [(v3(jit, o[j::k]), v3(jit, d[j::k]), jit.Float(tmax[j::k]),
              jit.Bool(active[j::k])) for j in range(k)]
    hits = geo.closest_hit_group(group)
    occ = geo.occluded_group(group)
    prims = []
    for j, (oj, dj, tj, aj) in enumerate(group):
        one = geo.closest_hit(oj, dj, tj, aj)
        np.testing.assert_array_equal(hits[j].t.numpy(), one.t.numpy())
        np.testing.assert_array_equal(hits[j].prim.numpy(), one.prim.numpy())
        np.testing.assert_array_equal(occ[j].numpy(), geo.occluded(oj, dj, tj, aj).numpy())
        prims.append(one.prim.numpy())
    # Rays that hit each kind of block, and rays that miss.
    prims = np.concatenate(prims)
    for b in geo.blocks:
        assert ((prims >= b.base) & (prims < b.base + b.count)).sum() > 20, type(b).__name__
    assert (prims == INVALID).sum() > 0.05 * n * k
    # Lanes where some rays are blocked and others not.
    blocked = np.stack([x.numpy() for x in occ], axis=1)
    assert (blocked.any(axis=1) & ~blocked.all(axis=1)).sum() > 0.02 * n


def test_a_render_of_instanced_meshes_with_k_rays_a_lane_equals_one_ray_a_lane(tmp_path):
    scene = _instanced_knots(tmp_path).with_overrides(size=(48, 36), spp=8)
    one = Integrator(scene, group=1, schedule="wavefront").render(moments=True)
    packed = Integrator(scene, group=default_group(), schedule="wavefront").render(moments=True)
    assert Integrator(scene).group == default_group()
    assert one.image.any()
    np.testing.assert_array_equal(packed.image, one.image)
    np.testing.assert_array_equal(packed.variance, one.variance)
    assert packed.rays_per_level == one.rays_per_level
    assert packed.shadow_rays_per_level == one.shadow_rays_per_level

KNOT = Path(__file__).resolve().parents[2] / "scenes" / "mesh_knot.toml"

#: Variants of the mesh scene (two meshes, a rectangle, two lights): (name, a change of
#: its text, Integrator options): as it is; a glass floor (two more levels, one ray a
#: lane); a light-path expression; the gaussian filter's splat; jittered samples.
CASES = [
    ("plain", None, {}),
    ("glass floor", ('[materials.floor]\ntype = "diffuse"\nreflectance = [0.45, 0.5, 0.55]',
                     '[materials.floor]\ntype = "dielectric"\nior = 1.5'), {}),
    ("lpe", None, {"lpe": "LDE"}),
    ("gaussian", ("spp = 16", 'spp = 16\nfilter = "gaussian"'), {}),
    ("jitter", ("spp = 16", "spp = 16\njitter = true"), {}),
]


def _scene(tmp_path, change, max_depth=None):
    text = KNOT.read_text()
    if change is not None:
        assert change[0] in text
        text = text.replace(change[0], change[1])
    path = tmp_path / "scene.toml"
    path.write_text(text.replace('file = "meshes/', f'file = "{KNOT.parent}/meshes/'))
    return load_scene(path).with_overrides(size=(48, 36), max_depth=max_depth)


def _render(scene, options, group, seeds=None):
    integ = Integrator(scene, group=group, schedule="wavefront", **options)
    return integ.render_seeds(seeds) if seeds else [integ.render(moments=True)]


@pytest.mark.parametrize("name, change, options", CASES)
def test_the_renders_of_k_rays_a_lane_equal_one_ray_a_lane(tmp_path, name, change, options):
    scene = _scene(tmp_path, change, max_depth=4 if name == "glass floor" else None)
    one = _render(scene, options, 1)
    packed = _render(scene, options, default_group())
    for a, b in zip(one, packed, strict=True):
        assert a.image.any()
        np.testing.assert_array_equal(b.image, a.image)
        if a.variance is not None:
            np.testing.assert_array_equal(b.variance, a.variance)
        assert b.rays_per_level == a.rays_per_level
        assert b.shadow_rays_per_level == a.shadow_rays_per_level
        assert b.significant_rays_per_level == a.significant_rays_per_level
    assert (len(one[0].rays_per_level) > 1) == (name == "glass floor")


@pytest.mark.parametrize("k", sorted({*GROUPS.values(), GROUP_ELSEWHERE} - {1}))
def test_every_k_the_tracer_may_choose_renders_as_one_ray_a_lane(tmp_path, k):
    """The K of every CPU width (not only this machine's) gives the image of K = 1."""
    scene = _scene(tmp_path, None)
    one, packed = _render(scene, {}, 1)[0], _render(scene, {}, k)[0]
    assert one.image.any()
    np.testing.assert_array_equal(packed.image, one.image)
    assert packed.shadow_rays_per_level == one.shadow_rays_per_level


def test_k_follows_the_width_of_dr_jits_packets(monkeypatch):
    """AVX-512's 16 lanes: K = 4; AVX2's 8: K = 2; another or an unknown width: the
    smaller kernel (tracer/integrator.py's GROUPS, measured by benchmarks/bench_group.py)."""
    from whitted.tracer import backend

    for width, k in ((16, 4), (8, 2), (4, GROUP_ELSEWHERE), (None, GROUP_ELSEWHERE)):
        monkeypatch.setattr(backend, "llvm_vector_width", lambda width=width: width)
        assert default_group() == k
        assert Integrator(load_scene(KNOT)).group == k


def test_dr_jit_reports_its_packet_width():
    """The width is read from libdrjit-core (not a public Python API): a drjit upgrade
    that renames the function must fail here rather than silently fall back."""
    from whitted.tracer import backend

    if backend.name() != "llvm":
        pytest.skip("the LLVM backend's width")
    assert backend.llvm_vector_width() in (4, 8, 16)


def test_several_seeds_a_render_with_k_rays_a_lane(tmp_path):
    scene = _scene(tmp_path, None)
    one = _render(scene, {}, 1, seeds=(3, 4))
    packed = _render(scene, {}, default_group(), seeds=(3, 4))
    for a, b in zip(one, packed, strict=True):
        np.testing.assert_array_equal(b.image, a.image)
        assert b.shadow_rays_per_level == a.shadow_rays_per_level


def test_a_scene_with_a_mesh_groups_its_camera_rays_and_others_do_not():
    assert Integrator(load_scene(KNOT)).group == default_group() > 1
    assert Integrator(load_scene(KNOT.parent / "three_lights.toml")).group == 1
    with pytest.raises(ValueError, match="group"):
        Integrator(load_scene(KNOT), group=0)


def test_a_chunk_whose_samples_do_not_divide_into_groups_is_traced_one_ray_a_lane():
    """5 x 3 pixels at 1 spp: 15 camera rays, not a multiple of K; the render still
    equals the one of one ray a lane."""
    scene = load_scene(KNOT).with_overrides(size=(5, 3), spp=1)
    a = Integrator(scene, group=1).render()
    b = Integrator(scene, group=default_group()).render()
    np.testing.assert_array_equal(b.image, a.image)
    assert b.rays_per_level == a.rays_per_level == [15]
