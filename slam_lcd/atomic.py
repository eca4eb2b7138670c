"""Atomic output: write to a temporary name beside the target, then rename into place.

A crash or Ctrl-C never leaves a half-written output under the final name, and an input
file can never be overwritten by accident (``guard_not_input``).
"""
from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from pathlib import Path
from typing import Iterator


@contextlib.contextmanager
def atomic_path(target: str | Path, *, directory: bool = False) -> Iterator[Path]:
    """Yield a temporary path beside ``target``; rename it to ``target`` on success.

    With ``directory=True`` the temporary path does not exist yet (writers such as the
    rosbag2 writer create the folder themselves); an existing target folder is replaced.
    """
    target = Path(target)
    target.parent.mkdir(parents=True, exist_ok=True)
    tmpdir = Path(tempfile.mkdtemp(prefix=f".{target.name}.", dir=target.parent))
    tmp = tmpdir / target.name
    try:
        yield tmp
        if directory:
            if target.exists():
                shutil.rmtree(target) if target.is_dir() else target.unlink()
            os.replace(tmp, target)
        else:
            os.replace(tmp, target)
    finally:
        shutil.rmtree(tmpdir, ignore_errors=True)


@contextlib.contextmanager
def atomic_write(target: str | Path, mode: str = "w", **kwargs):
    """``open()`` replacement whose result appears under ``target`` only when complete."""
    with atomic_path(target) as tmp:
        with open(tmp, mode, **kwargs) as fh:
            yield fh


def write_text(target: str | Path, text: str) -> None:
    with atomic_write(target, "w", encoding="utf-8") as fh:
        fh.write(text)


def guard_not_input(out: str | Path, *inputs: str | Path) -> None:
    """Refuse to write an output onto one of the inputs."""
    from .errors import InputError

    out_r = Path(out).resolve()
    for inp in inputs:
        if inp is not None and Path(inp).exists() and Path(inp).resolve() == out_r:
            raise InputError("output path is the same as an input; refusing to overwrite an input", out)
