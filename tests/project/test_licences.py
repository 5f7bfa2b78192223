"""whitted is BSD-3-Clause: nothing it needs at run time may put it under the GPL."""

import re
import tomllib
from importlib.metadata import PackageNotFoundError, metadata, requires
from pathlib import Path

from packaging.requirements import Requirement

ROOT = Path(__file__).resolve().parents[2]

#: Strong copyleft in a licence field, an SPDX expression or a trove classifier: the GPL
#: and the AGPL (a program distributed with them falls under their terms). The LGPL,
#: which allows linking from code of another licence, is not matched.
COPYLEFT = re.compile(r"(?<![L\w])A?GPL|GNU (Affero )?General Public License")


def licence_fields(name: str) -> list[str]:
    m = metadata(name)
    fields = [m.get("License-Expression") or ""]
    fields += [(m.get("License") or "").split("\n", 1)[0]]  # the name, not a full text
    fields += [c for c in m.get_all("Classifier") or [] if c.startswith("License ::")]
    return [f for f in fields if f]


def runtime_closure(extra: str | None = None) -> dict[str, list[str]]:
    """Every installed distribution the project's dependencies need (no extras; with
    ``extra``, that optional group's as well), with its licence fields."""
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    todo = [Requirement(r) for r in project["dependencies"]]
    if extra:
        todo += [Requirement(r) for r in project["optional-dependencies"][extra]]
    seen: dict[str, list[str]] = {}
    while todo:
        req = todo.pop()
        if req.marker is not None and not req.marker.evaluate({"extra": ""}):
            continue
        key = re.sub(r"[-_.]+", "-", req.name).lower()
        if key in seen:
            continue
        try:
            seen[key] = licence_fields(req.name)
        except PackageNotFoundError:
            seen[key] = []
            continue
        todo += [Requirement(r) for r in requires(req.name) or []]
    return seen


def test_the_copyleft_pattern_tells_gpl_from_permissive_licences():
    for text in ("GPL-3.0-or-later", "GPLv3+", "AGPL-3.0-only",
                 "License :: OSI Approved :: GNU General Public License v3 or later (GPLv3+)"):
        assert COPYLEFT.search(text), text
    for text in ("BSD-3-Clause", "MIT", "Apache-2.0 OR BSD-2-Clause", "LGPL-2.1-or-later",
                 "License :: OSI Approved :: GNU Lesser General Public License v3 (LGPLv3)"):
        assert not COPYLEFT.search(text), text


def test_no_runtime_dependency_is_gpl_licensed():
    closure = runtime_closure()
    assert "numpy" in closure and "mitsuba" in closure  # the walk found the dependencies
    gpl = {name: f for name, fields in closure.items() for f in fields if COPYLEFT.search(f)}
    assert not gpl, f"GPL-licensed runtime dependencies of a BSD-3-Clause project: {gpl}"


def test_no_test_dependency_is_gpl_licensed():
    """The test extra too (jsonschema, MIT, for tests/tracer/test_schema.py; hypothesis, MPL-2.0):
    the test suite is distributed with the project."""
    closure = runtime_closure("test")
    assert "jsonschema" in closure and closure["jsonschema"], closure.get("jsonschema")
    gpl = {name: f for name, fields in closure.items() for f in fields if COPYLEFT.search(f)}
    assert not gpl, f"GPL-licensed test dependencies of a BSD-3-Clause project: {gpl}"
def test_the_luxcore_extra_is_not_gpl_licensed():
    """whitted[luxcore] runs LuxCore in the harness: pyluxcore (Apache-2.0) and its needs."""
    import pytest

    closure = runtime_closure("luxcore")
    if not closure.get("pyluxcore"):
        pytest.skip("pyluxcore is not installed (pip install 'whitted[luxcore]')")
    gpl = {name: f for name, fields in closure.items() for f in fields if COPYLEFT.search(f)}
    assert not gpl, f"GPL-licensed dependencies of the luxcore extra: {gpl}"
