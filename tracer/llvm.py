"""Find a libLLVM that Dr.Jit 1.5's LLVM backend can use, before Dr.Jit loads.

Dr.Jit reads ``DRJIT_LIBLLVM_PATH`` once, when it is first imported, and
otherwise loads whatever ``libLLVM.so`` the system offers. With drjit 1.5.0,
LLVM 14 is refused and LLVM 15 and 16 abort the whole process inside
``dr.minimum`` ("LLVM ERROR: Cannot select ... fminimum"); 19 and 23 work.
Debian 12 ships 14 and 15, so the default choice is fatal there. This module
picks a library that works and sets the variable, or explains in one line
what to install. It must not import drjit itself.

Order of preference:

1. ``DRJIT_LIBLLVM_PATH`` set by the user (checked, never silently replaced);
2. the copy that the ``karellen-llvm-core`` wheel installs into the
   environment (a declared dependency on Linux);
3. a system library (``/usr/lib/llvm-*/lib``, ``/usr/lib/<triplet>``, ...),
   versions known to work (19 and newer) first, newest first.

Versions known to fail are refused by their file name, without loading them;
any other candidate is loaded once in a child process before it is chosen
(and the answer cached in ``~/.cache/whitted/llvm-probe.json``, a file used
only as :mod:`tracer.cache` allows), because a library of a good version can
still fail to load, and an LLVM abort kills the process.

``WHITTED_LLVM_SEARCH`` (directories separated by ``os.pathsep``) replaces
steps 2 and 3 with a search of those directories only; packagers and the
tests use it.
"""

from __future__ import annotations

import glob
import json
import os
import re
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

from whitted.tracer import cache

#: Majors measured to work with drjit 1.5.0.
KNOWN_GOOD_FROM = 19
#: Majors measured to fail: 14 is refused, 15 and 16 abort in ``dr.minimum``.
KNOWN_BAD = {14: "is refused by drjit 1.5 (too old)",
             15: "aborts drjit 1.5 inside dr.minimum",
             16: "aborts drjit 1.5 inside dr.minimum"}

INSTALL_HINT = ("pip install karellen-llvm-core  (or on Debian/Ubuntu: "
                "apt-get install libllvm19)")

_SYSTEM_GLOBS = (
    "/usr/lib/llvm-*/lib/libLLVM*.so*",
    "/usr/lib/*-linux-gnu/libLLVM*.so*",
    "/usr/lib64/libLLVM*.so*",
    "/usr/lib/libLLVM*.so*",
    "/usr/local/lib/libLLVM*.so*",
    "/opt/homebrew/opt/llvm/lib/libLLVM*.dylib",
    "/usr/local/opt/llvm/lib/libLLVM*.dylib",
)


class LLVMUnavailable(RuntimeError):
    """No libLLVM that works with drjit 1.5 was found; the message is one line."""


@dataclass(frozen=True)
class Candidate:
    path: str
    major: int | None  # None: the version could not be read from the name
    source: str        # "DRJIT_LIBLLVM_PATH", "karellen-llvm-core", "system", ...


def llvm_major(path: str) -> int | None:
    """The LLVM major version encoded in a library's file name, or None.

    Reads names such as ``libLLVM-15.so.1``, ``libLLVM.so.23.1``,
    ``libLLVM-19.so`` or ``libLLVM.so.19.1``; symbolic links are followed
    first, so an unversioned ``libLLVM.so`` resolves to its target.

    >>> llvm_major("/usr/lib/x86_64-linux-gnu/libLLVM-15.so.1")
    15
    >>> llvm_major("/env/lib/libLLVM.so.23.1")
    23
    """
    names = [os.path.basename(path)]
    try:
        names.append(os.path.basename(os.path.realpath(path)))
    except OSError:
        pass
    for name in names:
        m = re.match(r"libLLVM-(\d+)", name) or re.match(r"libLLVM\.so\.(\d+)", name) \
            or re.match(r"libLLVM\.(\d+)(?:\.\d+)*\.dylib", name)
        if m:
            return int(m.group(1))
    m = re.search(r"llvm-(\d+)", os.path.realpath(path))
    return int(m.group(1)) if m else None


def _package_candidates() -> list[Candidate]:
    """libLLVM files installed by the karellen-llvm-core wheel, if it is present.

    The wheel's file list (its RECORD) is read directly from the first
    ``karellen_llvm_core-*.dist-info`` on sys.path, as importlib.metadata would
    find it; importing importlib.metadata alone took a third of the time a
    whole `whitted render` spends importing (benchmarks/bench_speed.py direct).
    """
    found = []
    for entry in sys.path:
        records = sorted(glob.glob(os.path.join(entry or ".",
                                                "karellen_llvm_core-*.dist-info", "RECORD")))
        if not records:
            continue
        try:
            with open(records[0], encoding="utf-8") as f:
                lines = f.read().splitlines()
        except OSError:
            return []
        for line in lines:
            rel = line.split(",")[0]
            if re.match(r"libLLVM(-\d+)?\.(so|dylib)", os.path.basename(rel)):
                p = os.path.normpath(os.path.join(entry or ".", rel))
                if os.path.isfile(p):
                    found.append(Candidate(p, llvm_major(p), "karellen-llvm-core"))
        break
    # Prefer the fully versioned file name: it is the real library, not a link.
    found.sort(key=lambda c: -len(os.path.basename(c.path)))
    return found


def _dir_candidates(dirs: list[str], source: str) -> list[Candidate]:
    found = []
    for d in dirs:
        for p in sorted(glob.glob(os.path.join(d, "libLLVM*.so*")) +
                        glob.glob(os.path.join(d, "libLLVM*.dylib"))):
            if os.path.isfile(p):
                found.append(Candidate(p, llvm_major(p), source))
    return found


def _system_candidates() -> list[Candidate]:
    paths = []
    for pattern in _SYSTEM_GLOBS:
        paths += glob.glob(pattern)
    seen, found = set(), []
    for p in sorted(paths):
        real = os.path.realpath(p)
        if real in seen or not os.path.isfile(real):
            continue
        seen.add(real)
        found.append(Candidate(p, llvm_major(p), "system"))
    return found


#: The probe's program: Dr.Jit loads the library and runs a kernel with dr.minimum.
_PROBE_CODE = ("import drjit as dr, drjit.llvm as m\n"
               "assert dr.has_backend(dr.JitBackend.LLVM)\n"
               "x = m.Float([1, 2, 3])\n"
               "y = dr.minimum(x, 2.0) + dr.maximum(x, 2.0)\n"
               "assert y.numpy().tolist() == [3, 4, 5]\n")
#: How long a probe may take before its library counts as not loading (seconds).
PROBE_TIMEOUT = 120
#: Probe children started ahead by :func:`configure_before_drjit`, by path, with the id of
#: the process that started each: :func:`_probe` waits for one of these rather than
#: starting another (a forked process, which cannot wait for its parent's child, starts
#: its own).
_running: dict[str, tuple[int, subprocess.Popen]] = {}


def _spawn(path: str) -> subprocess.Popen:
    """The probe's child process for ``path``, started (its output dropped)."""
    return subprocess.Popen([sys.executable, "-c", _PROBE_CODE],
                            env=dict(os.environ, DRJIT_LIBLLVM_PATH=path),
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)


def _probe_key(path: str) -> str:
    # Keyed by the path as given: the same file reached through a link elsewhere
    # can fail where the original loads (its $ORIGIN-relative dependencies).
    return f"{os.path.abspath(path)}:{_mtime(path)}"


def _probe(path: str) -> bool:
    """Run Dr.Jit on ``path`` in a child process; an LLVM abort only kills the child.
    A child :func:`configure_before_drjit` started for ``path`` is waited for instead."""
    key = _probe_key(path)
    results = _read_probe_cache()
    if key in results:
        return results[key]
    starter, child = _running.pop(path, (None, None))
    try:
        child = child if starter == os.getpid() else _spawn(path)
        ok = child.wait(timeout=PROBE_TIMEOUT) == 0
    except subprocess.TimeoutExpired:
        child.kill()
        child.wait()
        ok = False
    except OSError:
        ok = False
    results[key] = ok
    if cache.folder(cache.home()) is not None:
        cache.write_bytes(_probe_cache_file(), json.dumps(results).encode())
    return ok


def configure_before_drjit() -> None:
    """:func:`configure`, finished before Dr.Jit or Mitsuba is first imported (what
    importing :mod:`tracer` does).

    Where :func:`configure` needs no child process (its answer is cached, or its first
    candidate is refused by name), it runs now. Otherwise the probe's child is started
    and left to run: a fresh machine's probe (a Python start, Dr.Jit's import and a small
    kernel, about 0.2 s) then overlaps what the program does before it needs Dr.Jit,
    such as reading a scene and its meshes. :func:`tracer.backend.use` calls
    :func:`configure`, which waits for that child; any other first import of ``drjit``
    or ``mitsuba`` is held by a finder on ``sys.meta_path`` until :func:`configure` has
    set ``DRJIT_LIBLLVM_PATH``. A program that never needs Dr.Jit leaves its child to
    finish alone; the child only loads the library and exits.
    """
    if _chosen is None and _error is None and "drjit" not in sys.modules \
            and _start_first_probe(os.environ) is not None:
        sys.meta_path.insert(0, _ConfigureFirst())
        return
    configure()


class _ConfigureFirst:
    """A ``sys.meta_path`` finder that runs :func:`configure` before the first import of
    Dr.Jit or Mitsuba, then leaves the import to the other finders."""

    def find_spec(self, name, path=None, target=None):
        if name.partition(".")[0] in ("drjit", "mitsuba"):
            if self in sys.meta_path:
                sys.meta_path.remove(self)
            configure()
        return None


def _start_first_probe(env) -> str | None:
    """Start the probe's child for the first candidate that :func:`find_libllvm` would
    load, if its answer is not cached; the path of the child started, or None."""
    results = _read_probe_cache()
    for c in _ranked(env):
        if c.path in _running:
            return None
        if _refused_by_name(c) is not None:
            continue
        answer = results.get(_probe_key(c.path))
        if answer is True:
            return None   # configure() chooses it without a child
        if answer is None:
            _running[c.path] = (os.getpid(), _spawn(c.path))
            return c.path
    return None


def _mtime(path: str) -> int:
    try:
        return int(os.stat(path).st_mtime)
    except OSError:
        return 0


def _probe_cache_file() -> Path:
    return cache.home() / "llvm-probe.json"


def _read_probe_cache() -> dict[str, bool]:
    """The probe's earlier answers, ``{"<path>:<mtime>": true or false}``; {} when the
    cache may not be used (:mod:`tracer.cache`) or holds anything else (it is rewritten)."""
    if cache.folder(cache.home(), create=False) is None:
        return {}
    data = cache.read_bytes(_probe_cache_file())
    try:
        results = json.loads(data) if data is not None else {}
    except (ValueError, UnicodeDecodeError, RecursionError):
        return {}
    if not isinstance(results, dict) or not all(
            isinstance(k, str) and isinstance(v, bool) for k, v in results.items()):
        return {}
    return results


def _refused_by_name(c: Candidate) -> str | None:
    """Why ``c`` cannot serve Dr.Jit 1.5 judging by its version alone, or None."""
    if c.major is not None and c.major in KNOWN_BAD:
        return KNOWN_BAD[c.major]
    if c.major is not None and c.major < 14:
        return "is too old"
    return None


def _rejection(c: Candidate) -> str | None:
    """Why ``c`` cannot serve Dr.Jit 1.5, or None when it works.

    Versions known to fail are refused by name, without loading them; every
    other candidate is loaded once by a child process (the answer is cached),
    since a library of a good version can still fail to load (a missing
    dependency such as libc++).
    """
    why = _refused_by_name(c)
    if why is not None:
        return why
    if not _probe(c.path):
        return "does not load in drjit 1.5"
    return None


def _describe(c: Candidate, why: str | None = None) -> str:
    name = f"LLVM {c.major}" if c.major is not None else os.path.basename(c.path)
    if why and c.major not in KNOWN_BAD:
        name += f" ({why})"
    return name


def _ranked(env) -> list[Candidate]:
    """The candidates in the order :func:`find_libllvm` tries them: ``DRJIT_LIBLLVM_PATH``
    alone when set, else the packaged library first, then the newest (17 and 18 are
    untested, so after 19 and newer)."""
    explicit = env.get("DRJIT_LIBLLVM_PATH")
    if explicit:
        return [Candidate(explicit, llvm_major(explicit), "DRJIT_LIBLLVM_PATH")] \
            if os.path.isfile(explicit) else []
    search = env.get("WHITTED_LLVM_SEARCH")
    if search is not None:
        candidates = _dir_candidates([d for d in search.split(os.pathsep) if d],
                                     "WHITTED_LLVM_SEARCH")
    else:
        candidates = _package_candidates() + _system_candidates()
    return sorted(candidates, key=lambda c: (c.source != "karellen-llvm-core",
                                             (c.major or 0) < KNOWN_GOOD_FROM,
                                             -(c.major or 0)))


def find_libllvm(env: dict[str, str] | None = None) -> Candidate:
    """Choose the libLLVM for Dr.Jit; raise :class:`LLVMUnavailable` if none works."""
    env = os.environ if env is None else env
    explicit = env.get("DRJIT_LIBLLVM_PATH")
    if explicit:
        c = Candidate(explicit, llvm_major(explicit), "DRJIT_LIBLLVM_PATH")
        if not os.path.isfile(explicit):
            raise LLVMUnavailable(
                f"DRJIT_LIBLLVM_PATH={explicit} does not exist; unset it or point it to "
                f"libLLVM {KNOWN_GOOD_FROM} or newer ({INSTALL_HINT})")
        if c.major in KNOWN_BAD:
            raise LLVMUnavailable(
                f"DRJIT_LIBLLVM_PATH={explicit} is LLVM {c.major}, which "
                f"{KNOWN_BAD[c.major]}; unset it or point it to libLLVM {KNOWN_GOOD_FROM} "
                f"or newer ({INSTALL_HINT})")
        if _rejection(c):
            raise LLVMUnavailable(
                f"DRJIT_LIBLLVM_PATH={explicit} does not work with drjit 1.5; unset it or "
                f"point it to libLLVM {KNOWN_GOOD_FROM} or newer ({INSTALL_HINT})")
        return c

    rejected: dict[str, None] = {}
    for c in _ranked(env):
        why = _rejection(c)
        if why is None:
            return c
        rejected[_describe(c, why)] = None
    found = f"found only {', '.join(sorted(rejected))}" if rejected else "found none"
    raise LLVMUnavailable(
        f"no libLLVM that works with drjit 1.5 ({found}; need {KNOWN_GOOD_FROM} or newer): "
        f"{INSTALL_HINT}")


def loaded_libllvm() -> str | None:
    """The libLLVM already mapped into this process (Linux), or None."""
    try:
        with open("/proc/self/maps") as f:
            for line in f:
                path = line.split()[-1] if line.strip() else ""
                if "libLLVM" in os.path.basename(path):
                    return path
    except OSError:
        pass
    return None


def check_loaded() -> None:
    """Refuse to go on when Dr.Jit already loaded a libLLVM that aborts.

    Dr.Jit loads libLLVM when it is imported; a program that imported drjit
    (or mitsuba) before ``tracer`` may hold a library that would abort at the
    first kernel. Raises :class:`LLVMUnavailable` with advice in that case.
    """
    path = loaded_libllvm()
    major = llvm_major(path) if path else None
    if major in KNOWN_BAD:
        raise LLVMUnavailable(
            f"drjit was imported before tracer and loaded {path} (LLVM {major}, which "
            f"{KNOWN_BAD[major]}); import tracer (or reference) before drjit and mitsuba, "
            f"or set DRJIT_LIBLLVM_PATH to libLLVM {KNOWN_GOOD_FROM} or newer")


_chosen: Candidate | None = None
_error: LLVMUnavailable | None = None


def configure() -> Candidate | None:
    """Find a libLLVM once per process and export it as ``DRJIT_LIBLLVM_PATH``.

    Returns the choice, or None when no usable library exists (the reason is
    kept for :func:`require`). Does nothing useful once drjit is imported,
    because Dr.Jit has read the variable by then.
    """
    global _chosen, _error
    if _chosen is not None or _error is not None:
        return _chosen
    try:
        _chosen = find_libllvm()
        os.environ["DRJIT_LIBLLVM_PATH"] = _chosen.path
    except LLVMUnavailable as e:
        _error = e
        # Keep Dr.Jit from loading a library that would abort the process: an
        # empty search leaves the LLVM backend off instead.
        os.environ["DRJIT_LIBLLVM_PATH"] = os.devnull
    return _chosen


def require() -> Candidate:
    """The configured libLLVM, or :class:`LLVMUnavailable` with its one-line reason."""
    configure()
    if _chosen is None:
        assert _error is not None
        raise _error
    return _chosen
