"""No module of ``slam_lcd`` is over 400 lines (CONTRIBUTING.md, "Where code goes").

A module that grows past the limit is split by what it does, not exempted: the test has no list
of exceptions. It counts lines as ``wc -l`` does, docstrings and comments included.
"""
from __future__ import annotations

from support.paths import REPO

PKG = REPO / "slam_lcd"
LIMIT = 400


def test_no_module_over_the_limit():
    long = {str(p.relative_to(PKG.parent)): n for p in sorted(PKG.rglob("*.py"))
            if (n := len(p.read_text().splitlines())) > LIMIT}
    assert not long, f"modules over {LIMIT} lines (split them): {long}"
