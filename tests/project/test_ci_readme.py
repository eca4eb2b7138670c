"""The README says what `.ci/run` does, and only that: every command it names is in the script, the
script's pytest command is the README's test command with the flags it names, and every
`slam-lcd` command the script runs from the wheel is named in the README."""
from __future__ import annotations

import re
import shlex

from support.paths import REPO

README = (REPO / "README.md").read_text(encoding="utf-8")
CI = (REPO / ".ci" / "run").read_text(encoding="utf-8")
HEADING = "### What CI runs (`.ci/run`)"


def ci_section() -> str:
    assert HEADING in README, f"README.md has no section {HEADING!r}"
    rest = README.split(HEADING, 1)[1]
    return re.split(r"^#{2,3} ", rest, maxsplit=1, flags=re.MULTILINE)[0]


def spans(text: str) -> list[str]:
    return re.findall(r"`([^`\n]+)`", text)


def ci_lines() -> list[str]:
    return [ln.strip() for ln in CI.splitlines() if ln.strip() and not ln.lstrip().startswith("#")]


def test_no_claim_that_the_readme_blocks_are_exactly_what_ci_runs():
    assert "runs exactly this" not in README


def test_every_command_and_name_the_readme_gives_for_ci_is_in_the_script():
    named = [s for s in spans(ci_section()) if ".ci/run" not in s]
    assert len(named) >= 10, named
    assert [s for s in named if s not in CI] == []


def test_the_pytest_command_is_the_readmes_with_the_flags_the_readme_names():
    (ci_pytest,) = [ln for ln in ci_lines() if ln.startswith("python -m pytest")]
    assert ci_pytest in spans(ci_section()), f"the README does not name {ci_pytest!r}"
    (block,) = [ln for ln in README.splitlines() if ln.startswith("python3 -m venv") and "pytest" in ln]
    readme_pytest = shlex.split(block.split("&&")[-1])
    assert shlex.split(ci_pytest)[:len(readme_pytest)] == readme_pytest
    assert "--durations=15" in shlex.split(ci_pytest)


def test_every_slam_lcd_command_of_the_wheel_step_is_named_in_the_readme():
    runs = [ln.split("#")[0].strip() for ln in ci_lines() if ln.startswith("slam-lcd ")]
    assert len(runs) >= 4, runs
    section = ci_section()
    assert [r for r in runs if f"`{r}`" not in section] == []


def test_the_chromium_install_is_announced_before_it_runs():
    block = CI.split("if ! command -v chromium", 1)[1].split("\nfi\n", 1)[0]
    lines = [ln.strip() for ln in block.splitlines()]
    first_echo = next(i for i, ln in enumerate(lines) if ln.startswith("echo"))
    first_install = next(i for i, ln in enumerate(lines) if "apt-get install" in ln and not ln.startswith("echo"))
    assert first_echo < first_install, block
    assert "chromium" in lines[first_echo].lower()
