"""Caches hold data, never code (issue 30; tracer/cache.py).

The laws: nothing but data entries is read from the cache folder; its folders
are made 0700 and its files 0600 whatever the umask; a folder another user
owns, or that others may write, or that is a symbolic link, is not used; an
entry that is not what its reader expects (another shape or type, an .npz
named .npy, a header claiming 120 GB, JSON of another type) is computed again
and replaced, never fatal.
"""

from __future__ import annotations

import json
import os
import stat
import subprocess
import sys
from types import SimpleNamespace

import numpy as np
import pytest
from conftest import ROOT, SCENES

from whitted.reference.check import suspects
from whitted.tracer import llvm

SIZE = (4, 3)


def _mode(path) -> int:
    return stat.S_IMODE(os.lstat(path).st_mode)


@pytest.fixture
def home(tmp_path, monkeypatch):
    """whitted's cache folder in tmp_path ($XDG_CACHE_HOME/whitted), not made yet."""
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    monkeypatch.delenv("WHITTED_SUSPECTS_CACHE", raising=False)
    return tmp_path / "xdg" / "whitted"


@pytest.fixture
def probes(monkeypatch):
    """The libLLVM probe's child process replaced: the paths it was run for, and its answer."""
    runs = SimpleNamespace(paths=[], ok=True)

    def spawn(path):
        runs.paths.append(path)
        return SimpleNamespace(wait=lambda timeout: 0 if runs.ok else 1)

    monkeypatch.setattr(llvm, "_spawn", spawn)
    return runs


@pytest.fixture(scope="module")
def scene():
    from whitted.tracer import load_scene

    return load_scene(SCENES / "sphere_point.toml").with_overrides(size=SIZE)


def _entry(scene, folder):
    """The path of the scene's image as written in the suspects' cache under ``folder``."""
    return folder / suspects._scene_key(scene, 0) / "as-written.npy"


# ----------------------------------------------------------------- no code is read


def test_a_render_opens_nothing_in_the_cache_folder_but_the_probe_answers(tmp_path):
    # Every file opened under $XDG_CACHE_HOME, in a whole `whitted render` process,
    # recorded by an audit hook: only the libLLVM probe's JSON (and its temporary file).
    # mesh_knot runs the BVH's symbolic loops, whose code an earlier version kept there.
    xdg = tmp_path / "xdg"
    code = ("import sys\nopened = []\n"
            f"root = {str(xdg)!r}\n"
            "def hook(event, args):\n"
            "    if event == 'open' and isinstance(args[0], (str, bytes)) and "
            "str(args[0]).startswith(root):\n"
            "        opened.append(str(args[0]))\n"
            "sys.addaudithook(hook)\n"
            "from whitted.reference.cli import main\n"
            "try:\n    main(sys.argv[1:])\nfinally:\n    print('OPENED', opened)\n")
    env = dict(os.environ, XDG_CACHE_HOME=str(xdg))
    r = subprocess.run([sys.executable, "-c", code, "render", str(SCENES / "mesh_knot.toml"),
                        "--size", "4x3", "--spp", "1", "-o", str(tmp_path / "x.exr"),
                        "--backend", "llvm"],
                       capture_output=True, text=True, env=env, cwd=ROOT, timeout=300)
    assert r.returncode == 0, r.stdout + r.stderr
    opened = eval(r.stdout.rsplit("OPENED ", 1)[1])
    names = {os.path.basename(p) for p in opened}
    assert all(n == "llvm-probe.json" or n.startswith(".llvm-probe.json.") for n in names), \
        opened
    assert not (xdg / "whitted" / "syntax").exists()


# ------------------------------------------------------------- folders and modes


def test_cache_folders_are_0700_and_files_0600_even_under_umask_002(home, probes, scene):
    old = os.umask(0o002)
    try:
        assert llvm._probe("/nowhere/libLLVM-19.so") is True
        img, hit = suspects.mutated_image(scene, None)
    finally:
        os.umask(old)
    assert not hit and img.shape == (3, 4, 3)
    entry = _entry(scene, home / "suspects")
    for folder in (home.parent, home, home / "suspects", entry.parent):
        assert _mode(folder) == 0o700, folder
    for f in (home / "llvm-probe.json", entry):
        assert _mode(f) == 0o600, f
    assert suspects.mutated_image(scene, None)[1]     # and it is used again


def _plant(home, scene):
    """A probe answer and an image of the right shape, neither of which is the truth."""
    home.mkdir(parents=True)
    (home / "llvm-probe.json").write_text(json.dumps(
        {f"{os.path.abspath('/nowhere/libLLVM-19.so')}:0": False}))
    entry = _entry(scene, home / "suspects")
    entry.parent.mkdir(parents=True)
    np.save(entry, np.full((3, 4, 3), 7, np.float32))
    return entry


@pytest.mark.parametrize("how", ["another owner", "mode 0777", "group-writable", "a link"])
def test_a_cache_folder_someone_else_could_write_is_not_used(home, probes, scene, how,
                                                             tmp_path, capsys):
    if how == "a link":
        real = tmp_path / "elsewhere"
        entry = _plant(real, scene)
        home.parent.mkdir(exist_ok=True)
        os.symlink(real, home)
    else:
        entry = _plant(home, scene)
        if how == "another owner":
            for p in (home, *home.rglob("*")):
                os.chown(p, 1, 1)
        else:
            os.chmod(home, 0o777 if how == "mode 0777" else 0o770)
    before = entry.read_bytes()
    assert llvm._probe("/nowhere/libLLVM-19.so") is True          # probed afresh
    assert probes.paths == ["/nowhere/libLLVM-19.so"]
    img, hit = suspects.mutated_image(scene, None)
    assert not hit and not (img == 7).all()                       # rendered afresh
    assert entry.read_bytes() == before                           # and nothing written there
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "not used" in err[0] and str(home) in err[0], err


def test_an_entry_owned_by_another_user_or_a_link_is_a_miss(home, probes, scene, tmp_path):
    entry = _plant(home, scene)
    os.chown(entry, 1, 1)
    assert not suspects.mutated_image(scene, None)[1]
    other = tmp_path / "other.npy"
    np.save(other, np.full((3, 4, 3), 7, np.float32))
    entry.unlink()
    os.symlink(other, entry)
    img, hit = suspects.mutated_image(scene, None)
    assert not hit and not (img == 7).all()
    assert not entry.is_symlink() and suspects.mutated_image(scene, None)[1]


# ------------------------------------------------------------- tampered entries


def _huge_header(path):
    # A valid .npy header claiming 100000 x 100000 x 3 float32 (120 GB), and no data.
    from numpy.lib import format as npy

    with open(path, "wb") as f:
        npy.write_array_header_1_0(f, {"descr": "<f4", "fortran_order": False,
                                       "shape": (100000, 100000, 3)})


TAMPERED = {
    "wrong shape": lambda p: np.save(p, np.zeros((5, 4, 3), np.float32)),
    "wrong dtype": lambda p: np.save(p, np.zeros((3, 4, 3), np.float64)),
    "npz named npy": lambda p: p.write_bytes(_npz(np.zeros((3, 4, 3), np.float32))),
    "pickled objects": lambda p: np.save(p, np.array([{"a": 1}], dtype=object)),
    "huge header": _huge_header,
    "short data": lambda p: p.write_bytes(_npy(np.zeros((3, 4, 3), np.float32))[:-8]),
    "not finite": lambda p: np.save(p, np.full((3, 4, 3), np.nan, np.float32)),
    "not npy": lambda p: p.write_bytes(b"hello"),
    "a folder": lambda p: p.mkdir(),
}


def _npy(a) -> bytes:
    import io

    buf = io.BytesIO()
    np.save(buf, a)
    return buf.getvalue()


def _npz(a) -> bytes:
    import io

    buf = io.BytesIO()
    np.savez(buf, image=a)
    return buf.getvalue()


@pytest.mark.parametrize("kind", list(TAMPERED))
def test_a_tampered_image_is_rendered_again_and_replaced(home, scene, kind):
    entry = _entry(scene, home / "suspects")
    entry.parent.mkdir(parents=True)
    TAMPERED[kind](entry)
    img, hit = suspects.mutated_image(scene, None)
    assert not hit and img.shape == (3, 4, 3) and img.dtype == np.float32
    assert np.isfinite(img).all()
    if kind != "a folder":                                  # a folder is left, not removed
        again, hit = suspects.mutated_image(scene, None)
        assert hit and np.array_equal(again, img)


KEY = f"{os.path.abspath('/nowhere/libLLVM-19.so')}:0"


@pytest.mark.parametrize("text", [
    "[1, 2]", '"a string"', "5", "null", "{", json.dumps({KEY: "no"}), json.dumps({KEY: 0}),
    json.dumps({KEY: [False]}), "[" * 100000, "\xff\xfe",
])
def test_a_probe_file_of_the_wrong_type_is_probed_again_and_replaced(home, probes, text):
    home.mkdir(parents=True)
    (home / "llvm-probe.json").write_bytes(text.encode("latin-1"))
    probes.ok = False
    assert llvm._probe("/nowhere/libLLVM-19.so") is False
    assert probes.paths == ["/nowhere/libLLVM-19.so"]
    assert json.loads((home / "llvm-probe.json").read_text()) == {KEY: False}
    assert llvm._probe("/nowhere/libLLVM-19.so") is False
    assert len(probes.paths) == 1                           # the answer is cached now
