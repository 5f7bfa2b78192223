"""The import graph of the code: no cycles, and imports flow one way.

Read from the source with :mod:`ast` (nothing is imported), so a cycle hidden in a
function body or behind ``if TYPE_CHECKING`` counts as much as one at the top of a
module: every ``import`` and ``from ... import`` anywhere in a module is an edge, and
so is a lazy ``deferred("whitted....")`` (:func:`tracer.backend.deferred`). ``from X
import Y`` where ``Y`` is a submodule is an edge to ``X.Y``; relative imports are
resolved against the importing module's package. The installed names map to the
repository's folders: ``whitted.tracer`` is ``tracer/``, ``whitted.reference``
``reference/``, ``whitted.scenes`` ``scenes/`` (docs/architecture.md).

The rules (docs/architecture.md, ../shared/style.md "The shape of the code"):
no strongly connected component of more than one module (nor a module importing
itself); nothing under ``whitted.tracer`` imports ``whitted.reference`` or Mitsuba;
``whitted.scenes`` imports neither (its scripts that make meshes and textures may
use the tracer's readers and writers).
"""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = {"whitted.tracer": ROOT / "tracer", "whitted.reference": ROOT / "reference",
            "whitted.scenes": ROOT / "scenes"}


def modules() -> dict[str, Path]:
    """Every module of the three packages, by its installed name."""
    out = {}
    for package, folder in PACKAGES.items():
        for path in sorted(folder.rglob("*.py")):
            rel = path.relative_to(folder).with_suffix("")
            if "__pycache__" in rel.parts:
                continue
            parts = [p for p in rel.parts if p != "__init__"]
            out[".".join([package, *parts])] = path
    return out


def _target(name: str, known) -> str | None:
    """The known module ``name`` is, or the deepest known package holding it."""
    while name:
        if name in known:
            return name
        name = name.rpartition(".")[0]
    return None


def imports_of(name: str, path: Path, known) -> list[tuple[str, int]]:
    """(imported name, line) for every import in the module, at any depth of its body.

    Names are absolute; those inside the three packages are resolved to a known module
    (``from X import Y`` is ``X.Y`` when that is a module, else ``X``).
    """
    tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
    is_package = path.name == "__init__.py"
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out += [(a.name, node.lineno) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base_parts = name.split(".")
                if not is_package:
                    base_parts = base_parts[:-1]
                base_parts = base_parts[:len(base_parts) - (node.level - 1)]
                base = ".".join(base_parts + ([node.module] if node.module else []))
            else:
                base = node.module or ""
            for a in node.names:
                sub = f"{base}.{a.name}"
                out.append((sub if sub in known else base, node.lineno))
        elif (isinstance(node, ast.Call) and isinstance(node.func, ast.Name)
              and node.func.id == "deferred" and node.args
              and isinstance(node.args[0], ast.Constant)
              and isinstance(node.args[0].value, str)):
            out.append((node.args[0].value, node.lineno))
    return out


def import_graph() -> dict[str, dict[str, int]]:
    """module -> {imported module of the three packages: first line importing it}."""
    known = modules()
    graph: dict[str, dict[str, int]] = {}
    for name, path in known.items():
        edges = graph.setdefault(name, {})
        for imported, line in imports_of(name, path, known):
            target = _target(imported, known)
            if target is not None:
                edges.setdefault(target, line)
    return graph


def strongly_connected(graph: dict[str, dict[str, int]]) -> list[list[str]]:
    """Tarjan's strongly connected components (iterative), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    on_stack: set[str] = set()
    stack: list[str] = []
    out: list[list[str]] = []
    counter = 0
    for root in graph:
        if root in index:
            continue
        work = [(root, iter(graph[root]))]
        index[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on_stack.add(root)
        while work:
            v, it = work[-1]
            w = next(it, None)
            if w is not None:
                if w not in index:
                    index[w] = low[w] = counter
                    counter += 1
                    stack.append(w)
                    on_stack.add(w)
                    work.append((w, iter(graph.get(w, {}))))
                elif w in on_stack:
                    low[v] = min(low[v], index[w])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[v])
            if low[v] == index[v]:
                component = []
                while True:
                    w = stack.pop()
                    on_stack.discard(w)
                    component.append(w)
                    if w == v:
                        break
                out.append(sorted(component))
    return out


def _cycle_in(component: list[str], graph) -> list[str]:
    """One cycle through the component's first module, as a path back to it."""
    members = set(component)
    start = component[0]
    path, seen = [start], {start}
    while True:
        nxt = sorted(w for w in graph[path[-1]] if w in members)
        if start in nxt and len(path) > 1 or nxt == [start]:
            return path + [start]
        fresh = [w for w in nxt if w not in seen]
        if not fresh:  # fall back: any member back to the start (a component has one)
            return path + ["...", start]
        path.append(fresh[0])
        seen.add(fresh[0])


def _describe(cycle: list[str], graph) -> str:
    steps = []
    for a, b in zip(cycle, cycle[1:], strict=False):
        line = graph.get(a, {}).get(b)
        steps.append(f"{a} (line {line}) -> " if line else f"{a} -> ")
    return "".join(steps) + cycle[-1]


def cycles(graph) -> list[str]:
    out = []
    for component in strongly_connected(graph):
        if len(component) > 1 or component[0] in graph[component[0]]:
            out.append(f"{', '.join(component)}\n    e.g. "
                       f"{_describe(_cycle_in(component, graph), graph)}")
    return out


def test_graph_reads_the_whole_code():
    graph = import_graph()
    assert "whitted.tracer.scene" in graph and "whitted.reference.check.judge" in graph
    assert "whitted.tracer.settings" in graph["whitted.tracer.materials.diffuse"]


def test_no_import_cycles():
    found = cycles(import_graph())
    assert not found, "import cycles (strongly connected modules):\n  " + "\n  ".join(found)


def test_a_cycle_is_found():
    graph = {"a": {"b": 1}, "b": {"c": 2}, "c": {"a": 3}, "d": {"a": 4}, "e": {"e": 5}}
    found = cycles(graph)
    assert len(found) == 2
    assert found[0].startswith("a, b, c") and "a (line 1) -> b" in found[0]
    assert found[1].startswith("e")


def test_from_import_of_a_submodule_is_an_edge_to_it(tmp_path):
    path = tmp_path / "m.py"
    path.write_text("def f():\n    from whitted.tracer import scene, load_scene\n"
                    "    from . import settings\n    from ..reference.check import judge\n")
    known = {"whitted.tracer", "whitted.tracer.scene", "whitted.tracer.settings",
             "whitted.reference.check.judge"}
    got = [n for n, _ in imports_of("whitted.tracer.m", path, known)]
    assert got == ["whitted.tracer.scene", "whitted.tracer",
                   "whitted.tracer.settings", "whitted.reference.check.judge"]


def _importers(prefix: str, forbidden: tuple[str, ...]) -> list[str]:
    known = set(modules())
    bad = []
    for name, path in modules().items():
        if name != prefix and not name.startswith(prefix + "."):
            continue
        for imported, line in imports_of(name, path, known):
            if any(imported == f or imported.startswith(f + ".") for f in forbidden):
                bad.append(f"{path.relative_to(ROOT)}:{line} imports {imported}")
    return bad


def test_tracer_never_imports_reference_or_mitsuba():
    bad = _importers("whitted.tracer", ("whitted.reference", "mitsuba"))
    assert not bad, "\n".join(bad)


def test_scenes_import_neither_reference_nor_mitsuba():
    bad = _importers("whitted.scenes", ("whitted.reference", "mitsuba"))
    assert not bad, "\n".join(bad)


def test_commands_are_at_the_top_no_library_module_imports_them():
    """The command modules (reference/commands/, and reference/cli.py, their older name)
    import the library; the library never imports a command (pip's layout: commands are
    leaves of the import graph)."""
    graph = import_graph()

    def is_command(m: str) -> bool:
        return m in ("whitted.reference.cli", "whitted.reference.commands") or m.startswith(
            "whitted.reference.commands.")

    bad = [f"{m} (line {line}) imports {t}" for m, edges in graph.items() if not is_command(m)
           for t, line in edges.items() if is_command(t)]
    assert not bad, "library modules importing a command:\n  " + "\n  ".join(bad)
    assert any(is_command(m) for m in graph)
