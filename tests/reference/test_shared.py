"""Results shared inside one report (reference/shared.py): made once, reused only where
reuse cannot change a verdict."""

from pathlib import Path

import pytest

from whitted.reference import mutants
from whitted.reference.shared import reused, shared
from whitted.tracer import faults, load_scene

SCENES = Path(__file__).resolve().parents[2] / "scenes"
#: a bug of the catalog (declared when reference.mutants is imported)
BUG = "lambert-no-cosine"


def test_inside_shared_a_result_is_made_once_per_key_and_outside_every_time():
    made = []

    def make(v):
        return lambda: made.append(v) or v

    with shared():
        assert reused(make(1), "scene", 0) == 1
        assert reused(make(2), "scene", 0) == 1      # the same key: the first result
        assert reused(make(3), "scene", 1) == 3      # another key
    assert reused(make(4), "scene", 0) == 4          # outside: made again
    assert made == [1, 3, 4]


def test_with_a_bug_on_nothing_is_reused_or_kept():
    made = []
    with shared():
        reused(lambda: made.append("clean") or "clean", "k")
        with faults.active(BUG):
            assert reused(lambda: made.append("bug") or "bug", "k") == "bug"
            assert reused(lambda: made.append("bug2") or "bug2", "other") == "bug2"
        assert reused(lambda: made.append("clean2") or "clean2", "other") == "clean2"
    assert made == ["clean", "bug", "bug2", "clean2"]


def test_a_reused_result_reports_the_switches_its_computation_asked_about():
    """The sweep finds which bugs reach a scene by recording the switches its clean
    renders ask about; a render reused from the comparison must report them again."""
    def render():
        faults.on(BUG)
        return "image"

    with shared():
        reused(render, "scene")                      # the comparison: nothing records
        with faults.recording() as asked:
            assert reused(lambda: pytest.fail("made again"), "scene") == "image"
    assert asked == {BUG}


@pytest.mark.parametrize("name", ["area_lights", "glass_sphere"])
def test_the_sweep_judges_alike_with_the_comparisons_results_shared(name):
    """The report's sweep reuses the comparison's references and clean renders; its
    findings must be those of a sweep that makes its own. area_lights has a second
    opinion (one-lobe reference, 16 pooled tracer seeds), glass_sphere the
    deterministic verdict only; the bugs include a shared one (blind to the
    deterministic reference) and one of each scene's kind."""
    from whitted.reference.verdicts.compare import compare_scene

    path = SCENES / f"{name}.toml"
    bugs = mutants.get(["light-sample-same-uv", "lambert-no-cosine", "area-pdf-rectangle",
                        "tir-ignored", "no-eta2-scaling", "sphere-half-b-discriminant"])

    def findings(result):
        return [(m.id, [(c.scene, c.verdict, round(c.margin, 9), c.check)
                        for c in m.caught_by], m.passed, m.blind, m.errors)
                for m in result.mutants]

    alone = mutants.sweep([path], bugs, quick=True, log=lambda m: None)
    with shared():
        compare_scene(mutants.sweep_size(load_scene(path), True))
        again = mutants.sweep([path], bugs, quick=True, log=lambda m: None)
    assert findings(again) == findings(alone)
    assert any(m.caught_by for m in alone.mutants)
