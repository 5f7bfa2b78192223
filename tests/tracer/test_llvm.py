"""Finding a libLLVM for Dr.Jit: a user never sees an LLVM abort, only one line of advice.

Each command-line case runs in a subprocess, since a bad libLLVM would abort
the whole interpreter.
"""

import glob
import os

import pytest
from conftest import MINIMAL, run_cli, write_scene

from whitted.tracer import llvm


@pytest.mark.parametrize("name,major", [
    ("/usr/lib/x86_64-linux-gnu/libLLVM-15.so.1", 15),
    ("/usr/lib/llvm-19/lib/libLLVM-19.so", 19),
    ("/env/lib/libLLVM.so.23.1", 23),
    ("/x/libLLVM.so.19.1", 19),
    ("/opt/homebrew/opt/llvm/lib/libLLVM.21.dylib", 21),
])
def test_llvm_major_is_read_from_the_file_name(name, major):
    assert llvm.llvm_major(name) == major


def test_known_bad_versions_are_never_chosen(tmp_path):
    for v in (14, 15, 16):
        (tmp_path / f"libLLVM-{v}.so.1").write_bytes(b"\x7fELF not really")
    with pytest.raises(llvm.LLVMUnavailable) as e:
        llvm.find_libllvm({"WHITTED_LLVM_SEARCH": str(tmp_path)})
    msg = str(e.value)
    assert "found only LLVM 14, LLVM 15, LLVM 16" in msg and "karellen-llvm-core" in msg
    assert "\n" not in msg


def test_a_good_version_is_preferred_to_a_bad_one(tmp_path, monkeypatch):
    (tmp_path / "libLLVM-15.so.1").write_bytes(b"x")
    (tmp_path / "libLLVM-19.so.1").write_bytes(b"x")
    (tmp_path / "libLLVM-18.so.1").write_bytes(b"x")
    probed = []
    monkeypatch.setattr(llvm, "_probe", lambda p: probed.append(p) or True)
    c = llvm.find_libllvm({"WHITTED_LLVM_SEARCH": str(tmp_path)})
    assert c.major == 19
    assert not any("libLLVM-15" in p for p in probed)  # a known-bad version is never loaded


def test_explicit_path_of_a_bad_version_is_refused_without_loading(tmp_path):
    fake = tmp_path / "libLLVM-15.so.1"
    fake.write_bytes(b"x")
    with pytest.raises(llvm.LLVMUnavailable, match="LLVM 15, which aborts drjit"):
        llvm.find_libllvm({"DRJIT_LIBLLVM_PATH": str(fake)})


def test_the_packaged_libllvm_is_found():
    c = llvm.find_libllvm({})
    assert c.major is not None and c.major >= llvm.KNOWN_GOOD_FROM


def _assert_one_line_exit_2(r, *words):
    assert r.returncode == 2, (r.returncode, r.stderr)
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1, r.stderr
    assert "LLVM ERROR" not in r.stderr and "Traceback" not in r.stderr
    for w in words:
        assert w in lines[0], lines[0]


def test_cli_without_any_usable_libllvm_says_what_to_install(tmp_path):
    scene = write_scene(tmp_path, MINIMAL)
    empty = tmp_path / "empty"
    empty.mkdir()
    env = {"WHITTED_LLVM_SEARCH": str(empty), "DRJIT_LIBLLVM_PATH": ""}
    r = run_cli("render", scene, "-o", tmp_path / "x.exr", "--backend", "llvm", env=env)
    _assert_one_line_exit_2(r, "no libLLVM", "pip install karellen-llvm-core")
    assert not (tmp_path / "x.exr").exists()


def test_cli_with_only_a_known_bad_libllvm_refuses_it(tmp_path):
    scene = write_scene(tmp_path, MINIMAL)
    d = tmp_path / "lib"
    d.mkdir()
    (d / "libLLVM-15.so.1").write_bytes(b"x")
    env = {"WHITTED_LLVM_SEARCH": str(d), "DRJIT_LIBLLVM_PATH": ""}
    r = run_cli("render", scene, "-o", tmp_path / "x.exr", "--backend", "llvm", env=env)
    _assert_one_line_exit_2(r, "found only LLVM 15")


SYSTEM_BAD = sorted(p for v in (15, 16) for p in glob.glob(f"/usr/lib/*/libLLVM-{v}.so*")
                    if os.path.isfile(p))


@pytest.mark.skipif(not SYSTEM_BAD, reason="no system libLLVM 15 or 16 on this machine")
def test_cli_pointed_at_a_real_libllvm_15_does_not_abort(tmp_path):
    # Loaded by Dr.Jit, this library aborts the process inside dr.minimum.
    scene = write_scene(tmp_path, MINIMAL)
    r = run_cli("render", scene, "-o", tmp_path / "x.exr", "--backend", "llvm",
                env={"DRJIT_LIBLLVM_PATH": SYSTEM_BAD[0]})
    _assert_one_line_exit_2(r, "DRJIT_LIBLLVM_PATH", "aborts drjit")


def test_cli_with_an_unreadable_explicit_library_is_refused(tmp_path):
    scene = write_scene(tmp_path, MINIMAL)
    junk = tmp_path / "libLLVM.so"
    junk.write_bytes(b"not a library")
    r = run_cli("render", scene, "-o", tmp_path / "x.exr", "--backend", "llvm",
                env={"DRJIT_LIBLLVM_PATH": str(junk), "XDG_CACHE_HOME": str(tmp_path)})
    _assert_one_line_exit_2(r, "does not work with drjit")


def test_cli_renders_with_a_good_library_found_by_search(tmp_path):
    good = llvm.find_libllvm({})
    scene = write_scene(tmp_path, MINIMAL)
    r = run_cli("render", scene, "-o", tmp_path / "x.exr", "--backend", "llvm",
                env={"WHITTED_LLVM_SEARCH": os.path.dirname(good.path), "DRJIT_LIBLLVM_PATH": ""})
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "x.exr").exists()


def test_cli_skips_a_good_version_that_does_not_load(tmp_path):
    # A link to the packaged libLLVM from another folder loses its $ORIGIN-relative
    # libc++: the version is fine, the library does not load. Probed, never used.
    good = llvm.find_libllvm({})
    d = tmp_path / "lib"
    d.mkdir()
    os.symlink(good.path, d / os.path.basename(good.path))
    if glob.glob(os.path.join(os.path.dirname(good.path), "**", "libc++.so.1"), recursive=True):
        scene = write_scene(tmp_path, MINIMAL)
        r = run_cli("render", scene, "-o", tmp_path / "x.exr", "--backend", "llvm",
                    env={"WHITTED_LLVM_SEARCH": str(d), "DRJIT_LIBLLVM_PATH": "",
                         "XDG_CACHE_HOME": str(tmp_path / "cache")})
        _assert_one_line_exit_2(r, "does not load")
    else:
        pytest.skip("the packaged libLLVM does not depend on a neighbouring libc++")


@pytest.mark.skipif(not SYSTEM_BAD, reason="no system libLLVM 15 or 16 on this machine")
def test_drjit_imported_first_with_a_bad_library_is_refused_not_aborted(tmp_path):
    # A program that imports drjit before tracer gets whatever libLLVM the system
    # offers; the backend must refuse it with advice instead of aborting later.
    import subprocess
    import sys

    code = ("import drjit\nimport whitted.tracer\nfrom whitted.tracer import backend, llvm\n"
            "try:\n    backend.use('llvm')\nexcept llvm.LLVMUnavailable as e:\n"
            "    print(e)\n    raise SystemExit(3)\n")
    env = dict(os.environ, DRJIT_LIBLLVM_PATH=SYSTEM_BAD[0])
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env)
    assert r.returncode == 3, r.stdout + r.stderr
    assert "imported before tracer" in r.stdout and "LLVM ERROR" not in r.stderr


@pytest.fixture
def spawned(tmp_path, monkeypatch):
    """A search of the packaged libLLVM's folder, an empty probe cache, no child started
    ahead, and the paths of the probe children started (real ones): (env, paths)."""
    good = llvm.find_libllvm({})
    env = {"WHITTED_LLVM_SEARCH": os.path.dirname(good.path)}
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    paths = []
    spawn = llvm._spawn
    monkeypatch.setattr(llvm, "_spawn", lambda p: paths.append(p) or spawn(p))
    monkeypatch.setattr(llvm, "_running", {})
    return env, paths


def test_a_probe_started_ahead_is_waited_for_not_run_again(spawned):
    # A child started ahead is the one configure() waits for: one child a library, and its
    # answer cached as a probe run by configure() caches it.
    env, spawned = spawned
    first = llvm._ranked(env)[0].path   # the folder may hold links to it too
    assert llvm._start_first_probe(env) == first
    assert llvm._start_first_probe(env) is None   # already running: not started twice
    assert llvm.find_libllvm(env).path == first
    assert spawned == [first] and llvm._running == {}
    assert llvm._read_probe_cache() == {llvm._probe_key(first): True}
    # Answered from the cache now: nothing to start ahead.
    assert llvm._start_first_probe(env) is None and spawned == [first]


def test_a_probe_started_ahead_for_a_library_that_fails_rejects_it(tmp_path, monkeypatch):
    junk = tmp_path / "lib" / "libLLVM-19.so.1"
    junk.parent.mkdir()
    junk.write_bytes(b"not a library")
    env = {"WHITTED_LLVM_SEARCH": str(junk.parent)}
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    monkeypatch.setattr(llvm, "_running", {})
    assert llvm._start_first_probe(env) == str(junk)
    with pytest.raises(llvm.LLVMUnavailable, match="does not load"):
        llvm.find_libllvm(env)
    assert llvm._running == {}


_IMPORT_THEN_DRJIT = """
import os, sys
import whitted.tracer
from whitted.tracer import llvm
hooked = [f for f in sys.meta_path if isinstance(f, llvm._ConfigureFirst)]
print("at import:", len(hooked), len(llvm._running), "DRJIT_LIBLLVM_PATH" in os.environ)
import drjit as dr, drjit.llvm as m
print("after drjit:", len([f for f in sys.meta_path if isinstance(f, llvm._ConfigureFirst)]),
      len(llvm._running))
x = m.Float([1, 2]) + 1
dr.eval(x)
print("loaded the chosen:", os.path.realpath(llvm.loaded_libllvm())
      == os.path.realpath(os.environ["DRJIT_LIBLLVM_PATH"]))
"""


def test_importing_tracer_starts_the_probe_and_drjit_waits_for_its_answer(tmp_path):
    # A fresh cache: importing tracer starts the probe's child and returns; the first
    # import of drjit finishes the choice (DRJIT_LIBLLVM_PATH set) before Dr.Jit loads.
    # With the answer cached, the choice is made at import, as before.
    import subprocess
    import sys

    env = {k: v for k, v in os.environ.items() if k != "DRJIT_LIBLLVM_PATH"}
    env["XDG_CACHE_HOME"] = str(tmp_path)
    runs = [subprocess.run([sys.executable, "-c", _IMPORT_THEN_DRJIT], env=env,
                           capture_output=True, text=True) for _ in range(2)]
    for r in runs:
        assert r.returncode == 0, r.stderr
    cold, warm = (r.stdout.splitlines() for r in runs)
    assert cold == ["at import: 1 1 False", "after drjit: 0 0", "loaded the chosen: True"]
    assert warm == ["at import: 0 0 True", "after drjit: 0 0", "loaded the chosen: True"]


def test_a_forked_process_probes_for_itself(spawned, monkeypatch):
    # A process forked after the import cannot wait for its parent's child (waitpid
    # answers ECHILD, which subprocess reads as success): it starts its own probe.
    env, spawned = spawned
    first = llvm._start_first_probe(env)
    parents_child = llvm._running[first][1]
    pid = os.getpid()
    monkeypatch.setattr(llvm.os, "getpid", lambda: pid + 1)   # as in a forked process
    assert llvm.find_libllvm(env).path == first
    assert spawned == [first, first]
    assert parents_child.wait(timeout=llvm.PROBE_TIMEOUT) == 0
