"""``drjit.syntax`` applied on first call (tracer.backend.syntax), in memory only.

The transformation of a loop's source is made when the function is first
called, once per wrapper, and kept for the process alone: no code is read
from or written to a cache folder, so nothing planted there can run (issue
30, "Caches hold data, never code").
"""

from __future__ import annotations

import hashlib
import importlib
import marshal
import sys

import drjit as dr
import pytest

from whitted.tracer import backend
from whitted.tracer.backend import jit

PROBE = """
import drjit as dr
from whitted.tracer.backend import jit


def count_down(x):
    i = jit.UInt32(x)
    n = dr.zeros(jit.UInt32, dr.width(i))
    while i > 0:
        n += {step}
        i -= 1
    return n
"""


@pytest.fixture
def probe(tmp_path, monkeypatch):
    """A module with a symbolic loop, written to tmp_path, and a fresh cache folder."""
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    monkeypatch.setattr(sys, "dont_write_bytecode", True)
    monkeypatch.syspath_prepend(str(tmp_path))
    path = tmp_path / "whitted_syntax_probe.py"
    path.write_text(PROBE.format(step=1))
    module = importlib.import_module("whitted_syntax_probe")
    yield path, module
    sys.modules.pop("whitted_syntax_probe", None)


def _run(fn):
    return backend.syntax(fn)(jit.UInt32([0, 3, 5])).numpy().tolist()


def test_the_source_is_transformed_on_first_call_once_per_wrapper(probe, monkeypatch):
    _, module = probe
    calls = []
    real = dr.syntax
    monkeypatch.setattr(dr, "syntax", lambda fn: calls.append(fn) or real(fn))
    wrapped = backend.syntax(module.count_down)
    assert calls == []                                    # not at decoration
    assert wrapped(jit.UInt32([0, 3, 5])).numpy().tolist() == [0, 3, 5]
    assert wrapped(jit.UInt32([2])).numpy().tolist() == [2]
    assert calls == [module.count_down]                   # once


def test_code_planted_in_the_old_cache_folder_is_never_run(probe, tmp_path):
    # The file name an earlier version computed and loaded its code from; here it holds
    # code that leaves a mark when run. The loop must still count, and leave no mark.
    _, module = probe
    fn = module.count_down
    h = hashlib.blake2b(marshal.dumps(fn.__code__), digest_size=16)
    h.update(f"{dr.__version__} {sys.version}".encode())
    folder = tmp_path / "cache" / "whitted" / "syntax"
    folder.mkdir(parents=True)
    mark = tmp_path / "planted-code-ran"
    ns: dict = {}
    exec(f"def count_down(x):\n    open({str(mark)!r}, 'w').close()\n    return x\n", ns)
    planted = folder / f"{fn.__module__}.{fn.__qualname__}-{h.hexdigest()}.marshal"
    planted.write_bytes(marshal.dumps(ns["count_down"].__code__))
    assert _run(fn) == [0, 3, 5]
    assert not mark.exists()


def test_nothing_is_written_to_the_cache_folder(probe, tmp_path):
    _, module = probe
    assert _run(module.count_down) == [0, 3, 5]
    assert not (tmp_path / "cache" / "whitted" / "syntax").exists()


def test_an_edited_source_is_transformed_anew(probe):
    path, module = probe
    assert _run(module.count_down) == [0, 3, 5]
    path.write_text(PROBE.format(step=2))
    module = importlib.reload(module)
    assert _run(module.count_down) == [0, 6, 10]
