"""The documented maximum max_depth (1000, WHITTED_MAX_DEPTH) renders promptly.

A glass scene at max_depth 1000 traces few rays (a refracted ray leaves the sphere
and ends on the floor; a ray reflected inside it loses all but 4 % of its weight
a bounce and reaches zero weight within about 30): what took minutes was building
the stack schedule's kernel, whose per-level counts were summed by one scatter each,
3,000 of them written out (now a loop beyond tracer.integrator.UNROLLED_LEVELS).
"""

import os
import subprocess
import sys
import time

import pytest

#: Seconds the render may take, start-up and every kernel's build included, on a
#: loaded machine: 1.5 s here, against 38 s before (more than 120 s on a busy machine).
BOUND = 20


def test_glass_at_max_depth_1000_renders_within_a_bound(tmp_path):
    """32 x 24, 1 spp, max_depth 1000, with an empty kernel cache (a HOME of its own), so
    that a kernel built once by an earlier run cannot hide the build's cost."""
    home = tmp_path / "home"
    home.mkdir()
    out = tmp_path / "glass.exr"
    start = time.perf_counter()
    try:
        r = subprocess.run([sys.executable, "-m", "whitted.reference.cli", "render", "glass_sphere",
                            "-o", str(out), "--size", "32x24", "--spp", "1",
                            "--max-depth", "1000"], capture_output=True, text=True,
                           timeout=BOUND, env={**os.environ, "HOME": str(home)})
    except subprocess.TimeoutExpired:
        pytest.fail(f"max_depth 1000 ran past {BOUND} s")
    seconds = time.perf_counter() - start
    assert r.returncode == 0, r.stderr
    assert out.exists()
    assert seconds < BOUND


def test_counts_summed_in_a_loop_equal_the_written_out_sums(monkeypatch):
    """Beyond UNROLLED_LEVELS the per-level counts are summed in a loop: the same counts,
    ray for ray, as the written-out scatters and as the wavefront schedule, and the same
    image to the bit."""
    import numpy as np

    import whitted.tracer.integrator as ti
    from whitted.tracer import load_scene

    scene = load_scene("scenes/tir_prisms.toml").with_overrides(size=(16, 12), spp=4,
                                                                  max_depth=72)

    def counts(r):
        return (r.rays_per_level, r.shadow_rays_per_level, r.significant_rays_per_level)

    looped = ti.Integrator(scene).render()
    monkeypatch.setattr(ti, "UNROLLED_LEVELS", 10 ** 6)
    written = ti.Integrator(scene).render()
    wave = ti.Integrator(scene, schedule="wavefront").render()
    assert counts(looped) == counts(written) == counts(wave)
    assert sum(looped.rays_per_level) > 16 * 12 * 4
    assert np.array_equal(looped.image, written.image)
