"""tests/ mirrors the package: every test file sits in the folder of the package it tests, or in one
of the folders that cut across packages (CONTRIBUTING.md, "Tests")."""
from __future__ import annotations

from support.paths import REPO
from support.slow_files import SLOW_FILES

TESTS = REPO / "tests"
ACROSS = {"base", "e2e", "project", "support"}  # top-level modules, as users run it, the checkout, helpers


def test_no_test_file_at_the_top_of_tests():
    assert sorted(p.name for p in TESTS.glob("test_*.py")) == []


def test_every_test_folder_is_a_package_of_slam_lcd_or_a_cross_cutting_one():
    packages = {p.parent.name for p in (REPO / "slam_lcd").glob("*/__init__.py")}
    folders = {p.name for p in TESTS.iterdir() if p.is_dir() and not p.name.startswith((".", "__"))}
    assert folders - packages - ACROSS == set()
    assert not ACROSS & packages, "a cross-cutting folder's name is also a package's"


def test_test_files_have_unique_names():
    """pytest imports test files by their base name (tests/ has no __init__.py): two equal names collide."""
    names = [p.name for p in TESTS.rglob("test_*.py")]
    assert len(names) == len(set(names))


def test_the_slow_files_named_in_conftest_exist():
    """tests/conftest.py hands these files (support.slow_files) to the workers first; a renamed one
    would silently lose its place."""
    assert [f for f in SLOW_FILES if not (TESTS / f).is_file()] == []
