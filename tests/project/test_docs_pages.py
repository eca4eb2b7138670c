"""The documentation stays a set of short pages for users: every docs page at most 250 lines, and
neither the docs nor the package's comments and docstrings cite the project's own issue tracker.
"""
from __future__ import annotations

import re

from support.paths import REPO

MAX_LINES = 250
# the word for a tracker entry followed by its number, with or without "#" (the pattern is built
# in parts so that this file does not match itself)
ISSUE_NUMBER = re.compile(r"\b" + "iss" + r"ue\s*#?\s*\d+", re.IGNORECASE)


def test_every_docs_page_is_at_most_250_lines():
    pages = sorted((REPO / "docs").rglob("*.md"))
    assert len(pages) > 10
    long = {str(p.relative_to(REPO)): n for p in pages
            if (n := len(p.read_text(encoding="utf-8").splitlines())) > MAX_LINES}
    assert not long, f"pages over {MAX_LINES} lines: {long}"


def test_no_issue_numbers_in_docs_or_code():
    files = [*(REPO / "docs").rglob("*.md"), REPO / "README.md", REPO / "mkdocs.yml"]
    for folder in ("slam_lcd", "tools", "tests", "examples"):
        files += (REPO / folder).rglob("*.py")
    hits = [f"{p.relative_to(REPO)}:{i}: {line.strip()}"
            for p in files for i, line in enumerate(p.read_text(encoding="utf-8").splitlines(), 1)
            if ISSUE_NUMBER.search(line)]
    assert not hits, "issue numbers:\n" + "\n".join(hits)


def test_every_docs_page_is_in_the_site_navigation():
    nav = (REPO / "mkdocs.yml").read_text(encoding="utf-8")
    listed = set(re.findall(r"^\s+(?:- [^:\n]+: )?([\w/.-]+\.md)\s*$", nav, re.MULTILINE))
    pages = {str(p.relative_to(REPO / "docs")) for p in (REPO / "docs").rglob("*.md")}
    assert pages <= listed, f"pages missing from mkdocs.yml's nav: {sorted(pages - listed)}"
