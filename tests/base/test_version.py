"""One version: the constant in slam_lcd/version.py is pyproject.toml's, and the package face re-exports it."""
from __future__ import annotations

import tomllib

from support.paths import REPO


def test_the_version_is_pyprojects():
    import slam_lcd
    from slam_lcd.version import __version__

    project = tomllib.loads((REPO / "pyproject.toml").read_text(encoding="utf-8"))["project"]
    assert __version__ == project["version"]
    assert slam_lcd.__version__ == __version__
