"""No two modules of the project import each other, directly or through others (an import
circle).

Two checks read the modules' own import statements (not run). At module level (including
inside a module-level ``try``/``if`` but not ``if TYPE_CHECKING:`` nor inside a function):
there a circle is a bug, whichever is imported first would see the other half-made. And
everywhere, a function's imports and the type checker's included (issue 33): a circle hidden
in a function still makes two modules one, and breaks as soon as the import moves to the top;
it is broken by moving the piece both need to where both can import it. The circles still to
break are listed (``KNOWN_CYCLES``). ``from a.b import c`` is an edge to ``a.b.c`` when that
is a module of the project, else to ``a.b``.
"""

from __future__ import annotations

import ast
from collections.abc import Iterator
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = ("common", "services", "pnav", "pnav_local", "pnav_learned", "examples")


def _modules(root: Path = ROOT) -> dict[str, Path]:
    found: dict[str, Path] = {}
    for package in PACKAGES:
        for path in sorted((root / package).rglob("*.py")):
            parts = list(path.relative_to(root).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts.pop()
            found[".".join(parts)] = path
    return found


def _type_checking(node: ast.If) -> bool:
    test = node.test
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING"
    )


def _top_level(body: list[ast.stmt]) -> Iterator[ast.Import | ast.ImportFrom]:
    for node in body:
        if isinstance(node, ast.Import | ast.ImportFrom):
            yield node
        elif isinstance(node, ast.If):
            if not _type_checking(node):
                yield from _top_level(node.body)
            yield from _top_level(node.orelse)
        elif isinstance(node, ast.Try):
            for block in (node.body, node.orelse, node.finalbody):
                yield from _top_level(block)
            for handler in node.handlers:
                yield from _top_level(handler.body)
        elif isinstance(node, ast.With):
            yield from _top_level(node.body)


def _everywhere(tree: ast.Module) -> Iterator[ast.Import | ast.ImportFrom]:
    """Every import of a module: in functions and ``if TYPE_CHECKING:`` blocks too."""
    for node in ast.walk(tree):
        if isinstance(node, ast.Import | ast.ImportFrom):
            yield node


def _edges(
    name: str, path: Path, modules: dict[str, Path], *, everywhere: bool = False
) -> set[str]:
    is_package = path.name == "__init__.py"
    out: set[str] = set()
    tree = ast.parse(path.read_text(), str(path))
    for node in _everywhere(tree) if everywhere else _top_level(tree.body):
        if isinstance(node, ast.Import):
            targets = [alias.name for alias in node.names]
        else:
            base = node.module or ""
            if node.level:
                anchor = name.split(".") if is_package else name.split(".")[:-1]
                anchor = anchor[: len(anchor) - (node.level - 1)]
                base = ".".join([*anchor, base] if base else anchor)
            targets = [
                f"{base}.{alias.name}" if f"{base}.{alias.name}" in modules else base
                for alias in node.names
            ]
        out |= {t for t in targets if t in modules and t != name}
    return out


def _circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def test_no_module_level_import_circle() -> None:
    modules = _modules()
    graph = {name: _edges(name, path, modules) for name, path in modules.items()}
    # the graph is the code's: tables imports keys (from common.contract import keys)
    assert "common.contract.keys" in graph["common.contract.tables"]
    assert _circles(graph) == []


def test_the_check_finds_a_circle() -> None:
    # the check itself: a circle of three, and one module beside it that is not in it
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}
    assert _circles(graph) == [["a", "b", "c"]]


# Circles through a function's or the type checker's imports, not yet broken, each with why
# it is still here. The list may only shrink: a listed circle that is gone fails the test too,
# so it is taken out with the change that breaks it.
KNOWN_CYCLES: list[list[str]] = []


def _every_circle(root: Path = ROOT) -> list[list[str]]:
    modules = _modules(root)
    graph = {name: _edges(name, path, modules, everywhere=True) for name, path in modules.items()}
    return sorted(_circles(graph))


def test_no_import_circle_even_through_functions_or_type_hints() -> None:
    assert _every_circle() == KNOWN_CYCLES


def test_the_check_finds_a_circle_hidden_in_a_function_or_a_type_hint(tmp_path: Path) -> None:
    tools = tmp_path / "pnav" / "tools"
    tools.mkdir(parents=True)
    (tmp_path / "pnav" / "__init__.py").write_text("")
    (tools / "__init__.py").write_text("")
    (tools / "a.py").write_text("from pnav.tools.b import thing\n")
    (tools / "b.py").write_text("def thing():\n    from pnav.tools import c\n")
    (tools / "c.py").write_text("def f():\n    from . import a\n")
    (tools / "d.py").write_text("import pnav.tools.a\n")  # on the way in, not in the circle
    (tools / "e.py").write_text(
        "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from pnav.tools.f import F\n"
    )
    (tools / "f.py").write_text("import pnav.tools.e as e\nclass F: ...\n")
    (tools / "g.py").write_text("from pnav.tools import a, e, not_a_module\n")
    assert _every_circle(tmp_path) == [
        ["pnav.tools.a", "pnav.tools.b", "pnav.tools.c"],
        ["pnav.tools.e", "pnav.tools.f"],
    ]
