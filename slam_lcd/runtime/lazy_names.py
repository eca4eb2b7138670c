"""PEP 562 lazy package attributes: a package names what it exports without importing it.

Why: configuration modules import their package (``slam_lcd.features.config`` ...), and the
package must not pull torch, gtsam or the runner in with it; a name is imported on first use.
"""
from __future__ import annotations

import importlib


def lazy_getattr(package: str, table: dict[str, str], namespace: dict):
    """A module ``__getattr__`` resolving ``table[name]`` (a submodule of ``package``) once, then caching it."""

    def __getattr__(name: str):
        if name in table:
            value = getattr(importlib.import_module(table[name], package), name)
            namespace[name] = value
            return value
        raise AttributeError(f"module {package!r} has no attribute {name!r}")

    return __getattr__
