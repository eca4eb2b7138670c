"""The package's import graph has no circle and no arrow pointing up between layers.

Walks every module of ``slam_lcd`` with :mod:`ast` (no import is executed), takes each import of
another ``slam_lcd`` module, at the top of a module, inside a function (an import deferred into
a function is still a dependency, only a later one) or under ``if TYPE_CHECKING:`` (the type
checker reads the modules in that order too, and a reader follows the same names), and fails
naming the modules of each circle, and each import of a module from a higher layer (:data:`LAYERS`,
as docs/architecture.md draws them). An arrow within a layer is allowed; an arrow up is an error
unless :data:`EXCEPTIONS` lists it with its reason.
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


# bottom to top: a module may import its own layer and those below it, never one above
LAYERS: list[tuple[str, set[str]]] = [
    ("base", {"errors", "types", "geometry", "value_range", "version", "loop_factor", "data"}),  # data: the presets
    ("support", {"files", "runtime", "vision"}),
    ("stages", {"io", "features", "frontend", "vocab", "lcd", "backend", "eval", "cloud"}),
    ("sources", {"sensors"}),
    ("maps", {"map"}),
    ("configuration", {"config"}),
    ("results", {"outputs"}),
    ("entrance", {"sim", "viewer", "run", "batch"}),
    ("top", {"cli", "slam_lcd", "__main__"}),  # slam_lcd: the package face (slam_lcd/__init__.py)
]

# (importing module, imported module) -> why that upward arrow stays; none today
EXCEPTIONS: dict[tuple[str, str], str] = {}


def _unit(module: str) -> str:
    """``slam_lcd.backend.pose_graph`` -> ``backend``; ``slam_lcd`` (the face) -> ``slam_lcd``."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else parts[0]


def _rank() -> dict[str, int]:
    return {unit: i for i, (_, units) in enumerate(LAYERS) for unit in units}


def _upward(edges: dict[str, set[str]], rank: dict[str, int]) -> list[str]:
    return sorted(f"{m} ({LAYERS[rank[_unit(m)]][0]}) -> {t} ({LAYERS[rank[_unit(t)]][0]})"
                  for m, ts in edges.items() for t in ts
                  if rank[_unit(t)] > rank[_unit(m)] and (m, t) not in EXCEPTIONS)


def test_every_module_has_a_layer():
    rank = _rank()
    assert sorted({_unit(m) for m in _modules()} - set(rank)) == [], "place new packages in LAYERS"
    assert sum(len(units) for _, units in LAYERS) == len(rank), "a package in two layers"


def test_no_import_points_up_a_layer():
    mods = _modules()
    edges = {m: _imports(m, p, mods) for m, p in mods.items()}
    up = _upward(edges, _rank())
    assert not up, "imports of a higher layer:\n" + "\n".join(up)


def test_each_exception_is_still_an_upward_import_with_a_reason():
    mods = _modules()
    rank = _rank()
    for (m, t), why in EXCEPTIONS.items():
        assert t in _imports(m, mods[m], mods), f"{m} no longer imports {t}: drop the exception"
        assert rank[_unit(t)] > rank[_unit(m)] and len(why) > 10, (m, t, why)


def test_the_walk_finds_an_upward_import():
    rank = {"errors": 0, "types": 0, "backend": 2, "cli": 8}
    edges = {"slam_lcd.types": {"slam_lcd.backend.loop_factors", "slam_lcd.errors"},
             "slam_lcd.cli.main": {"slam_lcd.types"}}
    assert _upward(edges, rank) == ["slam_lcd.types (base) -> slam_lcd.backend.loop_factors (stages)"]
