"""The on-disk cache of ``drjit.syntax``'s transformed code (tracer.backend.syntax).

A later process loads a loop's transformed code instead of transforming the
source again; what it loads must be the transformation of the source as it is
now, never of an earlier version.
"""

from __future__ import annotations

import importlib
import sys

import drjit as dr
import pytest

from tracer import backend
from tracer.backend import jit

PROBE = """
import drjit as dr
from tracer.backend import jit


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


def test_transformed_code_is_stored_and_loaded_by_a_later_wrapper(probe, monkeypatch):
    _, module = probe
    assert _run(module.count_down) == [0, 3, 5]
    files = list(backend.syntax_cache_dir().glob("whitted_syntax_probe.count_down-*.marshal"))
    assert len(files) == 1

    def refuse(fn):
        raise AssertionError("transformed again although the cache holds the code")

    # A later wrapper (as in a later process) loads the stored code: no transformation.
    monkeypatch.setattr(dr, "syntax", refuse)
    assert _run(module.count_down) == [0, 3, 5]


def test_an_edited_source_is_transformed_anew(probe):
    path, module = probe
    assert _run(module.count_down) == [0, 3, 5]
    # The same file, module and function name, another loop body: another key.
    path.write_text(PROBE.format(step=2))
    module = importlib.reload(module)
    assert _run(module.count_down) == [0, 6, 10]
    assert len(list(backend.syntax_cache_dir().glob("*.marshal"))) == 2


def test_a_damaged_cache_file_is_replaced(probe):
    _, module = probe
    _run(module.count_down)
    (stored,) = backend.syntax_cache_dir().glob("*.marshal")
    stored.write_bytes(b"not marshalled code")
    assert _run(module.count_down) == [0, 3, 5]
    assert stored.read_bytes() != b"not marshalled code"


def test_an_unwritable_cache_leaves_the_transformation_in_the_process(probe, tmp_path,
                                                                     monkeypatch):
    _, module = probe
    blocker = tmp_path / "not_a_folder"
    blocker.write_text("")
    monkeypatch.setenv("XDG_CACHE_HOME", str(blocker))
    assert _run(module.count_down) == [0, 3, 5]
