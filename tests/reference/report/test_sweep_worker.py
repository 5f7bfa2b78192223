"""The quick report's sweep in a worker process (reference/report/sweep_worker.py): the same
result as the sweep in the report's own process, and a failure is one line."""

import json

import pytest
from conftest import SCENES, approx_floats, sweep_without_seconds

from whitted.reference import mutants
from whitted.reference.report import sweep_worker
from whitted.tracer.errors import UserError


def test_the_worker_sweeps_as_the_reports_own_process_does():
    picked = [SCENES / "sphere_point.toml", SCENES / "three_lights.toml"]
    lines = []
    worker = sweep_worker.start(picked, quick=True)
    data = worker.result(progress=lines.append)
    here = json.loads(json.dumps(mutants.sweep(   # as JSON: tuples as lists
        picked, quick=True, log=lambda _: None,
        xml_sources=mutants.structure_sources()).to_json()))
    # The same verdicts, catches and checks; each margin within 1e-6 (relative): Dr.Jit
    # splits a sum into blocks by its thread count, and the worker runs on one thread
    # until the report waits for it, so a float32 sum may differ in its last places
    # (seen: a structure margin 9850.87299 against 9850.87327, 3e-8 apart relative).
    a, b = sweep_without_seconds(data), approx_floats(sweep_without_seconds(here), 1e-6)
    assert a == b, [(x["id"], k, x[k], y[k])
                    for x, y in zip(a["mutants"], b["mutants"], strict=True)
                    for k in x if x[k] != y[k]] or [k for k in a if a[k] != b[k]]
    # each scene's and each XML file's line reached the report, numbered as judged
    total = len(picked) + len(mutants.structure_sources())
    assert len(lines) == total and lines[0].startswith(f"[1/{total}]")
    assert not worker.tmp.exists()   # its files are removed


def test_a_worker_that_fails_says_why_in_one_line(tmp_path):
    bad = tmp_path / "broken.toml"
    bad.write_text("[film\n")
    with pytest.raises(UserError) as e:
        sweep_worker.start([bad]).result(progress=lambda _: None)
    message = str(e.value)
    assert message.startswith("the formula-bug sweep's worker failed: ")
    assert "broken.toml" in message
    assert "\n" not in message


@pytest.mark.parametrize("text", ["{", "[]", json.dumps({"pass": True}),
                                  json.dumps({"pass": True, "clean_passed": True,
                                              "all_caught": True, "quick": True,
                                              "seconds": 1.0, "scenes": [],
                                              "mutants": [{"id": "x"}]})])
def test_a_result_of_the_wrong_shape_is_refused(tmp_path, text):
    path = tmp_path / "sweep.json"
    path.write_text(text)
    with pytest.raises(UserError, match="formula-bug sweep's worker wrote"):
        sweep_worker.read_result(path)
