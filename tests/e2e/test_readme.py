"""The README's code blocks run as written, so they cannot rot.

Every ```bash and ```python block of README.md runs, in order, in one fresh folder (later
blocks use what earlier ones wrote: the demo log, the run's outputs). ``slam-lcd`` is this
checkout's CLI. A block that is not meant to run here is marked in the README by an HTML
comment on the line before it, ``<!-- readme-test: skip (reason) -->``; that list is
asserted to stay small (the two set-up commands, which create a virtual environment
and install; .ci/run runs exactly those).
"""
from __future__ import annotations

import os
import re
import subprocess
import sys

import pytest

from support.paths import REPO

SKIP = re.compile(r"<!--\s*readme-test:\s*skip\s*\((?P<reason>[^)]+)\)\s*-->")
FENCE = re.compile(r"^```(?P<lang>[a-z]*)\s*$")
MAX_SKIPPED = 2


def readme_blocks(text: str) -> list[dict]:
    """Fenced blocks: language, code, the line they start on, and the skip reason (or None)."""
    lines = text.splitlines()
    blocks, i = [], 0
    while i < len(lines):
        m = FENCE.match(lines[i])
        if m and m.group("lang"):
            start = i
            j = i + 1
            while j < len(lines) and not lines[j].startswith("```"):
                j += 1
            prev = next((lines[k] for k in range(start - 1, -1, -1) if lines[k].strip()), "")
            skip = SKIP.search(prev)
            blocks.append({"lang": m.group("lang"), "code": "\n".join(lines[start + 1:j]), "line": start + 1,
                           "skip": skip.group("reason") if skip else None})
            i = j + 1
        else:
            i += 1
    return blocks


def test_skip_marks_are_few_and_say_why():
    blocks = readme_blocks((REPO / "README.md").read_text(encoding="utf-8"))
    assert {b["lang"] for b in blocks} <= {"bash", "python"}, "only bash and python blocks (or mark the others)"
    skipped = [b for b in blocks if b["skip"]]
    assert len(skipped) <= MAX_SKIPPED and all(len(b["skip"]) > 10 for b in skipped), skipped
    assert sum(1 for b in blocks if not b["skip"]) >= 3


def test_marks_are_read(tmp_path):
    text = "x\n<!-- readme-test: skip (needs a robot) -->\n\n```bash\nfalse\n```\n```python\nprint(1)\n```\n"
    blocks = readme_blocks(text)
    assert [b["skip"] for b in blocks] == ["needs a robot", None]


@pytest.fixture(scope="module")
def readme_env(tmp_path_factory, superpoint_weights):
    """A shell where `slam-lcd` is this checkout's CLI, SuperPoint weights are found, and the cache is fresh."""
    root = tmp_path_factory.mktemp("readme")
    bin_dir = root / "bin"
    bin_dir.mkdir()
    shim = bin_dir / "slam-lcd"
    shim.write_text(f'#!/bin/sh\nexec "{sys.executable}" -m slam_lcd "$@"\n')
    shim.chmod(0o755)
    env = dict(os.environ)
    env["PATH"] = f"{bin_dir}{os.pathsep}{env.get('PATH', '')}"
    env["PYTHONPATH"] = str(REPO) + os.pathsep + env.get("PYTHONPATH", "")
    env["SLAM_LCD_SUPERPOINT_WEIGHTS"] = str(superpoint_weights)
    env["SLAM_LCD_CACHE_DIR"] = str(root / "cache")
    env["MPLBACKEND"] = "Agg"
    work = root / "work"
    work.mkdir()
    return env, work


def test_readme_blocks_run(readme_env):
    env, work = readme_env
    blocks = [b for b in readme_blocks((REPO / "README.md").read_text(encoding="utf-8")) if not b["skip"]]
    for b in blocks:
        if b["lang"] == "bash":
            cmd = ["bash", "-euo", "pipefail", "-c", b["code"]]
        else:
            cmd = [sys.executable, "-c", b["code"]]
        proc = subprocess.run(cmd, cwd=work, env=env, capture_output=True, text=True, timeout=900)
        assert proc.returncode == 0, (
            f"README.md block at line {b['line']} ({b['lang']}) failed with status {proc.returncode}:\n"
            f"{proc.stdout[-3000:]}\n{proc.stderr[-3000:]}")
        b["stdout"] = proc.stdout
    # the blocks did what they say
    assert (work / "out" / "corrected.tum").is_file() and (work / "ate.png").is_file()
    assert (work / "ate.zip").is_file() and (work / "corrected.csv").is_file()
    assert (work / "vocab.npz").is_file() and (work / "lcd_eval" / "pr.csv").is_file()
    plugin = next(b for b in blocks if b["lang"] == "python")
    assert "loop: keyframe" in plugin["stdout"] and "corrected poses" in plugin["stdout"]
