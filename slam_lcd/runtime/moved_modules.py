"""Modules that moved keep their old import paths: ``import slam_lcd.pipeline`` still works.

Why a finder and not a file per old path: the top of ``slam_lcd/`` holds only the base modules and
the packages, so a newcomer finds the run layer in ``slam_lcd/run/``, and a module's name says its
one job (``slam_lcd.io.message_builders`` builds messages, :mod:`slam_lcd.sensors.messages` decodes
them); scripts written against the old paths still run, with a :class:`DeprecationWarning` naming
the new one. The old name is an alias: ``slam_lcd.pipeline.Pipeline is slam_lcd.run.pipeline.Pipeline``.
"""
from __future__ import annotations

import importlib
import importlib.machinery
import sys
import warnings

MOVED = {
    "slam_lcd.pipeline": "slam_lcd.run.pipeline",
    "slam_lcd.runner": "slam_lcd.run.runner",
    "slam_lcd.run_sources": "slam_lcd.run.sources",
    "slam_lcd.run_checks": "slam_lcd.run.checks",
    "slam_lcd.extract_ahead": "slam_lcd.run.extract_ahead",
    "slam_lcd.frontend.frame_queue": "slam_lcd.run.frame_queue",
    "slam_lcd.io.messages": "slam_lcd.io.message_builders",
    "slam_lcd.lcd.evaluation": "slam_lcd.eval.loop_detection",
    "slam_lcd.lcd.nees": "slam_lcd.eval.nees",
}


class _Alias:
    """Finds an old module name and loads it as the module at its new place (the same object): a meta
    path finder and its loader (by protocol: importing importlib.abc would double ``import slam_lcd``)."""

    def find_spec(self, fullname, path=None, target=None):
        if fullname not in MOVED:
            return None
        return importlib.machinery.ModuleSpec(fullname, self)

    def create_module(self, spec):
        new = MOVED[spec.name]
        warnings.warn(f"{spec.name} moved to {new}; import it from there"
                      + (" (or the name from slam_lcd)" if new.startswith("slam_lcd.run.") else ""),
                      DeprecationWarning, stacklevel=2)
        module = importlib.import_module(new)
        self._spec = module.__spec__  # importlib stamps the alias's spec on the module: put it back
        return module

    def exec_module(self, module) -> None:
        module.__spec__ = self._spec


def install() -> None:
    """Add the finder once (``slam_lcd/__init__`` calls it)."""
    if not any(isinstance(f, _Alias) for f in sys.meta_path):
        sys.meta_path.append(_Alias())
