"""docs/kinds.md is generated from the kinds' docstrings and the schema; it documents every kind."""

from __future__ import annotations

import importlib.util
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def _make_kinds():
    spec = importlib.util.spec_from_file_location("make_kinds", ROOT / "docs" / "make_kinds.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _sections(page: str) -> dict[str, str]:
    """``### `kind``` heading -> the section's text, per ``## group``."""
    out = {}
    for group, body in re.findall(r"^## (\w+)\n(.*?)(?=^## |\Z)", page, re.M | re.S):
        for kind, text in re.findall(r"^### `([\w-]+)`\n(.*?)(?=^### |\Z)", body, re.M | re.S):
            out[(group.lower(), kind)] = text
    return out


def test_kinds_page_is_what_the_generator_prints():
    page = (ROOT / "docs" / "kinds.md").read_text()
    # Regenerate with: python docs/make_kinds.py > docs/kinds.md
    assert page == _make_kinds().render(), "docs/kinds.md is stale: regenerate it"


def test_every_registered_kind_has_a_section_that_describes_it_and_cites_a_source():
    from whitted.tracer import emitters, materials

    make_kinds = _make_kinds()
    sections = _sections((ROOT / "docs" / "kinds.md").read_text())
    registered = {("materials", k): m for k, m in materials.REGISTRY.items()}
    registered |= {("lights", k): m for k, m in {**emitters.LIGHTS,
                                                 **emitters.SHAPE_LIGHTS}.items()}
    # Shapes count once tracer.shapes has a registry (make_kinds picks it up by itself).
    registered |= {("shapes", k): m for k, m in (make_kinds.shape_registry() or {}).items()}
    assert registered.keys() <= sections.keys(), registered.keys() - sections.keys()
    for (group, kind), module in registered.items():
        text = make_kinds.description(module)
        assert text.strip(), f"{group} {kind}: its module has no docstring"
        assert text in sections[(group, kind)], f"{group} {kind}: description not on the page"
        assert make_kinds.cites_source(text), (
            f"{group} {kind}: its docstring cites no source (a lecture slide, a paper, "
            "a pbrt-v4 chapter or a Mitsuba plugin)")


def test_every_key_of_every_kind_in_the_schema_has_a_row():
    make_kinds = _make_kinds()
    sections = _sections((ROOT / "docs" / "kinds.md").read_text())
    for group in ("materials", "lights", "shapes"):
        for kind, table in make_kinds._variants(make_kinds._union(group)).items():
            rows = set(re.findall(r"^\| `(\w+)` \|", sections[(group, kind)], re.M))
            keys = set(table.get("properties", {})) - {"type"}
            assert keys == rows, (group, kind, keys ^ rows)


def test_source_check_refuses_a_description_without_one():
    make_kinds = _make_kinds()
    assert not make_kinds.cites_source("A perfect mirror: r = d - 2 (d . n) n.")
    assert make_kinds.cites_source('The law of reflection (lecture 1, "Reflection").')
    assert make_kinds.cites_source("pbrt-v4, section 9.5")
    assert make_kinds.cites_source("Whitted (1980)")
