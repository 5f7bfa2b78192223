"""Every formula line is reached by some scene of the report (issue 28).

A fresh interpreter renders the report's scenes under coverage.py: every built-in scene
with :func:`reference.report.build.quick_overrides` (the sizes of ``whitted report
--quick``) and at most :data:`SPP` samples per pixel, as the report's tracer side
renders it (at the strata centres, tracer-only parts replaced and in full, several seeds
with moments where lights are sampled), its image written as PNG, PPM and EXR; then the
report's imported Mitsuba scenes (``imported_cases(quick=True)``), read by
:mod:`tracer.mitsuba_xml` and rendered as the report renders them. It measures the code
that builds the kernels (:data:`MEASURED`): a line no scene reaches fails the test,
unless ``tests/e2e/coverage_allowed.toml`` lists it with the reason and the test that
reaches it instead.

Why coverage.py rather than a tracer of our own (``sys.settrace``): it is the field's
tool, well kept, and its C tracer is fast; a Dr.Jit kernel is built by running its
Python once (``dr.while_loop`` loops and ``dr.if_stmt`` branches are traced, both sides of
a branch), so a line that went into some kernel is a line coverage saw run, and one
it did not see is in no kernel of any scene.

Not counted: the blocks of ``if faults.on(...)`` and the wrong values of
``faults.pick(...)`` (the formula bugs of :mod:`tracer.faults`, reached by ``whitted
mutants``, whose sweep checks that every one is caught) and lines marked ``# pragma: no
cover`` (none is).

The allow-list is keyed by file and a line's stripped text, or by a function's
qualified name (every unreached line in it), never by line number, so that edits
elsewhere in a file leave it valid. An entry that matches no unreached line fails too
(the line became reachable, or moved away: the entry goes), and so does one whose
``tested_by`` names no test that exists (``"none"`` says that no test reaches the line
either: a finding, kept visible).

Run as a script (``python tests/e2e/test_formula_coverage.py OUT.json``) it is the measuring
child; ``--scenes PATTERN`` renders only some built-in scenes (to see which lines a
scene alone reaches).
"""

from __future__ import annotations

import ast
import fnmatch
import json
import re
import subprocess
import sys
import time
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
ALLOWED = Path(__file__).resolve().parent / "coverage_allowed.toml"

#: samples per pixel at most (the report's quick sizes, fewer samples: a line is reached
#: or not whatever the count; 4 = 2 x 2 strata, so stratification still runs)
SPP = 4
#: seeds of the pooled renders (the z-test's tracer side pools 16; two reach the same code)
SEEDS = 2

#: The measured files, relative to the tracer package: the kernels' formulas, the
#: camera, the writers of the image files and the Mitsuba XML reader.
MEASURED = ("shapes/*.py", "materials/*.py", "emitters/*.py", "camera.py", "fresnel.py",
            "phong.py", "lights.py", "texture.py", "sampling.py", "transform.py",
            "imageio.py", "mitsuba_xml.py", "scene.py", "fov.py")
#: Of these files only these functions (qualified names, and what they hold) are measured:
#: imageio.py's writers and what they call (its readers are the scene loader's and the
#: tests'), scene.py's one formula, the field of view along ``fov_axis`` (the rest of it is
#: the scene model's validation).
ONLY_FUNCTIONS = {"imageio.py": ("srgb_encode", "to_srgb8", "_atomic_write", "file_mode",
                                 "_os_error", "write_exr", "write_png", "_write_png_file",
                                 "ppm_values", "write_ppm", "write_image"),
                  "scene.py": ("Camera.fov_x",)}
#: Blocks not counted (coverage.py excludes the whole block of a matching ``if``).
EXCLUDE = (r"^\s*(el)?if faults\.on\(",)


# ---------------------------------------------------------------- the measuring child


def _tracer_dir() -> Path:
    """The folder of ``whitted.tracer``, found without importing it."""
    import importlib.util

    spec = importlib.util.find_spec("whitted.tracer")
    return Path(spec.origin).parent


def _qualnames(source: str) -> dict[int, str]:
    """Line number -> the qualified name of the innermost function (or class) holding it."""
    out: dict[int, str] = {}

    def walk(node, prefix):
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
                name = prefix + child.name
                first = min([child.lineno] + [d.lineno for d in child.decorator_list])
                for n in range(first, child.end_lineno + 1):
                    out[n] = name
                walk(child, name + ".")
            else:
                walk(child, prefix)

    walk(ast.parse(source), "")
    return out


def _render_builtin(path: Path, folder: Path) -> None:
    """One built-in scene as the report's tracer side renders it, its image in 3 formats."""
    from whitted.reference.report.build import quick_overrides
    from whitted.reference.verdicts.compare import at_strata_centres, comparable
    from whitted.tracer import load_scene
    from whitted.tracer.imageio import write_image
    from whitted.tracer.integrator import Integrator

    scene = quick_overrides(load_scene(path))
    scene = at_strata_centres(scene.with_overrides(spp=min(scene.film.spp, SPP)))
    judged = comparable(scene)
    image = Integrator(judged).render().image
    if judged is not scene:           # the full render, tracer-only parts and all
        image = Integrator(scene).render().image
    scene.tracer_only_used()
    if judged.samples_lights():       # the z-test's pooled seeds, with moments
        Integrator(judged).render_seeds(range(SEEDS), moments=True)
    for suffix in (".png", ".ppm", ".exr"):
        write_image(folder / f"{path.stem}{suffix}", image)


def _render_imported(case, folder: Path) -> None:
    """One of the report's imported Mitsuba scenes, read and rendered as the report does."""
    from whitted.reference.renderers.mitsuba.importer import dict_to_xml, render_imported
    from whitted.tracer.mitsuba_xml import read_xml
    from whitted.tracer.scene import parse_scene

    xml = case.xml
    if xml is None:                   # mi.cornell_box(), written as XML
        from whitted.reference import mitsuba

        source = mitsuba().cornell_box()
        source["sensor"]["film"]["width"] = source["sensor"]["film"]["height"] = case.size
        xml = folder / f"{case.name}.xml"
        xml.write_text(dict_to_xml(source))
    imp = read_xml(xml)
    scene = parse_scene(imp.data, str(xml))
    scene = scene.with_overrides(max_depth=2, spp=min(case.spp, SPP))
    render_imported(scene, seeds=min(case.passes, SEEDS))


def measure(out: Path, pattern: str | None = None) -> None:
    """Render the scenes under coverage; write each measured file's unreached lines."""
    import tempfile

    import coverage

    t0 = time.perf_counter()
    tracer_dir = _tracer_dir()
    files = sorted({p for g in MEASURED for p in tracer_dir.glob(g)
                    if p.name != "__init__.py" or p.stat().st_size})
    cov = coverage.Coverage(data_file=None, config_file=False,
                            include=[str(p) for p in files])
    for rx in EXCLUDE:
        cov.exclude(rx)
    cov.start()
    try:
        from whitted.reference.renderers.mitsuba.importer import imported_cases
        from whitted.scenes import builtin_scenes

        timings = {}
        with tempfile.TemporaryDirectory(prefix="whitted-coverage-") as tmp:
            for path in builtin_scenes():
                if pattern and not fnmatch.fnmatch(path.stem, pattern):
                    continue
                t = time.perf_counter()
                _render_builtin(path, Path(tmp))
                timings[path.stem] = time.perf_counter() - t
            for case in imported_cases(quick=True):
                t = time.perf_counter()
                _render_imported(case, Path(tmp))
                timings["imported/" + case.name] = time.perf_counter() - t
    finally:
        cov.stop()
    result = {"seconds": time.perf_counter() - t0, "scenes": timings, "files": {}}
    for p in files:
        _, statements, _, missing, _ = cov.analysis2(str(p))
        source = p.read_text()
        lines, names = source.splitlines(), _qualnames(source)
        rel = p.relative_to(tracer_dir.parent).as_posix()
        only = ONLY_FUNCTIONS.get(p.name)
        if only:
            def inside(n, only=only, names=names):
                name = names.get(n, "")
                return any(name == f or name.startswith(f + ".") for f in only)
            statements = [n for n in statements if inside(n)]
            missing = [n for n in missing if inside(n)]
        result["files"][rel] = {
            "statements": len(statements),
            "unreached": [[n, lines[n - 1].strip(), names.get(n, "")] for n in missing]}
    out.write_text(json.dumps(result, indent=1))


# ---------------------------------------------------------------- the allow-list


def load_allowed(path: Path = ALLOWED) -> list[dict]:
    """The allow-list's entries: file, line (stripped text) or function, reason, tested_by."""
    return tomllib.loads(path.read_text()).get("allow", [])


def _matches(entry: dict, file: str, text: str, function: str) -> bool:
    if entry["file"] != file:
        return False
    if "line" in entry and entry["line"] != text:
        return False
    if "function" in entry:
        f = entry["function"]
        if function != f and not function.startswith(f + "."):
            return False
    return True


def judge(files: dict, allowed: list[dict]) -> tuple[list[str], list[dict]]:
    """(unreached lines no entry allows, as 'file:line: text', entries that match nothing)."""
    used = [False] * len(allowed)
    bad = []
    for file, info in files.items():
        for n, text, function in info["unreached"]:
            hits = [i for i, e in enumerate(allowed) if _matches(e, file, text, function)]
            for i in hits:
                used[i] = True
            if not hits:
                bad.append(f"{file}:{n}: {text}" + (f"  (in {function})" if function else ""))
    return bad, [e for e, u in zip(allowed, used, strict=True) if not u]


# ---------------------------------------------------------------- the tests


def run_child(tmp_path: Path, pattern: str | None = None) -> dict:
    out = tmp_path / "coverage.json"
    args = [sys.executable, __file__, str(out)] + (["--scenes", pattern] if pattern else [])
    proc = subprocess.run(args, capture_output=True, text=True, timeout=900, cwd=ROOT)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-6000:]
    return json.loads(out.read_text())


def test_allow_list_entries_say_why_and_name_an_existing_test():
    for e in load_allowed():
        where = f"{e.get('file')}: {e.get('line') or e.get('function')}"
        assert set(e) <= {"file", "line", "function", "reason", "tested_by"}, where
        assert (ROOT / e["file"]).is_file(), where
        assert "line" in e or "function" in e, where
        assert len(e.get("reason", "")) >= 20, f"{where}: say why no scene reaches it"
        if e["tested_by"] == "none":   # no test reaches it either: a finding, said so
            continue
        test_file, _, test_name = e["tested_by"].partition("::")
        assert (ROOT / test_file).is_file(), f"{where}: no test file {test_file}"
        if test_name:
            text = (ROOT / test_file).read_text()
            assert re.search(rf"def {re.escape(test_name)}\b", text), \
                f"{where}: {test_file} has no {test_name}"


def test_judge_keys_by_text_and_function_not_line_number():
    files = {"tracer/a.py": {"unreached": [[10, "return None", "f"], [20, "return None", "g"],
                                           [30, "x = 1", "C.h.inner"]]}}
    allowed = [{"file": "tracer/a.py", "line": "return None", "function": "f"},
               {"file": "tracer/a.py", "function": "C.h"},
               {"file": "tracer/a.py", "line": "gone = 2"}]
    bad, stale = judge(files, allowed)
    assert bad == ["tracer/a.py:20: return None  (in g)"]
    assert stale == [allowed[2]]


def test_every_formula_line_is_reached_by_a_scene_of_the_report(tmp_path):
    result = run_child(tmp_path)
    allowed = load_allowed()
    bad, stale = judge(result["files"], allowed)
    total = sum(f["statements"] for f in result["files"].values())
    assert not bad, (
        f"{len(bad)} of {total} measured lines are reached by no scene of the report "
        f"(quick sizes, {result['seconds']:.0f} s); add a scene that reaches each, or list "
        f"it in {ALLOWED.relative_to(ROOT)} with the reason and the test that reaches it:\n"
        + "\n".join(bad))
    assert not stale, ("allow-list entries that match no unreached line (now reached, or "
                       "gone): remove them:\n"
                       + "\n".join(f"{e['file']}: {e.get('line') or e.get('function')}"
                                   for e in stale))


if __name__ == "__main__":
    import argparse

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("out", type=Path)
    parser.add_argument("--scenes", help="only the built-in scenes matching this pattern")
    ns = parser.parse_args()
    measure(ns.out, ns.scenes)
