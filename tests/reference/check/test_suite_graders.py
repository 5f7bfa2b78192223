"""`whitted suite check`'s files for graders: Gradescope's results.json and a JUnit junit.xml,
written with the table, the page and suite.json, all or none."""

import errno
import json
import xml.etree.ElementTree as ET

import numpy as np
import pytest
from conftest import MINIMAL

from whitted.reference.cli import main


@pytest.fixture(scope="module")
def graded(tmp_path_factory):
    """A suite of two 8x6 scenes, one image that passes, one far too bright, one missing
    scene image, and an image of no scene: the command's exit status and output folder."""
    from whitted.reference.check import suite
    from whitted.tracer.imageio import read_exr, write_exr

    base = tmp_path_factory.mktemp("graders")
    for name in ("good", "bright", "absent"):
        (base / f"{name}.toml").write_text(MINIMAL)
    suite.export(base / "suite", [base / f"{n}.toml" for n in ("good", "bright", "absent")],
                 log=lambda m: None)
    images = base / "images"
    images.mkdir()
    ref = read_exr(base / "suite" / "references" / "good.exr")
    write_exr(images / "good.exr", ref * np.float32(1.0001))
    write_exr(images / "bright.exr", ref * np.float32(3) + np.float32(1))
    write_exr(images / "stray.exr", ref)
    rc = main(["suite", "check", str(images), "--suite", str(base / "suite")])
    return rc, images / "whitted-check"


def test_results_json_follows_gradescopes_schema(graded):
    rc, out = graded
    assert rc == 1
    data = json.loads((out / "results.json").read_text())
    assert data["score"] == 1.0 and data["max_score"] == 3.0
    assert isinstance(data["output"], str) and "stray.exr" in data["output"]
    tests = {t["name"]: t for t in data["tests"]}
    assert set(tests) == {"good", "bright", "absent"}
    for t in data["tests"]:
        assert set(t) >= {"name", "score", "max_score", "status", "output"}
        assert t["max_score"] == 1.0 and t["status"] in ("passed", "failed")
        assert isinstance(t["output"], str) and t["output"]
    assert tests["good"]["score"] == 1.0 and tests["good"]["status"] == "passed"
    assert tests["bright"]["score"] == 0.0 and tests["bright"]["status"] == "failed"
    assert "FAIL" in tests["bright"]["output"] and "pixels" in tests["bright"]["output"]
    assert tests["absent"]["status"] == "failed" and "missing" in tests["absent"]["output"]


def test_junit_xml_parses_back_with_one_testcase_a_scene(graded):
    _, out = graded
    root = ET.parse(out / "junit.xml").getroot()
    assert root.tag == "testsuites"
    (suite,) = root.findall("testsuite")
    assert (suite.get("tests"), suite.get("failures"), suite.get("errors")) == ("3", "2", "0")
    cases = {c.get("name"): c for c in suite.findall("testcase")}
    assert set(cases) == {"good", "bright", "absent"}
    assert list(cases["good"]) == []
    (failure,) = cases["bright"].findall("failure")
    assert failure.get("type") == "FAIL" and "pixels" in failure.get("message")
    assert cases["absent"].find("failure").get("type") == "missing"
    assert "stray.exr" in suite.find("system-out").text


def test_junit_xml_escapes_what_xml_cannot_carry():
    from whitted.reference.check.suite import Graded, SuiteResult, junit_xml

    bad = "a\x01b\udcff<&>"
    result = SuiteResult(False, [Graded("s", "x.png", False, "error", bad)])
    case = ET.fromstring(junit_xml(result)).find("testsuite/testcase")
    assert case.find("error").get("type") == "error"
    assert "<&>" in case.find("error").text and "\\x01" in case.find("error").text


@pytest.mark.parametrize("target", ["gradescope_results", "junit_xml"])
def test_a_grader_file_that_cannot_be_written_leaves_no_output(graded, tmp_path, monkeypatch,
                                                                capsys, target):
    import whitted.reference.check.suite as suite

    images = graded[1].parent

    def fail(*a, **k):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(suite, target, fail)
    rc = main(["suite", "check", str(images), "--suite", str(images.parent / "suite"),
               "-o", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert rc == 2 and "No space left on device" in err and err.count("\n") == 1
    assert not (tmp_path / "out").exists()
