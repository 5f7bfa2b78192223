"""Image files a user hands over: refused in one line before they can hang, flood or exhaust.

Every image the project reads (a scene's bitmap texture or environment map,
``whitted check``'s input) is checked by tracer/imageheader.py first: a regular
file, a known header, and a size from that header whose reading fits
WHITTED_MAX_MEMORY, before any decoder runs; a C library's own messages never
reach the terminal.
"""

import contextlib
import functools
import io
import os
import signal
import struct
import zlib

import numpy as np
import pytest
from conftest import run_cli

from whitted.tracer.errors import SceneError, UserError

#: 100000 x 100000 RGB: about 3 TB to decode, in a file of about a kilobyte.
HUGE = 100_000

SCENE = """
[film]
width = 8
height = 6
spp = 1
max_depth = 2

[camera]
origin = [0, 0, 5]
target = [0, 0, 0]

[materials.wall]
type = "diffuse"
reflectance = {texture}

[[shapes]]
type = "sphere"
material = "wall"

[[lights]]
{light}
"""

POINT = 'type = "point"\nposition = [0, 0, 5]\nintensity = 1'


def _scene(tmp_path, image: str, as_envmap: bool = False):
    text = SCENE.format(
        texture=0.5 if as_envmap else f'{{ bitmap = {{ filename = "{image}" }} }}',
        light=f'type = "envmap"\nfilename = "{image}"' if as_envmap else POINT)
    p = tmp_path / "scene.toml"
    p.write_text(text)
    return p


def _chunk(kind: bytes, data: bytes) -> bytes:
    return (struct.pack(">I", len(data)) + kind + data
            + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF))


def bomb_png(path, width=HUGE, height=HUGE) -> None:
    """A PNG whose IHDR claims ``width`` x ``height`` RGB pixels, with a few rows of data:
    a decompression bomb's header (ISO/IEC 15948, 11.2.2)."""
    ihdr = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    rows = zlib.compress(b"\0" * (1 << 16), 9)
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", ihdr) + _chunk(b"IDAT", rows)
                     + _chunk(b"IEND", b""))


@functools.cache
def exr_bytes(width=8, height=6) -> bytes:
    """A valid float32 RGB OpenEXR file's bytes (ZIP-compressed scanlines, as written)."""
    import tempfile

    from whitted.tracer.imageio import write_exr

    image = np.random.default_rng(1).random((height, width, 3)).astype(np.float32)
    with tempfile.TemporaryDirectory() as d:
        write_exr(os.path.join(d, "x.exr"), image)
        with open(os.path.join(d, "x.exr"), "rb") as f:
            return f.read()


def bomb_exr(path) -> None:
    """A valid 8 x 6 OpenEXR file whose dataWindow is made to claim HUGE x HUGE pixels."""
    data = bytearray(exr_bytes())
    at = data.index(b"dataWindow\0box2i\0") + len(b"dataWindow\0box2i\0") + 4
    data[at:at + 16] = struct.pack("<4i", 0, 0, HUGE - 1, HUGE - 1)
    path.write_bytes(bytes(data))


def cli(*args) -> tuple[int, str, str]:
    """``whitted ARGS`` in this process: (exit status, stdout, stderr)."""
    from whitted.reference.cli import main

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        rc = main([str(a) for a in args])
    return rc, out.getvalue(), err.getvalue()


def refused(rc: int, err: str, *words: str) -> bool:
    """Exit 2 with exactly one line on stderr that holds every word."""
    lines = err.strip("\n").split("\n")
    return rc == 2 and len(lines) == 1 and all(w in err for w in words)


@pytest.fixture
def no_decoders(monkeypatch):
    """Every image decoder replaced by one that fails the test if it is ever called."""
    import OpenEXR
    from PIL import Image

    import whitted.reference.check.images as user_image

    def called(*a, **k):
        raise AssertionError("a decoder ran on an image that should have been refused")

    exr_bytes()  # written (by OpenEXR) before its reader is taken away

    monkeypatch.setattr(Image, "open", called)
    monkeypatch.setattr(OpenEXR, "File", called)
    monkeypatch.setattr(user_image, "_bitmap_array", called)


@contextlib.contextmanager
def deadline(seconds: int):
    """Fail, rather than hang, when the block blocks (a FIFO opened with no writer)."""
    def expired(*_):
        raise TimeoutError(f"still blocked after {seconds} s")

    old = signal.signal(signal.SIGALRM, expired)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)


# ------------------------------------------------------------------ decompression bombs


@pytest.mark.parametrize("as_envmap", [False, True], ids=["bitmap", "envmap"])
def test_a_png_texture_claiming_a_huge_size_is_refused_before_decoding(tmp_path, no_decoders,
                                                                      as_envmap):
    from whitted.tracer import load_scene

    bomb_png(tmp_path / "bomb.png")
    assert (tmp_path / "bomb.png").stat().st_size < 4096
    scene = _scene(tmp_path, "bomb.png", as_envmap)
    with pytest.raises(SceneError, match="WHITTED_MAX_MEMORY") as e:
        load_scene(scene)
    assert "100,000 x 100,000 PNG" in str(e.value) and "\n" not in str(e.value)
    rc, _, err = cli("render", scene, "-o", tmp_path / "out.exr")
    assert refused(rc, err, "bomb.png", "WHITTED_MAX_MEMORY"), err
    assert not (tmp_path / "out.exr").exists()


def test_an_exr_texture_whose_data_window_claims_a_huge_size_is_refused_before_decoding(
        tmp_path, no_decoders):
    from whitted.tracer import load_scene

    bomb_exr(tmp_path / "bomb.exr")
    with pytest.raises(SceneError, match="WHITTED_MAX_MEMORY"):
        load_scene(_scene(tmp_path, "bomb.exr"))


def _huge_headers(tmp_path):
    bomb_png(tmp_path / "bomb.png")
    bomb_exr(tmp_path / "bomb.exr")
    (tmp_path / "bomb.pfm").write_bytes(b"PF\n%d %d\n-1\n" % (HUGE, HUGE) + bytes(64))
    (tmp_path / "bomb.hdr").write_bytes(b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n"
                                        b"-Y %d +X %d\n" % (HUGE, HUGE) + bytes(64))
    (tmp_path / "bomb.ppm").write_bytes(b"P6\n%d %d\n255\n" % (HUGE, HUGE) + bytes(64))
    return ["bomb.png", "bomb.exr", "bomb.pfm", "bomb.hdr", "bomb.ppm"]


def test_check_refuses_images_whose_headers_claim_a_huge_size_before_decoding(tmp_path,
                                                                            no_decoders):
    from whitted.reference.check.images import read_user_image

    for name in _huge_headers(tmp_path):
        with pytest.raises(UserError, match="WHITTED_MAX_MEMORY") as e:
            read_user_image(tmp_path / name)
        assert "100,000 x 100,000" in str(e.value), name
    rc, _, err = cli("check", tmp_path / "bomb.png", "--scene", "sphere_point",
                     "-o", tmp_path / "out")
    assert refused(rc, err, "bomb.png", "WHITTED_MAX_MEMORY"), err
    assert not (tmp_path / "out").exists()


def test_the_image_limit_follows_whitted_max_memory(tmp_path, monkeypatch):
    from whitted.reference.check.images import read_user_image
    from whitted.tracer.imageio import write_png

    write_png(tmp_path / "a.png", np.full((60, 80, 3), 0.5, np.float32))
    monkeypatch.setenv("WHITTED_MAX_MEMORY", "64K")
    with pytest.raises(UserError, match="WHITTED_MAX_MEMORY"):
        read_user_image(tmp_path / "a.png")
    monkeypatch.setenv("WHITTED_MAX_MEMORY", "64M")
    assert read_user_image(tmp_path / "a.png").size == (80, 60)


# ------------------------------------------------------------------ FIFOs and devices


def test_a_fifo_as_checks_image_is_refused_at_once(tmp_path):
    os.mkfifo(tmp_path / "pipe.png")
    with deadline(10):
        rc, _, err = cli("check", tmp_path / "pipe.png", "--scene", "sphere_point",
                         "-o", tmp_path / "out")
    assert refused(rc, err, "pipe.png", "FIFO"), err
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("as_envmap", [False, True], ids=["bitmap", "envmap"])
def test_a_fifo_or_a_device_as_a_texture_is_refused_at_once(tmp_path, as_envmap):
    from whitted.tracer import load_scene

    os.mkfifo(tmp_path / "pipe.exr")
    os.symlink("/dev/zero", tmp_path / "zero.png")
    with deadline(10):
        with pytest.raises(SceneError, match="FIFO"):
            load_scene(_scene(tmp_path, "pipe.exr", as_envmap))
        with pytest.raises(SceneError, match="device"):
            load_scene(_scene(tmp_path, "zero.png", as_envmap))


# ------------------------------------------------------------------ C libraries' messages


def _corrupt_exr(path) -> None:
    """An OpenEXR file cut short: OpenEXR prints a line of its own on stderr reading it."""
    data = exr_bytes(32, 24)
    path.write_bytes(data[:len(data) - 40])


def test_a_corrupt_exr_texture_prints_one_line_and_nothing_of_openexr(tmp_path, capfd):
    _corrupt_exr(tmp_path / "cut.exr")
    rc, _, err = cli("render", _scene(tmp_path, "cut.exr"), "-o", tmp_path / "out.exr")
    library = capfd.readouterr().err  # what reached file descriptor 2 itself
    assert refused(rc, err, "cut.exr", "unreadable OpenEXR"), err
    assert library == "", library
    assert not (tmp_path / "out.exr").exists()


def test_a_corrupt_exr_given_to_check_gives_exactly_one_stderr_line(tmp_path):
    _corrupt_exr(tmp_path / "cut.exr")
    r = run_cli("check", tmp_path / "cut.exr", "--scene", "sphere_point", "-o",
                tmp_path / "out", timeout=120)
    assert r.returncode == 2, r.stderr
    assert r.stderr.count("\n") == 1 and "unreadable OpenEXR" in r.stderr, r.stderr
    assert "Traceback" not in r.stderr
    assert not (tmp_path / "out").exists()
