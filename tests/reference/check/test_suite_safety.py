"""`whitted suite check` and `whitted check` on hostile input: exit 2 in one line, nothing left.

A suite folder comes from anyone: its manifest's paths stay inside it (no
absolute path, no ``..``, no escape through a symbolic link), its structure is
checked before any work, and neither a FIFO nor a garbage reference hangs or
crashes the command. An error, a full disk or Ctrl-C while writing leaves no
partial output. Root ignores file modes, so a read-only folder is simulated by
a folder standing where a file is to be written and by a writer that raises
EROFS; a full disk by a writer that raises ENOSPC.
"""

import errno
import json
import os
import shutil

import numpy as np
import pytest
from conftest import MINIMAL, run_cli

from whitted.reference.check.suite import MAX_MANIFEST_NESTING, safe_member
from whitted.reference.cli import main
from whitted.tracer.errors import UserError


@pytest.fixture(scope="module")
def golden(tmp_path_factory):
    """A one-scene suite of an 8x6 scene, exported, and an image that passes against it."""
    from whitted.reference.check import suite
    from whitted.tracer.imageio import read_exr, write_exr

    base = tmp_path_factory.mktemp("safety")
    scene = base / "tiny.toml"
    scene.write_text(MINIMAL)
    suite.export(base / "suite", [scene], log=lambda m: None)
    (base / "images").mkdir()
    # Within the noise of the reference, yet not its bytes: a stored copy would show.
    image = read_exr(base / "suite" / "references" / "tiny.exr") * np.float32(1.0001)
    write_exr(base / "images" / "tiny.exr", image)
    return base


@pytest.fixture()
def work(golden, tmp_path):
    """A fresh copy of the suite and the images: (suite, images, manifest as a dict)."""
    shutil.copytree(golden / "suite", tmp_path / "suite")
    shutil.copytree(golden / "images", tmp_path / "images")
    manifest = json.loads((tmp_path / "suite" / "manifest.json").read_text())
    return tmp_path / "suite", tmp_path / "images", manifest


def _snapshot(*folders):
    """Every file under the folders with its bytes (a changed or new file shows)."""
    return {p: p.read_bytes() for f in folders for p in sorted(f.rglob("*")) if p.is_file()}


def _write_manifest(suite, data):
    (suite / "manifest.json").write_text(json.dumps(data))


def _whitted(capsys, *args):
    """Run the command in this process (so that monkeypatches apply): (rc, stdout, stderr)."""
    rc = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return rc, out, err


def _refused(rc, err, *words):
    assert rc == 2, err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    for w in words:
        assert w in err, err


def _no_temporaries(*folders):
    left = [p for f in folders for p in f.rglob(".whitted-*")]
    assert not left, left


# ---------------------------------------------------------------- paths stay inside the suite


def test_safe_member_accepts_a_path_inside_and_refuses_every_way_out(tmp_path):
    root = tmp_path / "suite"
    (root / "references").mkdir(parents=True)
    (tmp_path / "outside").mkdir()
    (root / "escape").symlink_to(tmp_path / "outside")
    (root / "loop").symlink_to(root / "loop")
    ok = safe_member(root, "references/a.exr", "entry")
    assert ok == (root / "references" / "a.exr").resolve()
    for rel, why in (("/etc/passwd", "absolute"), ("../x.exr", "'..'"),
                     ("references/../../x.exr", "'..'"), ("escape/a.exr", "symbolic link"),
                     ("loop/a.exr", "cannot be resolved"), ("", "non-empty"), (".", "outside"),
                     ("a\0b", "NUL"), (3, "non-empty string")):
        with pytest.raises(UserError, match="entry") as e:
            safe_member(root, rel, "entry")
        assert why in str(e.value), (rel, str(e.value))


@pytest.mark.parametrize("key, value, why", [
    ("reference_png", "ABS", "absolute"),
    ("reference_exr", "../outside.exr", "'..'"),
    ("reference_exr", "escape/tiny.exr", "symbolic link"),
    ("scene", "escape/tiny.toml", "symbolic link"),
])
def test_update_never_writes_outside_the_suite(work, capsys, key, value, why):
    suite, images, manifest = work
    outside = suite.parent / "outside"
    outside.mkdir()
    victim = outside / "victim.png"
    victim.write_bytes(b"not to be overwritten")
    shutil.copy(suite / "references" / "tiny.exr", outside / "tiny.exr")
    shutil.copy(suite / "scenes" / "tiny.toml", outside / "tiny.toml")
    (suite / "escape").symlink_to(outside)
    manifest["scenes"][0]["files"][key] = str(victim) if value == "ABS" else value
    _write_manifest(suite, manifest)
    before = _snapshot(suite.parent)
    rc, out, err = _whitted(capsys, "suite", "check", images, "--suite", suite, "--update")
    _refused(rc, err, f"scenes[0] (tiny) files.{key}", why)
    assert "updated" not in out
    assert _snapshot(suite.parent) == before      # no file written or changed anywhere
    assert not (suite.parent / "outside.exr").exists()


# ---------------------------------------------------------------- manifests of the wrong shape


def _entry_with(path, value):
    def edit(m):
        obj = m["scenes"][0]
        *keys, last = path
        for k in keys:
            obj = obj[k]
        obj[last] = value
        return m
    return edit


@pytest.mark.parametrize("edit, words", [
    (lambda m: [m], "a JSON object"),
    (lambda m: "a string", "a JSON object"),
    (lambda m: None, "a JSON object"),
    (lambda m: {"scenes": m["scenes"]}, "whitted_suite"),
    (lambda m: {**m, "whitted_suite": True}, "whitted_suite"),
    (lambda m: {**m, "scenes": "tiny"}, "scenes: expected a list"),
    (lambda m: {**m, "scenes": [3]}, "scenes[0]: expected an object"),
    (lambda m: {**m, "scenes": m["scenes"] * 2}, "appears twice"),
    (_entry_with(["name"], 5), "name: expected a string"),
    (_entry_with(["name"], "../x"), "not a scene name"),
    (_entry_with(["files"], ["scenes/tiny.toml"]), "files: expected an object"),
    (_entry_with(["files", "scene"], 3), "files scene: expected a string"),
    (_entry_with(["files", "reference_exr"], "references/tiny.png"), "does not end in .exr"),
    (_entry_with(["files", "meshes"], [None]), "files.meshes[0]"),
    (_entry_with(["size"], "8x6"), "size: expected a list"),
    (_entry_with(["size"], [8, -6]), "two integers > 0"),
    (_entry_with(["spp"], 1.5), "spp: expected an integer"),
    (_entry_with(["tests"], {"materials": "diffuse"}), "tests.materials: expected a list"),
    (_entry_with(["formulas"], [{"formula": 1, "topic": "x"}]), "formula: expected a string"),
    (_entry_with(["light_paths"], {"LE": "half"}), "light_paths.LE: expected a finite number"),
    (_entry_with(["reference"], "golden"), "reference: expected an object"),
])
def test_a_manifest_of_the_wrong_shape_is_one_line(work, capsys, edit, words):
    suite, images, manifest = work
    _write_manifest(suite, edit(manifest))
    before = _snapshot(suite.parent)
    rc, _, err = _whitted(capsys, "suite", "check", images, "--suite", suite, "--update")
    _refused(rc, err, "manifest.json", words)
    assert _snapshot(suite.parent) == before


@pytest.mark.parametrize("text, words", [
    ("[" * 100_000 + "]" * 100_000, "nested"),
    ('{"whitted_suite": 1, "scenes": [], "x": ' + "[" * (MAX_MANIFEST_NESTING + 2)
     + "]" * (MAX_MANIFEST_NESTING + 2) + "}", "nested more than"),
    ('{"whitted_suite": 1, "scenes": [], "x": NaN}', "not JSON"),
    ("\xff\xfe not text", "not JSON"),
    ("", "not JSON"),
])
def test_deep_nesting_and_non_json_manifests_are_one_line(work, capsys, text, words):
    suite, images, _ = work
    (suite / "manifest.json").write_text(text, errors="surrogateescape")
    rc, _, err = _whitted(capsys, "suite", "check", images, "--suite", suite)
    _refused(rc, err, "manifest.json", words)
    assert not (images / "whitted-check").exists()


@pytest.mark.parametrize("fifo", ["manifest.json", "references/tiny.exr"])
def test_a_fifo_in_the_suite_is_refused_without_waiting(work, fifo):
    suite, images, _ = work
    (suite / fifo).unlink()
    os.mkfifo(suite / fifo)
    # A fresh process with a deadline: reading the FIFO would block for ever.
    r = run_cli("suite", "check", images, "--suite", suite, timeout=60)
    _refused(r.returncode, r.stderr, fifo, "regular file")
    assert not (images / "whitted-check").exists()


@pytest.mark.parametrize("content, words", [
    (b"garbage, not an EXR", "tiny.exr"),   # the reader says why, in one line
    (b"v/1\x01\x02\x00\x00\x00" + b"\xff" * 64, "tiny.exr"),   # an EXR's magic, then garbage
    ("nan", "not finite"),
    ("small", "is 4x3, the scene's film 8x6"),
])
def test_a_bad_stored_reference_is_one_line_before_any_rendering(work, capsys, monkeypatch,
                                                                 content, words):
    from whitted.reference.check import suite as suite_module
    from whitted.tracer.imageio import write_exr

    suite, images, _ = work
    exr = suite / "references" / "tiny.exr"
    exr.unlink()
    if content == "nan":
        write_exr(exr, np.full((6, 8, 3), np.nan, np.float32))
    elif content == "small":
        write_exr(exr, np.zeros((3, 4, 3), np.float32))
    else:
        exr.write_bytes(content)

    def no_rendering(*a, **k):
        raise AssertionError("rendered before the suite was checked")

    monkeypatch.setattr("whitted.reference.check.judge.check_image", no_rendering)
    monkeypatch.setattr(suite_module, "find_image", no_rendering)
    rc, _, err = _whitted(capsys, "suite", "check", images, "--suite", suite)
    _refused(rc, err, "tiny", words)
    assert not (images / "whitted-check").exists()


# ---------------------------------------------------------------- all outputs or none


def test_update_into_a_suite_it_cannot_write_is_refused_before_rendering(work, capsys,
                                                                        monkeypatch):
    # Root writes anywhere, so the unwritable place is a folder where the PNG goes.
    suite, images, _ = work
    png = suite / "references" / "tiny.png"
    png.unlink()
    png.mkdir()

    def no_rendering(*a, **k):
        raise AssertionError("rendered before the targets were checked")

    monkeypatch.setattr("whitted.reference.check.judge.check_image", no_rendering)
    before = _snapshot(suite.parent)
    rc, _, err = _whitted(capsys, "suite", "check", images, "--suite", suite, "--update")
    _refused(rc, err, "tiny.png", "is a folder")
    assert _snapshot(suite.parent) == before
    assert not (images / "whitted-check").exists()


@pytest.mark.parametrize("target, fault", [
    ("whitted.tracer.imageio.write_png", OSError(errno.EROFS, "Read-only file system", "x.png")),
    ("whitted.tracer.imageio.write_png", KeyboardInterrupt()),
    ("whitted.reference.check.suite.suite_page", OSError(errno.ENOSPC, "No space left on device")),
    ("whitted.reference.check.suite.suite_page", KeyboardInterrupt()),
])
def test_suite_check_that_fails_while_writing_leaves_nothing(work, capsys, monkeypatch,
                                                             target, fault):
    suite, images, _ = work

    def fail(*a, **k):
        raise fault

    monkeypatch.setattr(target, fail)
    before = _snapshot(suite.parent)
    rc, out, err = _whitted(capsys, "suite", "check", images, "--suite", suite, "--update")
    if isinstance(fault, KeyboardInterrupt):
        assert rc == 130 and err == "whitted: interrupted\n", err
    else:
        _refused(rc, err, fault.strerror)
    assert "updated" not in out
    assert _snapshot(suite.parent) == before
    assert not (images / "whitted-check").exists()
    _no_temporaries(suite.parent)


def test_suite_update_that_passes_writes_everything_and_no_temporary(work, capsys):
    suite, images, _ = work
    rc, out, err = _whitted(capsys, "suite", "check", images, "--suite", suite, "--update")
    assert rc == 0, out + err
    assert "updated 1 reference(s)" in out
    manifest = json.loads((suite / "manifest.json").read_text())
    assert manifest["scenes"][0]["reference"]["source"] == "golden image tiny.exr"
    assert {p.name for p in (images / "whitted-check").iterdir()} == {
        "index.html", "suite.json", "results.json", "junit.xml"}
    _no_temporaries(suite.parent)


@pytest.mark.parametrize("fault", [OSError(errno.ENOSPC, "No space left on device"),
                                   KeyboardInterrupt()])
@pytest.mark.parametrize("existing", [False, True])
def test_check_that_fails_while_writing_leaves_nothing(golden, tmp_path, capsys, monkeypatch,
                                                       fault, existing):
    import whitted.reference.check.judge as check

    out = tmp_path / "out"
    if existing:
        out.mkdir()
        (out / "mine.txt").write_text("kept")
    real = check.side_by_side

    def after_the_heat_map(*a, **k):   # diff.png is written by now
        real(*a, **k)
        raise fault

    monkeypatch.setattr(check, "side_by_side", after_the_heat_map)
    rc, _, err = _whitted(capsys, "check", golden / "images" / "tiny.exr", "--scene",
                          golden / "tiny.toml", "-o", out)
    if isinstance(fault, KeyboardInterrupt):
        assert rc == 130 and err == "whitted: interrupted\n", err
    else:
        _refused(rc, err, "No space left on device", str(out))
        assert ".whitted-" not in err
    if existing:
        assert [p.name for p in out.iterdir()] == ["mine.txt"]
    else:
        assert not out.exists()
    _no_temporaries(tmp_path)


def test_check_refuses_a_folder_where_an_output_goes_before_rendering(golden, tmp_path,
                                                                     capsys):
    out = tmp_path / "out"
    (out / "check.json").mkdir(parents=True)
    rc, _, err = _whitted(capsys, "check", golden / "images" / "tiny.exr", "--scene",
                          golden / "tiny.toml", "-o", out)
    _refused(rc, err, "check.json", "is a folder")
    assert [p.name for p in out.iterdir()] == ["check.json"]
