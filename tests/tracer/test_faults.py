"""The switches that put a formula bug into the tracer at run time (tracer/faults.py)."""

import re

import drjit as dr
import numpy as np
import pytest
from conftest import SCENES

import whitted.reference.mutants  # noqa: F401  (declares the catalog's ids)
from whitted.tracer import faults, load_scene
from whitted.tracer.integrator import Integrator


def _render(name, size=(48, 36), spp=4):
    scene = load_scene(SCENES / f"{name}.toml").with_overrides(size=size, spp=spp)
    return Integrator(scene).render().image


def _kernels(name):
    """The IR of every kernel a small render launches, without what Dr.Jit decides at run
    time from the buffers it is handed (their alignment) and the hash in the name."""
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    try:
        dr.kernel_history()
        _render(name)
        irs = []
        for k in dr.kernel_history():
            if k["type"] == dr.KernelType.JIT:
                t = k["ir"].getvalue()
                t = re.sub(r"drjit_[0-9a-f]{32}", "drjit_K", t)
                t = re.sub(r"align \d+", "align A", t)
                irs.append(re.sub(r"i32 \d+, <(\d+) x i1>", r"i32 A, <\1 x i1>", t))
        return irs
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, False)


def test_switching_off_restores_the_image_bit_for_bit():
    # mirror_sphere: one lobe per hit, so every sample's light is summed in a fixed order
    # (with two lobes the children of one sample add into one slot from several threads).
    before = _render("mirror_sphere")
    with faults.active("reflect-sign"):
        wrong = _render("mirror_sphere")
    after = _render("mirror_sphere")
    assert np.abs(wrong - before).max() > 0.01
    assert np.array_equal(before, after)


@pytest.mark.skipif("config.getoption('--backend') == 'cuda'", reason="LLVM IR")
def test_a_switched_kernel_is_not_reused_unswitched():
    # Dr.Jit caches kernels by a hash of their IR: the switch changes the traced IR, so
    # its kernel is another one, and switching off gives back the very same IR.
    before = _kernels("sphere_point")
    with faults.active("lambert-no-inv-pi"):
        switched = _kernels("sphere_point")
    after = _kernels("sphere_point")
    assert before == after
    assert switched != before and len(switched) == len(before)


def test_two_switches_at_once_apply_both_and_nest():
    # Only direct light from one point light on diffuse surfaces: dropping 1/pi multiplies
    # every pixel by pi, whatever the falloff, so both bugs together are the one times pi.
    with faults.active("point-light-no-falloff"):
        one = _render("sphere_point")
        with faults.active("lambert-no-inv-pi") as on:
            assert on == {"point-light-no-falloff", "lambert-no-inv-pi"}
            both = _render("sphere_point")
        assert faults.current() == {"point-light-no-falloff"}
    assert faults.current() == frozenset()
    lit = one > 1e-3 * one.max()
    assert lit.mean() > 0.2
    assert np.allclose(both[lit], np.pi * one[lit], rtol=1e-5)


def test_an_unknown_id_is_refused_in_one_line():
    with pytest.raises(faults.UnknownFault) as e:
        with faults.active("reflect-sign", "no-such-bug"):
            pass
    msg = str(e.value)
    assert "no-such-bug" in msg and "\n" not in msg
    assert faults.current() == frozenset()   # nothing was switched on


def test_recording_collects_the_switches_a_render_reaches():
    with faults.recording() as asked:
        _render("sphere_point")
    assert {"lambert-no-inv-pi", "point-light-no-falloff", "lambert-no-cosine",
            "fov-vertical-for-horizontal"} <= asked
    # No glass, area light, spot or mesh there: their switches are never asked about.
    assert not asked & {"schlick-for-exact", "area-pdf-disk", "spot-linear-falloff",
                        "barycentrics-swapped"}
