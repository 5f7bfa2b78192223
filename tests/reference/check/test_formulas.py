"""`whitted formulas`: a renderer's formulas judged one function at a time, and a wrong one
named by the catalog's bug that gives the same answers."""

import re
import shutil
import subprocess
import sys

import pytest
from conftest import ROOT, run_cli

from whitted.reference.check import formulas as F
from whitted.reference.cli import main

ADAPTER_PY = ROOT / "docs" / "formulas" / "adapter.py"
ADAPTER_CPP = ROOT / "docs" / "formulas" / "adapter.cpp"
WRONG = ROOT / "tests" / "data" / "formulas" / "wrong_adapter.py"
#: what the C++ example implements (it answers "not implemented" to the others)
CPP_FORMULAS = ("sphere_intersect,triangle_intersect,reflect,refract,fresnel_exact,"
                "fresnel_schlick,lambert,phong,blinn_phong,point_light,spot_falloff")


def _whitted(capsys, *args):
    rc = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return rc, out, err


def _sections(out: str) -> dict[str, str]:
    """The printed table, one block of lines a formula."""
    blocks, name = {}, None
    for line in out.splitlines():
        m = re.match(r"^(\w+)\s+\d+\s+", line)
        if m and m.group(1) in F.BY_NAME:
            name = m.group(1)
            blocks[name] = line + "\n"
        elif name and line.startswith("  "):
            blocks[name] += line + "\n"
    return blocks


def test_the_python_adapter_passes_as_a_program_and_as_a_callable(capsys):
    rc, out, err = _whitted(capsys, "formulas", "--program", f"{sys.executable} {ADAPTER_PY}")
    assert rc == 0, out + err
    assert "PASS: all 14 formulas" in out
    assert all(" pass" in b for b in _sections(out).values()) and len(_sections(out)) == 14
    rc, out, err = _whitted(capsys, "formulas", "--python", f"{ADAPTER_PY}:formula")
    assert rc == 0, out + err


def test_the_cpp_adapter_compiles_without_dependencies_and_passes(tmp_path, capsys):
    gxx = shutil.which("g++")
    if gxx is None:
        pytest.skip("g++ is not installed: the C++ example adapter cannot be compiled here")
    exe = tmp_path / "adapter"
    r = subprocess.run([gxx, "-std=c++17", "-O2", "-Wall", "-Werror", "-o", str(exe),
                        str(ADAPTER_CPP)], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    rc, out, err = _whitted(capsys, "formulas", "--program", exe, "--formulas", CPP_FORMULAS)
    assert rc == 0, out + err
    # What it leaves out is a failure, said so, not a bad adapter.
    rc, out, err = _whitted(capsys, "formulas", "--program", exe, "--formulas", "camera_ray")
    assert rc == 1 and "not implemented" in out, out + err


# The wrong adapter's bugs, each the catalog's as a student would write it.
NAMED = ["schlick-dense-side-cosine", "tir-ignored", "sphere-near-root-from-inside",
         "reflect-sign", "fresnel-average-amplitudes", "lambert-abs-cosine",
         "half-vector-unnormalized", "phong-no-normalization", "barycentrics-swapped",
         "camera-y-not-flipped", "point-light-linear-falloff", "spot-linear-falloff",
         "instance-normal-by-matrix"]


def test_each_bug_of_a_wrong_adapter_is_named_in_its_formula(capsys):
    sys.path.insert(0, str(WRONG.parent))
    try:
        import wrong_adapter
    finally:
        sys.path.remove(str(WRONG.parent))
    rc, out, err = _whitted(capsys, "formulas", "--program",
                            f"{sys.executable} {WRONG} {','.join(NAMED)}")
    assert rc == 1, out + err
    blocks = _sections(out)
    for bug in NAMED:
        block = blocks[wrong_adapter.BUGS[bug][0]]
        assert "FAIL" in block and f"catalog bug: {bug} " in block, block
        assert "first failing input" in block and "expected:" in block and "given:" in block
    assert " pass" in blocks["fresnel_conductor"]   # the formula left right passes


def test_snells_ratio_inverted_is_named(capsys):
    rc, out, _ = _whitted(capsys, "formulas", "--formulas", "refract", "--program",
                          f"{sys.executable} {WRONG} snell-eta-inverted")
    assert rc == 1 and "catalog bug: snell-eta-inverted " in out, out


def test_a_bug_the_catalog_lacks_fails_and_names_none(capsys, tmp_path):
    rc, out, _ = _whitted(capsys, "formulas", "--formulas", "fresnel_schlick", "--program",
                          f"{sys.executable} {WRONG} schlick-exponent-4",
                          "--json", tmp_path / "f.json")
    assert rc == 1
    assert "catalog bug: none matches (tried schlick-dense-side-cosine, tir-ignored)" in out
    import json

    data = json.loads((tmp_path / "f.json").read_text())
    (f,) = data["formulas"]
    assert f["status"] == "FAIL" and f["bugs"] == [] and f["first_failure"]["inputs"]


def test_every_formula_reaches_a_bug_of_the_catalog():
    # Naming works only where the tracer's formula carries the catalog's switches.
    from whitted.reference import mutants  # noqa: F401
    from whitted.tracer import faults

    for f in F.FORMULAS:
        with faults.recording() as asked:
            f.tracer([inputs for _, inputs in f.cases()])
        assert asked & set(mutants.BY_ID), f.name


def test_the_tracers_formulas_agree_with_mitsubas_on_every_case():
    # Where Mitsuba is the reference, the tracer's own formula (used to name bugs) must
    # pass it, or a right answer would be matched against a wrong baseline.
    for f in F.FORMULAS:
        rows = [inputs for _, inputs in f.cases()]
        for (label, _), e, t in zip(f.cases(), f.expected(rows), f.tracer(rows), strict=True):
            assert F.compare(f, t, e) is None, (f.name, label, e, t)


def test_the_cases_cover_grazing_inside_tir_and_misses():
    labels = {f.name: " ".join(label for label, _ in f.cases()) for f in F.FORMULAS}
    for name in ("refract", "fresnel_exact", "fresnel_schlick"):
        assert "total internal reflection" in labels[name] and "grazing" in labels[name]
        assert "from inside" in labels[name]
    assert "from inside" in labels["sphere_intersect"] and "miss" in labels["sphere_intersect"]
    assert "degenerate" in labels["triangle_intersect"] and "grazing" in labels["reflect"]


PROGRAMS = {
    "garbage": ("import sys; sys.stdin.readline(); print('hello')", "not JSON"),
    "wrong id": ("import sys; sys.stdin.readline(); print('{\"id\": 7, \"outputs\": {}}')",
                 "expected an object"),
    "wrong type": ("import sys; sys.stdin.readline(); "
                   "print('{\"id\": 1, \"outputs\": {\"hit\": 1}}')", "true or false"),
    "crash": ("import sys; sys.stdin.readline(); sys.exit('segfault, say')", "crashed"),
    "timeout": ("import sys, time; sys.stdin.readline(); time.sleep(30)", "timed out"),
}


@pytest.mark.parametrize("kind", PROGRAMS)
def test_a_bad_adapter_exits_2_in_one_line(capsys, tmp_path, kind):
    code, words = PROGRAMS[kind]
    script = tmp_path / "bad.py"
    script.write_text(code)
    rc, _, err = _whitted(capsys, "formulas", "--timeout", "2", "--program",
                          f"{sys.executable} {script}")
    assert rc == 2, err
    assert err.count("\n") == 1 and words in err and "Traceback" not in err, err


def test_a_callable_that_raises_or_hangs_is_a_bad_adapter(capsys, tmp_path):
    (tmp_path / "bad.py").write_text("import time\n"
                                     "def boom(name, inputs):\n    raise ZeroDivisionError('x')\n"
                                     "def hang(name, inputs):\n    time.sleep(30)\n")
    rc, _, err = _whitted(capsys, "formulas", "--python", f"{tmp_path / 'bad.py'}:boom")
    assert rc == 2 and "crashed" in err and "ZeroDivisionError" in err, err
    rc, _, err = _whitted(capsys, "formulas", "--timeout", "1", "--python",
                          f"{tmp_path / 'bad.py'}:hang")
    assert rc == 2 and "timed out" in err, err


def test_the_list_and_bad_options():
    r = run_cli("formulas", "--list")
    assert r.returncode == 0 and "tolerance" in r.stdout and "refract" in r.stdout
    r = run_cli("formulas")
    assert r.returncode == 2 and "--program" in r.stderr
    r = run_cli("formulas", "--python", "x:f", "--formulas", "nothing*")
    assert r.returncode == 2 and "no formula matches" in r.stderr
