"""Hostile Mitsuba XML scenes: every command exits 0, or 2 with one line and nothing written.

One test per class of failure of the XML reader (tracer/mitsuba_xml.py) and of
``whitted import`` (reference/renderers/mitsuba/importer.py): values that raised tracebacks,
inputs that hung (an include bomb, FIFOs), inputs that read gigabytes
(/dev/zero, includes beyond WHITTED_MAX_SCENE_BYTES), files named by the scene
(symbolic links followed, regular files only), partial output, long values
echoed in messages, and Mitsuba's own errors (corrupt ``serialized`` files,
``--verify``). The CLI runs in-process, as in tests/reference/renderers/mitsuba/test_import.py.
"""

import contextlib
import os
import signal
import struct
import zlib
from pathlib import Path

import pytest

from whitted.reference.cli import main

SCENE = """<scene version="3.0.0">
  <default name="r" value="1"/>
  <sensor type="perspective">
    <float name="fov" value="45"/>
    <transform name="to_world"><lookat origin="0, 0, 5" target="0, 0, 0" up="0, 1, 0"/></transform>
    <film type="hdrfilm"><integer name="width" value="WIDTH"/><integer name="height" value="4"/>
    </film>
    <sampler type="independent"><integer name="sample_count" value="SPP"/></sampler>
  </sensor>
  <integrator type="path"><integer name="max_depth" value="DEPTH"/></integrator>
  EXTRA
  <shape type="sphere"><float name="radius" value="$r"/>
    <bsdf type="diffuse"><rgb name="reflectance" value="0.5"/></bsdf></shape>
  <emitter type="point"><point name="position" value="0, 0, 3"/></emitter>
</scene>
"""

SERIALIZED = (Path(__file__).resolve().parents[2] / "scenes" / "mitsuba-data" / "tests"
              / "serialized" / "rectangle_normals_uv.serialized")


def scene(tmp_path, name="s.xml", **kw) -> Path:
    values = {"WIDTH": "6", "SPP": "1", "DEPTH": "3", "EXTRA": ""} | kw
    text = SCENE
    for k, v in values.items():
        text = text.replace(k, v)
    path = tmp_path / name
    path.write_text(text)
    return path


def refused(capsys, argv, *words) -> str:
    """Run ``whitted ARGV``: exit 2, one line on stderr holding ``words``, no traceback."""
    assert main([str(a) for a in argv]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("whitted: error: "), err
    assert "Traceback" not in err
    for w in words:
        assert w in err, (w, err)
    return err


@contextlib.contextmanager
def deadline(seconds: int):
    """Fail instead of hanging: SIGALRM interrupts a blocking open or read."""
    def expired(*_):
        raise TimeoutError(f"still running after {seconds} s")

    old = signal.signal(signal.SIGALRM, expired)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)


# ---------------------------------------------------------------- values: no traceback


BAD_VALUES = [
    ({"EXTRA": ""}, ["-D", "r=inf"], ["radius", "finite number", "'inf'"]),
    ({"EXTRA": ""}, ["-D", "r=nan"], ["radius", "'nan'"]),
    ({"EXTRA": ""}, ["-D", "r=1e39"], ["radius", "float32"]),
    ({"EXTRA": ""}, ["-D", "r="], ["-D", "NAME=VALUE"]),
    ({"EXTRA": ""}, ["-D", "r=abc"], ["radius", "'abc'"]),
    ({"WIDTH": "0x10"}, [], ["width", "integer", "'0x10'"]),
    ({"WIDTH": ""}, [], ["width", "integer", "nothing"]),
    ({"WIDTH": "1e3"}, [], ["width", "integer", "'1e3'"]),
    ({"DEPTH": "2.5"}, [], ["max_depth", "integer", "'2.5'"]),
    ({"SPP": "-4"}, [], ["sample_count", "at least 1"]),
    ({"EXTRA": '<default name="a" value="$a"/><shape type="sphere">'
               '<float name="radius" value="$a"/></shape>'}, [], ["$a has no value"]),
    ({"EXTRA": '<shape type="sphere"><bsdf type="diffuse"><spectrum name="reflectance" '
               'value="400:a, 500:1"/></bsdf></shape>'}, [], ["spectrum", "'a'"]),
    ({"EXTRA": '<shape type="sphere"><bsdf type="diffuse"><spectrum name="reflectance" '
               'value="400:1:2"/></bsdf></shape>'}, [], ["wavelength:value pairs"]),
    ({"EXTRA": '<shape type="sphere"><bsdf type="diffuse"><spectrum name="reflectance" '
               'value=""/></bsdf></shape>'}, [], ["spectrum", "at least two pairs"]),
]


@pytest.mark.parametrize("edit, argv, words, command", [
    (*case, command) for case in BAD_VALUES for command in ("import", "render")
    if command == "import" or not case[1]])   # -D is an option of import only
def test_bad_values_are_one_line_errors(tmp_path, capsys, edit, argv, words, command):
    """Values Python's float and int refuse (or take: inf, nan), blanks, negative counts and
    a default that refers to itself: one line naming the element, nothing written."""
    path = scene(tmp_path, **edit)
    out = tmp_path / ("s.toml" if command == "import" else "s.exr")
    refused(capsys, [command, path, "-o", out, *argv], *words)
    assert not out.exists()


def test_unknown_encoding_declaration_is_one_line(tmp_path, capsys):
    path = scene(tmp_path)
    path.write_text('<?xml version="1.0" encoding="klingon"?>\n' + path.read_text())
    refused(capsys, ["import", path, "-o", tmp_path / "s.toml"], "encoding", "klingon")
    refused(capsys, ["render", path, "-o", tmp_path / "s.exr"], "encoding")


# ---------------------------------------------------------------- hangs: includes, FIFOs


def test_include_bomb_stops_at_the_include_budget(tmp_path, capsys, monkeypatch):
    """4^15 includes, each within the 16-deep limit: refused at WHITTED_MAX_INCLUDES in all."""
    for k in range(15):
        (tmp_path / f"b{k}.xml").write_text('<scene version="3.0.0">'
                                            + f'<include filename="b{k + 1}.xml"/>' * 4
                                            + "</scene>")
    (tmp_path / "b15.xml").write_text('<scene version="3.0.0"></scene>')
    path = scene(tmp_path, EXTRA='<include filename="b0.xml"/>')
    with deadline(60):
        refused(capsys, ["render", path, "-o", tmp_path / "s.exr"],
                "1,000 includes", "WHITTED_MAX_INCLUDES")
    monkeypatch.setenv("WHITTED_MAX_INCLUDES", "20")   # 1 + 4 + 16 = 21 at two levels
    (tmp_path / "b2.xml").write_text('<scene version="3.0.0"></scene>')
    refused(capsys, ["render", path, "-o", tmp_path / "s.exr"], "20 includes")
    monkeypatch.setenv("WHITTED_MAX_INCLUDES", "21")
    assert main(["render", str(path), "-o", str(tmp_path / "s.exr")]) == 0


def test_fifos_as_scene_or_include_are_refused_without_blocking(tmp_path, capsys):
    os.mkfifo(tmp_path / "pipe.xml")
    with deadline(30):
        refused(capsys, ["render", tmp_path / "pipe.xml", "-o", tmp_path / "s.exr"], "FIFO")
        path = scene(tmp_path, EXTRA='<include filename="pipe.xml"/>')
        refused(capsys, ["import", path, "-o", tmp_path / "s.toml"], "FIFO", ":11: <include>")


# ---------------------------------------------------------------- memory: bytes read


def test_devices_are_refused_before_any_read(tmp_path, capsys):
    """/dev/zero as an include, or as the scene through a symbolic link: never read."""
    (tmp_path / "zero.xml").symlink_to("/dev/zero")
    refused(capsys, ["render", tmp_path / "zero.xml", "-o", tmp_path / "s.exr"], "a device")
    path = scene(tmp_path, EXTRA='<include filename="/dev/zero"/>')
    refused(capsys, ["import", path, "-o", tmp_path / "s.toml"], "a device")


def test_scene_bytes_limit_counts_the_scene_and_all_its_includes(tmp_path, capsys,
                                                                  monkeypatch):
    """WHITTED_MAX_SCENE_BYTES bounds the total: each file alone fits, together they do not."""
    monkeypatch.setenv("WHITTED_MAX_SCENE_BYTES", "4K")
    part = '<scene version="3.0.0"><!--' + "x" * 1500 + "--></scene>"
    (tmp_path / "part.xml").write_text(part)
    path = scene(tmp_path, EXTRA='<include filename="part.xml"/>' * 3)
    refused(capsys, ["render", path, "-o", tmp_path / "s.exr"],
            "4,096 bytes", "WHITTED_MAX_SCENE_BYTES")
    path = scene(tmp_path, EXTRA='<include filename="part.xml"/>')
    assert main(["render", str(path), "-o", str(tmp_path / "s.exr")]) == 0


# ---------------------------------------------------------------- paths named by the scene


def test_named_files_are_resolved_and_must_be_regular(tmp_path, capsys):
    """Symbolic links are followed and the target checked (a link to a FIFO is refused);
    files outside the scene's folder are allowed, as in Mitsuba."""
    os.mkfifo(tmp_path / "pipe")
    (tmp_path / "scene").mkdir()
    (tmp_path / "scene" / "mesh.obj").symlink_to(tmp_path / "pipe")
    path = scene(tmp_path / "scene", EXTRA='<shape type="obj">'
                 '<string name="filename" value="mesh.obj"/></shape>')
    with deadline(30):
        refused(capsys, ["render", path, "-o", tmp_path / "s.exr"], ":11: <shape", "mesh file",
                "FIFO")
    (tmp_path / "scene" / "mesh.obj").unlink()
    (tmp_path / "scene" / "mesh.obj").symlink_to(tmp_path)
    refused(capsys, ["render", path, "-o", tmp_path / "s.exr"], ":11: <shape", "is a folder")
    # outside the scene's folder: allowed, as Mitsuba allows it
    (tmp_path / "light.xml").write_text('<scene version="3.0.0"><emitter type="point">'
                                        '<point name="position" value="1, 1, 3"/>'
                                        "</emitter></scene>")
    path = scene(tmp_path / "scene", EXTRA='<include filename="../light.xml"/>')
    assert main(["render", str(path), "-o", str(tmp_path / "s.exr")]) == 0


# ---------------------------------------------------------------- partial output


def test_import_that_cannot_load_writes_nothing(tmp_path, capsys):
    """The TOML is loaded from memory before it is written; an earlier file is kept."""
    path = scene(tmp_path)
    out = tmp_path / "out.toml"
    refused(capsys, ["import", path, "-o", out, "-D", "r=-1"], "cannot load", "radius")
    assert not out.exists()
    out.write_text("# an earlier import\n")
    refused(capsys, ["import", path, "-o", out, "-D", "r=-1"], "nothing was written")
    assert out.read_text() == "# an earlier import\n"
    assert main(["import", str(path), "-o", str(out)]) == 0
    assert "radius = 1.0" in out.read_text()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.toml", "s.xml"]


# ---------------------------------------------------------------- messages


def test_long_values_are_cut_in_messages(tmp_path, capsys):
    path = scene(tmp_path, EXTRA='<shape type="' + "q" * 1000 + '"/><ref id="x"/>')
    err = refused(capsys, ["render", path, "-o", tmp_path / "s.exr"], "...")
    assert len(err) < 300, err
    path = scene(tmp_path)
    err = refused(capsys, ["import", path, "-o", tmp_path / "s.toml", "-D", "r=" + "9x" * 300],
                  "radius", "...")
    assert len(err) < 300, err
    err = refused(capsys, ["import", path, "-o", tmp_path / "s.toml", "-D", "=" + "x" * 600],
                  "NAME=VALUE")
    assert len(err) < 200, err


# ---------------------------------------------------------------- serialized, Mitsuba


def _serialized_scene(tmp_path, data: bytes) -> Path:
    (tmp_path / "m.serialized").write_bytes(data)
    return scene(tmp_path, EXTRA='<shape type="serialized">'
                 '<string name="filename" value="m.serialized"/></shape>')


@pytest.mark.parametrize("verify", [False, True])
def test_corrupt_serialized_files_are_one_line_errors(tmp_path, capsys, verify):
    """Garbage, a PLY named .serialized, a header claiming 10^12 vertices (Mitsuba would
    allocate them), a truncated file (Mitsuba's RuntimeError): one line, nothing left."""
    extra = ["--verify"] if verify else []
    out = tmp_path / "s.toml"
    header = struct.pack("<HH", 0x041C, 4)
    cases = [
        (bytes(range(256)) * 2, "not a Mitsuba serialized mesh"),
        (b"ply\nformat ascii 1.0\nend_header\n", "not a Mitsuba serialized mesh"),
        (header + zlib.compress(struct.pack("<I", 0x1000) + b"m\0"
                                + struct.pack("<QQ", 10 ** 12, 10 ** 12)), "10^12"),
        (SERIALIZED.read_bytes()[:60], "Mitsuba cannot read"),
    ]
    for data, words in cases:
        path = _serialized_scene(tmp_path, data)
        words = "1,000,000,000,000 vertices" if words == "10^12" else words
        refused(capsys, ["import", path, "-o", out, *extra], ":11: <shape", words)
        assert not out.exists() and not (tmp_path / "meshes").exists()


def test_verify_turns_mitsubas_refusal_into_one_line(tmp_path, capsys):
    """A property the reader ignores but Mitsuba refuses: --verify says so in one line."""
    path = scene(tmp_path, EXTRA='<shape type="sphere"><float name="no_such_property" '
                 'value="1"/></shape>')
    out = tmp_path / "s.toml"
    refused(capsys, ["import", path, "-o", out, "--verify"], "Mitsuba cannot load it")
    assert not out.exists()


def test_failed_import_removes_the_meshes_it_converted(tmp_path, capsys):
    path = scene(tmp_path, EXTRA=f'<shape type="serialized"><string name="filename" '
                                 f'value="{SERIALIZED}"/></shape>')
    refused(capsys, ["import", path, "-o", tmp_path / "s.toml", "-D", "r=-1"], "radius")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.xml"]
    assert main(["import", str(path), "-o", str(tmp_path / "s.toml")]) == 0
    assert (tmp_path / "meshes" / "s_rectangle_normals_uv_0.obj").is_file()
