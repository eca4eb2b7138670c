"""The package's import graph has no circle: every module can be read after the ones it imports.

Walks every module of ``slam_lcd`` with :mod:`ast` (no import is executed), takes each import of
another ``slam_lcd`` module, at the top of a module, inside a function (an import deferred into
a function is still a dependency, only a later one) or under ``if TYPE_CHECKING:`` (the type
checker reads the modules in that order too, and a reader follows the same names), and fails
naming the modules of each circle.
"""
from __future__ import annotations

import ast
from pathlib import Path

from support.paths import REPO

PKG = REPO / "slam_lcd"


def _modules() -> dict[str, Path]:
    out = {}
    for p in PKG.rglob("*.py"):
        parts = p.relative_to(PKG.parent).with_suffix("").parts
        name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
        out[name] = p
    return out


def _imports(name: str, path: Path, mods: dict[str, Path]) -> set[str]:
    tree = ast.parse(path.read_text())
    here = name.split(".") if path.name == "__init__.py" else name.split(".")[:-1]
    out = set()
    for n in ast.walk(tree):
        if isinstance(n, ast.ImportFrom):
            base = ".".join(here[:len(here) - (n.level - 1)] + ([n.module] if n.module else [])) if n.level \
                else (n.module or "")
            for a in n.names:
                target = f"{base}.{a.name}" if f"{base}.{a.name}" in mods else base
                if target in mods and target != name:
                    out.add(target)
        elif isinstance(n, ast.Import):
            out |= {a.name for a in n.names if a.name in mods and a.name != name}
    return out


def _circles(edges: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    found = []
    for root in sorted(edges):
        if root in index:
            continue
        work = [(root, iter(sorted(edges[root])))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on.add(root)
        while work:
            v, it = work[-1]
            for w in it:
                if w not in index:
                    index[w] = low[w] = len(index)
                    stack.append(w)
                    on.add(w)
                    work.append((w, iter(sorted(edges[w]))))
                    break
                if w in on:
                    low[v] = min(low[v], index[w])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[v])
                if low[v] == index[v]:
                    comp = []
                    while True:
                        w = stack.pop()
                        on.discard(w)
                        comp.append(w)
                        if w == v:
                            break
                    if len(comp) > 1:
                        found.append(sorted(comp))
    return found


def _package_edges_removed(edges: dict[str, set[str]]) -> dict[str, set[str]]:
    """A package's ``__init__`` re-exporting its own modules is not a circle with them."""
    return {m: {t for t in ts if not t.startswith(m + ".")} for m, ts in edges.items()}


def test_the_package_has_no_import_circle():
    mods = _modules()
    edges = _package_edges_removed({m: _imports(m, p, mods) for m, p in mods.items()})
    circles = _circles(edges)
    assert not circles, "import circles: " + "; ".join(" <-> ".join(c) for c in circles)


def test_the_walk_finds_a_circle_when_there_is_one():
    assert _circles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert _circles({"a": {"b"}, "b": set()}) == []


def test_an_import_for_the_type_checker_counts(tmp_path):
    src = tmp_path / "a.py"
    src.write_text("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from .b import B\n")
    mods = {"pkg.a": src, "pkg.b": tmp_path / "b.py"}
    assert _imports("pkg.a", src, mods) == {"pkg.b"}
