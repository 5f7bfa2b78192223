"""The wavefront's compaction: the next level is every child's kept rays, in order."""

import drjit as dr
import numpy as np
import pytest

from whitted import tracer  # noqa: F401  (chooses libLLVM before drjit loads)
from whitted.tracer import backend
from whitted.tracer.backend import jit


@pytest.mark.parametrize("k", [1, 2, 3])
def test_compact_keeps_each_child_in_order(k):
    """_compact against numpy: child 0's kept rays, then child 1's, ...; every field."""
    backend.use()
    from whitted.tracer.integrator import _Batch, _compact

    rng = np.random.default_rng(k)
    n = 37
    children, want = [], {f: [] for f in ("o", "d", "weight", "slot")}
    for _ in range(k):
        o, d, w = (rng.normal(size=(3, n)).astype(np.float32) for _ in range(3))
        slot = rng.integers(0, 1000, n).astype(np.uint32)
        keep = rng.random(n) < 0.6
        b = _Batch(jit.Array3f(*o), jit.Array3f(*d), jit.Array3f(*w), jit.UInt32(slot),
                   first=7, spp=4)
        children.append((b, jit.Bool(keep)))
        for f, v in (("o", o), ("d", d), ("weight", w)):
            want[f].append(v[:, keep])
        want["slot"].append(slot[keep])
    out = _compact(children)
    assert out.first == 7 and out.spp == 4 and out.state is None
    for f in ("o", "d", "weight"):
        np.testing.assert_array_equal(getattr(out, f).numpy(), np.concatenate(want[f], axis=1))
    np.testing.assert_array_equal(out.slot.numpy(), np.concatenate(want["slot"]))
    # the pixel and sample of each ray follow from its slot
    pixel, sample = out.pixel_and_sample()
    np.testing.assert_array_equal(pixel.numpy(), out.slot.numpy() // 4 + 7)
    np.testing.assert_array_equal(sample.numpy(), out.slot.numpy() % 4)


def test_compact_nothing_kept():
    backend.use()
    from whitted.tracer.integrator import _Batch, _compact

    z = dr.zeros(jit.Array3f, 4)
    b = _Batch(z, z, z, dr.arange(jit.UInt32, 4))
    assert _compact([(b, dr.zeros(jit.Bool, 4)), (b, dr.zeros(jit.Bool, 4))]) is None
