"""The two schedules of the recursion trace the same rays and find the same light.

The wavefront (a kernel a level, rays compacted between levels) and the stack
(one kernel a chunk, each lane walking its sample's ray tree depth first with
a stack in local memory) must trace ray for ray the same trees: the counts per
level are equal exactly. Only the order in which a sample's terms are summed
differs, so the images may differ by float32 rounding alone.
"""

import numpy as np
import pytest

from whitted import tracer  # noqa: F401  (chooses libLLVM before drjit loads)
from whitted.reference.cli import resolve_scene
from whitted.tracer import load_scene
from whitted.tracer.integrator import SCHEDULES, Integrator

#: (scene, max_depth or None for the scene's own, Integrator options): glass (two
#: slots), masks (a third slot straight through), thin glass, the classic model,
#: Schlick's Fresnel, area lights inside glass with a light-path expression (DFA
#: states carried on the stack), a biased min_weight, a background hit term.
CASES = [
    ("glass_sphere", None, {}),
    ("glass_sphere", None, {"lpe": "L.*E"}),
    # a path of exactly two specular vertices: a ray popped from the stack must go on
    # with its own DFA state, not with the state of the ray traced before it
    ("whitted_1980", None, {"lpe": "LDSSE"}),
    ("masked", 6, {}),
    ("thin_glass", None, {}),
    ("whitted_mix", None, {}),
    ("schlick_diamond", None, {}),
    ("emitter_in_glass", None, {"lpe": "LS*E"}),
    ("whitted_1980", None, {"min_weight": 0.05}),
    ("heckbert_minray", 8, {}),
    ("sky", None, {}),
    ("three_lights", None, {}),  # no recursion: the stack's loop runs once a lane
]


def _both(name, max_depth, options, moments=False):
    scene = load_scene(resolve_scene(name)).with_overrides(size=(40, 30), spp=4,
                                                          max_depth=max_depth)
    out = {}
    for schedule in ("wavefront", "stack"):
        integ = Integrator(scene, schedule=schedule, **options)
        assert integ.schedule == schedule
        out[schedule] = integ.render(moments=moments)
    return scene, integ, out["wavefront"], out["stack"]


@pytest.mark.parametrize(("name", "max_depth", "options"), CASES,
                         ids=[f"{c[0]}{'-' + '-'.join(c[2]) if c[2] else ''}" for c in CASES])
def test_stack_traces_the_wavefront_rays_and_light(name, max_depth, options):
    scene, integ, a, b = _both(name, max_depth, options, moments=True)
    if integ.materials.has_delta:  # rays below the camera level were traced
        assert sum(b.rays_per_level) > b.rays_per_level[0]
    assert b.rays_per_level == a.rays_per_level
    assert b.shadow_rays_per_level == a.shadow_rays_per_level
    assert b.significant_rays_per_level == a.significant_rays_per_level
    # A sample's radiance is a sum of non-negative terms, at most one per ray of its tree
    # and per shadow ray. Summed in another order, a sum of m terms moves by at most
    # (m - 1) u times itself, u = 2^-24 (Higham, "Accuracy and Stability of Numerical
    # Algorithms", 2nd ed., eq. 4.4); a pixel's mean of such samples inherits the bound.
    # m: the largest tree the scene allows, every slot kept at every level, each ray
    # with one shadow ray per light.
    slots = integ.materials.delta_slots
    depth = scene.film.max_depth
    m = sum(slots ** k for k in range(depth)) * (1 + len(integ.illuminating))
    bound = (m - 1) * 2.0 ** -24 * np.abs(a.image) + 1e-30
    assert np.all(np.abs(b.image - a.image) <= bound)
    # E[x^2] - E[x]^2 is not a sum of non-negative terms: compare it with its own scale.
    np.testing.assert_allclose(b.variance, a.variance, rtol=0,
                               atol=4 * (m - 1) * 2.0 ** -24 * float(np.max(a.image)) ** 2)


def test_shared_trees_in_many_chunks_are_the_renders_of_each_seed():
    """Shared ray trees split into chunks (a lane counts as ceil(S / SEEDS_PER_LANE_SAMPLE)
    samples of one): each seed's image and variance are still, bit for bit, that seed's
    own render, whatever the chunk (the last one partial here). Rows of a chunk written
    at another chunk's place, or a chunk's seeds in the wrong order, break the equality."""
    from whitted.tracer.integrator import SEEDS_PER_LANE_SAMPLE

    scene = load_scene(resolve_scene("emitter_in_glass")).with_overrides(size=(24, 18), spp=16)
    seeds = [3, 4, 5, 6, 7, 8]
    lane_samples = -(-len(seeds) // SEEDS_PER_LANE_SAMPLE)
    chunked = Integrator(scene, chunk_samples=16 * lane_samples * 29)   # 29 pixels a chunk
    assert chunked._shares_trees(tuple(seeds))
    together = chunked.render_seeds(seeds, moments=True)
    whole = Integrator(scene)
    for seed, r in zip(seeds, together, strict=True):
        alone = whole.render(moments=True, seed=seed)
        assert np.array_equal(r.image, alone.image)
        assert np.array_equal(r.variance, alone.variance)


def test_auto_takes_the_stack_where_rays_recurse():
    """Recursion (delta materials, max_depth > 2): the stack; direct light only: the
    wavefront's one level, whose camera kernel skips packets of missed rays."""
    glass = load_scene(resolve_scene("glass_sphere"))
    assert Integrator(glass).schedule == "stack"
    assert Integrator(glass.with_overrides(max_depth=2)).schedule == "wavefront"
    assert Integrator(load_scene(resolve_scene("three_lights"))).schedule == "wavefront"
    assert SCHEDULES == ("auto", "wavefront", "stack")
    with pytest.raises(ValueError, match="schedule must be one of"):
        Integrator(glass, schedule="megakernel")


def test_a_chunk_is_larger_where_no_ray_spawns_another(monkeypatch):
    """Without mirrors, glass or masks a camera ray ends where it is shaded, and the CPU
    chunk is FLAT_CHUNK_SAMPLES (tracer.limits, where its memory is measured); where rays
    spawn children it stays sized for max_depth. Both chunkings give the same image."""
    from whitted.tracer import backend, limits

    monkeypatch.setattr(backend, "name", lambda: "llvm")   # the CPU's rule, on any backend
    flat = load_scene(resolve_scene("three_lights"))
    assert Integrator(flat).chunk_samples == limits.FLAT_CHUNK_SAMPLES > limits.CHUNK_SAMPLES
    glass = load_scene(resolve_scene("glass_sphere"))
    for depth in (2, 26):
        assert Integrator(glass.with_overrides(max_depth=depth)).chunk_samples \
            == limits.chunk_samples(depth) <= limits.CHUNK_SAMPLES
    small = flat.with_overrides(size=(40, 30), spp=4)
    whole = Integrator(small).render().image
    assert np.array_equal(Integrator(small, chunk_samples=4 * 7).render().image, whole)


@pytest.mark.parametrize("schedule", ["stack", "wavefront"])
@pytest.mark.parametrize("name,jitter", [("area_lights", False), ("emitter_in_glass", True),
                                         ("emitter_in_glass", False),
                                         ("disk_triangle_lights", True), ("sky", False)])
def test_seeds_rendered_together_are_the_renders_of_each_seed(name, jitter, schedule):
    """Integrator.render_seeds: every pixel holds the samples of each seed in turn, and
    each sample reads its own seed's light samples (and jitter), or, on the stack
    without jitter, each lane carries every seed through its one ray tree with a sum
    of light per seed; either way each image and variance is, bit for bit, the one a
    render with that seed alone gives: each seed's terms are summed in the same order
    (one chunk here; the wavefront's splits of a level can reorder a sample's adds, to
    float32 rounding). A sample reading the first seed's keys, a seed's light added to
    another's sum, or seeds in the wrong rows, makes images differ by whole light
    samples. Shared trees trace the rays of one render (emitter_in_glass: its point
    light's shadow rays once, its sphere light's once per seed)."""
    import dataclasses

    scene = load_scene(resolve_scene(name)).with_overrides(size=(24, 18), spp=16)
    scene = dataclasses.replace(scene, film=dataclasses.replace(scene.film, jitter=jitter))
    integ = Integrator(scene, schedule=schedule)
    seeds = [7, 8, 9]
    together = integ.render_seeds(seeds, moments=True)
    for seed, r in zip(seeds, together, strict=True):
        alone = integ.render(moments=True, seed=seed)
        assert np.array_equal(r.image, alone.image)
        assert np.array_equal(r.variance, alone.variance)
    assert not np.array_equal(together[0].image, together[1].image)
    shared = schedule == "stack" and not jitter
    assert integ._shares_trees(tuple(seeds)) == shared
    if shared:
        assert together[0].rays_per_level == alone.rays_per_level
        if name == "emitter_in_glass":   # the point light's shadow rays: once, not 3 times
            assert sum(together[0].shadow_rays_per_level) < len(seeds) * sum(
                alone.shadow_rays_per_level)


def test_a_small_remainder_joins_the_last_chunk_where_no_ray_spawns_another():
    """Where no ray spawns another, a remainder of at most a quarter chunk
    (tracer.limits.FLAT_TAIL_PART) joins the chunk before it instead of being traced as
    a chunk of its own; a larger one, or any where rays spawn others, stays apart. The
    image is the same bit for bit however the pixels are chunked."""
    from whitted.tracer import limits
    from whitted.tracer.integrator import _chunk_spans

    assert _chunk_spans(10, 4, 2) == [(0, 4), (4, 6)]        # a remainder of 2 joins
    assert _chunk_spans(11, 4, 2) == [(0, 4), (4, 4), (8, 3)]
    assert _chunk_spans(3, 4, 2) == [(0, 3)]
    assert _chunk_spans(8, 4, 2) == [(0, 4), (4, 4)]
    assert _chunk_spans(9, 4, 0) == [(0, 4), (4, 4), (8, 1)]
    flat = load_scene(resolve_scene("three_lights")).with_overrides(size=(40, 30), spp=4)
    per_chunk = 4 * 290   # 290 pixels: four chunks and a remainder of 40, which joins
    joined = Integrator(flat, chunk_samples=per_chunk)
    assert joined.tail_samples == limits.flat_tail(per_chunk) == per_chunk // 4
    done = []
    image = joined.render(progress=lambda n, total: done.append(n)).image
    assert done == [290, 580, 870, 1200]
    apart = Integrator(flat, chunk_samples=per_chunk)
    apart.tail_samples = 0
    done.clear()
    assert np.array_equal(apart.render(progress=lambda n, total: done.append(n)).image, image)
    assert done == [290, 580, 870, 1160, 1200]
    glass = load_scene(resolve_scene("glass_sphere")).with_overrides(size=(40, 30), spp=4)
    assert Integrator(glass, chunk_samples=per_chunk).tail_samples == 0
