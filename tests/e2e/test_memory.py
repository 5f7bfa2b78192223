"""Peak memory of a deep render stays bounded by the chunking, not by the image or the depth.

Heckbert's scene at DEPTH 25 splits rays at every glass surface; the depth-first walk
keeps one pending batch a level. With a fixed chunk of 2^21 samples that took 4.1 GB
(1920 x 1080, 4 spp); the chunk is now sized for max_depth (tracer.limits.chunk_samples).
"""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

SCENE = Path(__file__).resolve().parents[2] / "scenes" / "heckbert_minray.toml"

CHILD = textwrap.dedent("""
    import json, resource, sys
    from whitted.tracer import load_scene
    from whitted.tracer.integrator import Integrator
    chunk, options = json.loads(sys.argv[1]), json.loads(sys.argv[3])
    options = {"size": (1920, 1080), **options}
    scene = load_scene(sys.argv[2]).with_overrides(**options)
    Integrator(scene, chunk_samples=chunk).render()
    print(json.dumps(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024))
""")


def peak_bytes(chunk: int | None, scene: Path = SCENE, **options) -> int:
    """Peak resident memory of a process that renders ``scene`` (by default at 1920 x 1080,
    Heckbert's at 4 spp, max_depth 26) with chunks of ``chunk`` samples (None: the rule's)."""
    options = options or {"spp": 4, "max_depth": 26}
    out = subprocess.run([sys.executable, "-c", CHILD, json.dumps(chunk), str(scene),
                          json.dumps(options)], check=True, capture_output=True,
                         text=True).stdout
    return int(out.strip().splitlines()[-1])


@pytest.mark.slow
def test_deep_render_peak_memory_is_bounded():
    """1920 x 1080 at 4 spp (8.3 M samples; DEPTH 25, 2.2e8 rays): with the chunk sized
    for max_depth 26 (2^19 samples) the process peaked at 1.6 GB here, with the fixed
    2^21 of before at 4.1 GB (tests/e2e/test_memory.py's peak_bytes(1 << 21)); 2 GiB lies
    between, with a margin for Dr.Jit's allocator."""
    assert peak_bytes(None) < 2 * 1024 ** 3


@pytest.mark.slow
def test_a_flat_chunk_holds_at_most_its_bytes_a_sample():
    """Where no ray spawns another, a chunk is FLAT_CHUNK_SAMPLES (2^22) samples, and the
    last one up to a quarter more (FLAT_MAX_CHUNK_SAMPLES), on the measure of
    FLAT_BYTES_PER_SAMPLE (128) each. mesh_knot at 1920 x 1120, 16 spp (34.4 M samples:
    eight chunks and a remainder of 0.2 chunk, which joins the last; 4 rays a lane: the
    most a sample held of the scenes measured) with that rule against chunks of 2^21:
    the peaks may differ by at most the 3.1 M samples more in flight times 128 bytes
    (measured between 2^21 and 2^23: 38 bytes a sample)."""
    from whitted.tracer.limits import (
        CHUNK_SAMPLES,
        FLAT_BYTES_PER_SAMPLE,
        FLAT_MAX_CHUNK_SAMPLES,
    )

    knot = SCENE.parent / "mesh_knot.toml"
    small, large = (peak_bytes(c, knot, spp=16, size=(1920, 1120))
                    for c in (CHUNK_SAMPLES, None))
    assert large - small <= (FLAT_MAX_CHUNK_SAMPLES - CHUNK_SAMPLES) * FLAT_BYTES_PER_SAMPLE
