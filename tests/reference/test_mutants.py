"""The catalog of formula bugs (reference/mutants.py): each one is caught by some scene's verdict.

The sweep is the harness's power check: every plausible bug of the catalog,
switched into the tracer in turn (tracer/faults.py), must make at least one
built-in scene fail as ``whitted compare`` judges it, while the tracer as
written passes every scene. It runs at the quick sizes (at most 64 pixels
wide, 16 spp); ``python -m pytest -m slow tests/reference/test_mutants.py`` runs it at the
scenes' own sizes.
"""

import ast
import math
import re
from dataclasses import replace
from pathlib import Path

import pytest
from conftest import ROOT, SCENES, sweep_without_seconds

from whitted.reference import cli, mutants
from whitted.reference.renderers.mitsuba.deterministic import DeterministicReference
from whitted.reference.report.build import _mutants_html, _mutants_markdown
from whitted.reference.verdicts.compare import image_metrics, judge
from whitted.tracer import faults, load_scene
from whitted.tracer.integrator import Integrator

BUILTIN = sorted(SCENES.glob("*.toml"))


def _check(value, limit, passed=None):
    return {"value": value, "limit": limit,
            "pass": value < limit if passed is None else passed}


def test_margin_is_how_far_the_most_violated_check_exceeds_its_limit():
    checks = {"median_rel": _check(3e-5, 1e-5), "frac_over_01pct": _check(5e-4, 1e-3)}
    assert mutants.margin(checks) == (pytest.approx(3.0), "median_rel")
    # The z-test's fraction passing: failing fraction over the allowed one.
    z = {"z_fraction_passed": _check(0.99, 0.9975, passed=False)}
    assert mutants.margin(z)[0] == pytest.approx(0.01 / 0.0025)
    assert mutants.margin({"median_rel": _check(float("nan"), 1e-5, False)})[0] == math.inf


def _functions(path: Path) -> dict[str, ast.AST]:
    """'name' and 'Class.name' -> the function's node, for every function of a module."""
    tree = ast.parse(path.read_text())
    out = {}
    for node in tree.body:
        if isinstance(node, ast.FunctionDef):
            out[node.name] = node
        elif isinstance(node, ast.ClassDef):
            for f in node.body:
                if isinstance(f, ast.FunctionDef):
                    out[f"{node.name}.{f.name}"] = f
    return out


def _switches(node: ast.AST) -> list[str]:
    """The ids of the faults.on("id") and faults.pick("id", ...) calls inside a node."""
    return [c.args[0].value for c in ast.walk(node)
            if isinstance(c, ast.Call) and isinstance(c.func, ast.Attribute)
            and c.func.attr in ("on", "pick") and isinstance(c.func.value, ast.Name)
            and c.func.value.id == "faults" and c.args
            and isinstance(c.args[0], ast.Constant)]


def test_each_bug_has_one_switch_in_the_formula_function_it_names():
    ids = [m.id for m in mutants.CATALOG]
    assert len(ids) == len(set(ids)) and len(ids) >= 25
    for m in mutants.CATALOG:
        path, func = (x.strip() for x in m.where.split(":"))
        found = _switches(_functions(ROOT / path)[func])
        assert found.count(m.id) == 1, (m.id, m.where, found)
        assert m.summary.endswith(".") and m.wrong and m.correct
        assert re.fullmatch(r'lecture [12], "[^"]+"', m.topic), m.topic
    # ... and no switch in the tracer that the catalog does not name.
    in_tracer = [i for p in (ROOT / "tracer").rglob("*.py") for i in _switches(
        ast.parse(p.read_text()))]
    assert sorted(in_tracer) == sorted(ids)


def test_the_topics_are_the_lectures_slide_titles():
    seeds = Path("/work/shared/seeds")
    if not seeds.is_dir():
        pytest.skip("the lecture texts are not on this machine")
    text = " ".join(p.read_text() for p in seeds.glob("*.txt")).replace("’", "'")
    for m in mutants.CATALOG:
        title = m.topic.split('"')[1]
        assert title in text, title


def test_the_deterministic_reference_runs_no_tracer_formula_but_the_shared_ones():
    # Which bugs are 'shared' is not a guess: rendering the deterministic reference asks
    # about exactly the switches in the tracer code it reads (pixel positions, light
    # samples); every other switch lives in code only the tracer runs.
    shared = {m.id for m in mutants.CATALOG if m.shared}
    for name in ("area_lights", "glass_sphere"):
        scene = mutants.sweep_size(load_scene(SCENES / f"{name}.toml"), True)
        with faults.recording() as asked:
            DeterministicReference(scene).render()
        assert asked <= shared, asked - shared
    assert asked == {"pixel-sample-corner"}                       # glass_sphere
    assert shared == {"pixel-sample-corner", "light-sample-same-uv"}


@pytest.mark.parametrize("bug", ["light-sample-same-uv", "pixel-sample-corner"])
def test_a_shared_bug_is_invisible_to_the_deterministic_reference(bug):
    # With the bug in the code both read, the two agree at float precision: only the
    # one-lobe reference (Mitsuba's own sampler) can see it, as the sweep assumes.
    scene = mutants.sweep_size(load_scene(SCENES / "area_lights.toml"), True)
    with faults.active(bug):
        tracer = Integrator(scene).render().image
        ref = DeterministicReference(scene).render().image
    verdict, _ = judge("exact-strata", image_metrics(tracer, ref, with_flip=False), tracer, ref)
    assert verdict.passed, verdict.checks
    clean = Integrator(scene).render().image
    assert abs(float(clean.mean()) - float(tracer.mean())) > 1e-4 * float(clean.mean())


def test_a_bug_whose_switch_nothing_reads_is_reported_missed():
    # The sweep's pass needs a scene that fails: a catalog entry that switches nothing
    # (a misspelt id in the tracer, a switch left out) makes it fail.
    faults.declare(["no-op-bug"])
    noop = replace(mutants.BY_ID["lambert-no-inv-pi"], id="no-op-bug")
    result = mutants.sweep([SCENES / "sphere_point.toml"],
                           [noop, mutants.BY_ID["lambert-no-inv-pi"]], log=lambda _: None)
    assert result.clean_passed and not result.passed
    missed, caught = result.mutants
    assert not missed.caught and not missed.passed and not missed.blind
    assert caught.caught and caught.strongest.margin > 1e3


def test_mutants_command_exit_codes(capsys, tmp_path):
    assert cli.main(["mutants", "--only", "no-such-bug"]) == 2
    err = capsys.readouterr().err
    assert "no-such-bug" in err and err.count("\n") == 1
    assert cli.main(["mutants", "--scenes", "sphere_point", "--only", "lambert-no-inv-pi",
                     "-o", str(tmp_path / "m")]) == 0
    out = capsys.readouterr().out
    assert "1/1 mutants caught" in out and "PASS" in out
    assert (tmp_path / "m" / "mutants.json").exists()
    # A bug that sphere_point cannot show (no mirror there) is not caught: exit 1.
    assert cli.main(["mutants", "--scenes", "sphere_point", "--only", "reflect-sign"]) == 1
    assert "NOT CAUGHT: reflect-sign" in capsys.readouterr().out
    assert cli.main(["mutants", "--list"]) == 0
    listed = capsys.readouterr().out
    assert all(m.id in listed for m in mutants.CATALOG)


def test_every_bug_is_caught_and_the_tracer_as_written_passes_every_scene():
    result = mutants.sweep(BUILTIN, quick=True, log=lambda _: None,
                           xml_sources=mutants.structure_sources())
    report = mutants.format_table(result)
    failing = [s.name for s in result.scenes if not s.passed]
    assert not failing, report
    missed = [m.id for m in result.mutants if not m.caught]
    assert not missed, report
    assert not [m.errors for m in result.mutants if m.errors], report
    for m in result.mutants:
        assert all(c.margin > 1 for c in m.caught_by)
        if mutants.BY_ID[m.id].shared:     # seen only by the one-lobe reference: as the
            # second opinion, or as the main verdict of a scene it judges (shape_lights)
            assert {c.verdict for c in m.caught_by} <= {"second opinion", "onelobe"}
            assert "second opinion" in {c.verdict for c in m.caught_by}
        stage = mutants.BY_ID[m.id].stage
        if stage == "import":     # only Mitsuba's own reading of the XML can see it
            assert {c.verdict for c in m.caught_by} == {"structure"}, m.id
        if stage == "output":     # only the PNG against Mitsuba's encoding can see it
            assert {c.verdict for c in m.caught_by} == {"image file"}, m.id
        if mutants.BY_ID[m.id].shared or stage == "parse":
            # code both sides could read: caught by a margin of 10 or more somewhere
            assert m.strongest.margin >= 10, (m.id, m.strongest)
    # The report's section renders the same result.
    data = result.to_json()
    assert "NOT CAUGHT" not in _mutants_markdown(data)
    assert _mutants_html(data).count("<tr>") >= 2 * len(mutants.CATALOG)


@pytest.mark.slow
def test_every_bug_is_caught_at_the_scenes_own_sizes():
    result = mutants.sweep(BUILTIN, quick=False, log=lambda _: None,
                           xml_sources=mutants.structure_sources())
    assert result.passed, mutants.format_table(result)


def test_report_shows_the_bug_sweep_and_fails_when_a_bug_escapes(tmp_path):
    # A folder with one scene: that scene passes, but most bugs need others to show, so
    # the report, whose claim includes the harness's power, fails.
    import json
    import shutil

    folder = tmp_path / "scenes"
    folder.mkdir()
    shutil.copy(SCENES / "sphere_point.toml", folder)
    out = tmp_path / "rep"
    assert cli.main(["report", "--quick", "--no-fresnel", "--scenes-dir", str(folder),
                     "-o", str(out)]) == 1
    data = json.loads((out / "report.json").read_text())
    assert data["scenes"][0]["pass"] and not data["pass"]
    mu = data["mutants"]
    assert mu["clean_passed"] and not mu["all_caught"] and len(mu["mutants"]) == len(
        mutants.CATALOG)
    caught = {m["id"] for m in mu["mutants"] if m["caught"]}
    assert "lambert-no-inv-pi" in caught and "reflect-sign" not in caught
    assert "## Formula bugs: **FAIL**" in (out / "report.md").read_text()
    assert "id='mutants'" in (out / "index.html").read_text()


def test_a_scene_with_jitter_and_a_gaussian_filter_is_swept_as_compare_judges_it(tmp_path):
    """compare judges a scene at its strata centres with the box filter (jitter and a
    wider filter move and weigh the same samples alike on both sides); the sweep must
    too, or the tracer as written fails every such scene (a user's, or an import)."""
    text = (SCENES / "sphere_point.toml").read_text().replace(
        "[film]", '[film]\njitter = true\nfilter = "gaussian"', 1)
    (tmp_path / "jittered.toml").write_text(text)
    result = mutants.sweep([tmp_path / "jittered.toml"], [mutants.BY_ID["lambert-no-inv-pi"]],
                           log=lambda _: None)
    assert result.clean_passed, mutants.format_table(result)
    assert result.all_caught


def test_a_sweep_from_the_last_scene_gives_the_same_result_in_the_same_order():
    """The quick report's worker sweeps the scenes last first (reference.report.sweep_worker);
    its result lists scenes, and each bug's catches, in the given order all the same.
    Both bugs here are caught by both scenes, so a list kept in judging order differs."""
    picked = [SCENES / "sphere_point.toml", SCENES / "three_lights.toml"]
    bugs = [mutants.BY_ID["lambert-no-inv-pi"], mutants.BY_ID["point-light-no-falloff"]]
    forward = mutants.sweep(picked, bugs, log=lambda _: None)
    backward = mutants.sweep(picked, bugs, log=lambda _: None, last_first=True)
    assert [len(m.caught_by) for m in forward.mutants] == [2, 2]
    assert sweep_without_seconds(backward.to_json()) == sweep_without_seconds(forward.to_json())
