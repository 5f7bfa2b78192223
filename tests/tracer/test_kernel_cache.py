"""The same scene gives the same kernels every time it is built, so Dr.Jit compiles them once.

Dr.Jit on the CPU uses a numpy array's memory as it is and writes whether it
is 64-byte aligned into the kernel; numpy's small arrays land on 16- or
32-byte boundaries as it happens. Before :func:`tracer.backend.upload`, a scene
built again (each render of the formula-bug sweep builds its own) gave another
kernel hash by chance, and LLVM compiled the kernel again.
"""

import drjit as dr
import numpy as np
import pytest

from whitted import tracer  # noqa: F401  (chooses libLLVM before drjit loads)
from whitted.reference.cli import resolve_scene
from whitted.tracer import backend, load_scene
from whitted.tracer.backend import jit, upload, upload_rows
from whitted.tracer.integrator import Integrator


def _hashes(fn) -> set:
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    dr.kernel_history()  # clears it
    try:
        fn()
        return {k["hash"] for k in dr.kernel_history() if k["type"] == dr.KernelType.JIT}
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, False)


def test_upload_places_every_array_on_a_64_byte_boundary():
    """Each numpy offset (0..15 floats into a buffer) gives the same kernel: one float
    broadcast to every lane, and a table read in lane order."""
    backend.use()
    buf = np.arange(64, dtype=np.float32)
    seen = set()
    for off in range(16):
        one = upload(jit.Float, buf[off:off + 1], np.float32)
        table = upload(jit.Float, buf[off:off + 20], np.float32)
        assert one[0] == off and table.numpy().tolist() == list(range(off, off + 20))

        def kernel(one=one, table=table):
            dr.eval(dr.arange(jit.Float, 20) * one + table)

        seen |= _hashes(kernel)
    assert len(seen) == 1
    rows = upload_rows(jit.Array3f, [[1, 2, 3], [4, 5, 6]])
    assert rows.numpy().T.tolist() == [[1, 2, 3], [4, 5, 6]]
    assert upload(jit.Bool, [True, False], bool).numpy().tolist() == [True, False]


@pytest.mark.parametrize("name", ["sky", "textured", "whitted_mix", "masked", "shapes_zoo"])
def test_a_scene_built_again_gives_the_same_kernels(name):
    """Four builds of one scene: one set of kernel hashes. Before the fix these scenes
    gave a new hash in most builds (numpy's alignment, by chance)."""
    backend.use()
    scene = load_scene(resolve_scene(name)).with_overrides(size=(16, 12), spp=1)
    first = _hashes(lambda: Integrator(scene).render())
    for _ in range(3):
        again = load_scene(resolve_scene(name)).with_overrides(size=(16, 12), spp=1)
        assert _hashes(lambda s=again: Integrator(s).render()) == first


def test_nearby_max_depths_share_the_stack_kernel():
    """The stack schedule sizes its kernel for max_depth rounded up to a multiple of 8,
    with max_depth itself an opaque value: a depth sweep compiles a kernel per 8 depths,
    not one per depth."""
    backend.use()
    scene = load_scene(resolve_scene("glass_sphere")).with_overrides(size=(16, 12), spp=1)

    def kernels(max_depth):
        integ = Integrator(scene.with_overrides(max_depth=max_depth))
        assert integ.schedule == "stack"
        integ.render()  # the first render and later ones may differ (benchmarks/HISTORY.md)
        return _hashes(integ.render)

    assert kernels(3) == kernels(8) == kernels(5)
    assert kernels(9) == kernels(16) != kernels(8)
