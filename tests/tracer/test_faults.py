"""The switches that put a formula bug into the tracer at run time (tracer/faults.py)."""

import re

import numpy as np
import pytest
from conftest import SCENES, jit_kernels

import whitted.reference.mutants  # noqa: F401  (declares the catalog's ids)
from whitted.tracer import faults, load_scene
from whitted.tracer.integrator import Integrator


def _render(name, size=(48, 36), spp=4):
    scene = load_scene(SCENES / f"{name}.toml").with_overrides(size=size, spp=spp)
    return Integrator(scene).render().image


def _kernels(name):
    """The IR of every kernel a small render launches, without what Dr.Jit decides at run
    time from the buffers it is handed (their alignment) and the hash in the name."""
    irs = []
    for k in jit_kernels(lambda: _render(name)):
        t = k["ir"].getvalue()
        t = re.sub(r"drjit_[0-9a-f]{32}", "drjit_K", t)
        t = re.sub(r"align \d+", "align A", t)
        irs.append(re.sub(r"i32 \d+, <(\d+) x i1>", r"i32 A, <\1 x i1>", t))
    return irs


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


#: Bugs decided by faults.pick that reach glass_sphere (its catalog entries): each
#: breaks a formula in another part of the tracer.
PICKED = ("lambert-no-inv-pi", "shadow-acne", "point-light-linear-falloff",
          "fresnel-average-amplitudes", "snell-eta-inverted", "camera-y-not-flipped",
          "pixel-sample-corner")


@pytest.mark.skipif("config.getoption('--backend') == 'cuda'", reason="LLVM IR")
def test_bugs_decided_in_the_kernel_share_one_kernel_and_leave_the_clean_one_alone():
    # issue 33: the formula-bug sweep compiled a kernel for each scene and bug; with
    # shared_kernel the bug's number is an input of one kernel, not part of its IR.
    clean = _kernels("glass_sphere")
    shared = []
    for fault_id in PICKED:
        with faults.active(fault_id, shared_kernel=True):
            shared.append(_kernels("glass_sphere"))
    assert all(irs == shared[0] for irs in shared[1:])
    assert shared[0] != clean
    assert _kernels("glass_sphere") == clean


def test_a_bug_decided_in_the_kernel_gives_the_image_of_the_python_switch():
    # The same operations on the same numbers; only the compiler's choice of where to
    # fuse a multiply and an add (one rounding, 2^-24 relative, fewer or more) may
    # differ between the larger shared kernel and the switched one, a few roundings
    # along a sample's path: 1e-5 relative bounds it with room, while every bug here
    # changes the image by more than 1 % somewhere.
    clean = _render("glass_sphere")
    for fault_id in PICKED:
        with faults.active(fault_id):
            switched = _render("glass_sphere")
        with faults.active(fault_id, shared_kernel=True):
            shared = _render("glass_sphere")
        assert np.abs(switched - clean).max() > 0.01, fault_id
        np.testing.assert_allclose(shared, switched, rtol=1e-5, atol=1e-6, err_msg=fault_id)


@pytest.mark.skipif("config.getoption('--backend') == 'cuda'", reason="LLVM IR")
@pytest.mark.parametrize("name, fault_id", [("glass_sphere", "rotation-sign-flipped"),
                                            ("shape_lights", "rotation-sign-flipped"),
                                            ("whitted_mix", "steps-composed-in-reverse")])
def test_a_scene_read_again_with_a_placement_bug_shares_the_sweeps_kernel(name, fault_id):
    # issue 33: inside the sweep (shared_kernel) the scene's numbers are inputs of the
    # kernel (faults.number), so the scene read again with a bug of its placements
    # (its rotations turned or composed otherwise: other numbers, the same shapes)
    # runs the kernel that every other bug of the scene runs. Before, each such
    # reading compiled its own: 67 kernels, 11.8 s of LLVM in a cold quick sweep
    # (benchmarks/bench_kernels.py; benchmarks/HISTORY.md).
    scene = load_scene(SCENES / f"{name}.toml").with_overrides(size=(16, 12), spp=4)
    with faults.active(fault_id):
        moved = load_scene(SCENES / f"{name}.toml").with_overrides(size=(16, 12), spp=4)
    assert moved.shapes != scene.shapes or moved.lights != scene.lights
    with faults.active(fault_id, shared_kernel=True):
        assert _shading_kernel(moved) == _shading_kernel(scene)


def _shading_kernel(scene) -> str:
    """The hash of the largest kernel a render launches: its shading kernel (a moved mesh
    builds its own BVH first, in kernels of its own)."""
    return max((k["operation_count"], k["hash"])
               for k in jit_kernels(lambda: Integrator(scene).render()) if "hash" in k)[1]
