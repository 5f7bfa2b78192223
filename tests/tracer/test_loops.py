"""The package's symbolic loops are ``drjit.while_loop`` calls, never ``@drjit.syntax``.

``drjit.syntax`` parses and recompiles a function's source when it is applied: in every
process, since its result may not be kept on disk (docs/safety.md, "Caches hold data,
never code"). Applied to the render's loops (the BVH walks, a block's loop over its
shapes) it took about 26 ms of every ``whitted render`` of a mesh, and to the BVH
build's another 20 ms (issue 33). docs/extending.md, "Loops", says how to write them.
The scan reads the source with :mod:`ast`, so a use in any function counts. That the
loops find what they should is tested where they are used (tests/tracer/test_bvh.py
against brute force; the scenes' renders).
"""

from __future__ import annotations

import ast
import textwrap
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def syntax_uses(source: str) -> list[int]:
    """Lines that name ``syntax`` as an attribute (``dr.syntax``, ``drjit.syntax``) or
    import it (``from drjit import syntax``)."""
    lines = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Attribute) and node.attr == "syntax":
            lines.append(node.lineno)
        elif isinstance(node, ast.ImportFrom) and any(a.name == "syntax" for a in node.names):
            lines.append(node.lineno)
    return lines


def test_no_module_of_the_package_uses_drjit_syntax():
    found = [f"{path.relative_to(ROOT)}:{line}"
             for folder in ("tracer", "reference", "scenes")
             for path in sorted((ROOT / folder).rglob("*.py"))
             for line in syntax_uses(path.read_text(encoding="utf-8"))]
    assert found == []


def test_the_scan_finds_each_way_of_naming_it():
    assert syntax_uses(textwrap.dedent("""
        import drjit as dr
        from drjit import syntax
        from whitted.tracer import backend

        @dr.syntax
        def f(x):
            return x

        g = backend.syntax(f)
        """)) == [3, 6, 10]
    assert syntax_uses("def f(x):\n    while x:\n        x -= 1\n") == []
