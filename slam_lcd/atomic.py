"""Atomic output: write to a temporary name beside the target, then rename into place.

A crash or Ctrl-C never leaves a half-written output under the final name, nor a
temporary file beside it (creating and removing the temporary folder, and the final
rename, run with Ctrl-C held back: :func:`slam_lcd.interrupts.defer_sigint`), and an input
file can never be overwritten by accident (``guard_not_input``, :func:`check_no_clash`).
"""
from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from pathlib import Path
from typing import Iterable, Iterator, Mapping

from .interrupts import defer_sigint


@contextlib.contextmanager
def atomic_path(target: str | Path, *, directory: bool = False) -> Iterator[Path]:
    """Yield a temporary path beside ``target``; rename it to ``target`` on success.

    With ``directory=True`` the temporary path does not exist yet (writers such as the
    rosbag2 writer create the folder themselves); an existing target folder is replaced.
    """
    target = Path(target)
    target.parent.mkdir(parents=True, exist_ok=True)
    with defer_sigint():
        tmpdir = Path(tempfile.mkdtemp(prefix=f".{target.name}.", dir=target.parent))
    tmp = tmpdir / target.name
    try:
        yield tmp
        with defer_sigint():
            replace_path(tmp, target)
    finally:
        with defer_sigint():
            shutil.rmtree(tmpdir, ignore_errors=True)


def replace_path(src: Path, target: Path) -> None:
    """Move ``src`` (file or folder) to ``target``, replacing what is there.

    A folder in the way is first renamed aside (then deleted), so ``target`` is at every
    instant either the old or the new content, never missing half of it.
    """
    src, target = Path(src), Path(target)
    if target.is_dir() and not target.is_symlink():
        aside = Path(tempfile.mkdtemp(prefix=f".{target.name}.old.", dir=target.parent))
        os.replace(target, aside / target.name)
        os.replace(src, target)
        shutil.rmtree(aside, ignore_errors=True)
    else:
        os.replace(src, target)


@contextlib.contextmanager
def atomic_write(target: str | Path, mode: str = "w", **kwargs):
    """``open()`` replacement whose result appears under ``target`` only when complete."""
    with atomic_path(target) as tmp:
        with open(tmp, mode, **kwargs) as fh:
            yield fh


def write_text(target: str | Path, text: str) -> None:
    with atomic_write(target, "w", encoding="utf-8") as fh:
        fh.write(text)


def same_path(a: str | Path, b: str | Path) -> bool:
    """Do ``a`` and ``b`` name the same file (symlinks resolved; hard links too when both exist)?"""
    a, b = Path(a), Path(b)
    if a.exists() and b.exists():
        try:
            return os.path.samefile(a, b)
        except OSError:
            pass
    return a.resolve() == b.resolve()


def _inside(path: Path, folder: Path) -> bool:
    try:
        path.resolve().relative_to(folder.resolve())
        return True
    except ValueError:
        return False


def check_no_clash(outputs: Iterable[str | Path], inputs: Mapping[str, str | Path | None]) -> None:
    """Refuse, before any work, an output that is an input or lies inside an input folder.

    ``inputs`` maps what the input is (``'log'``, ``'--gt'``, ``'--config'`` ...) to its path;
    None values are skipped. The error names the output, the flag and the input path.
    """
    from .errors import InputError

    outs = [Path(o) for o in outputs]
    for what, inp in inputs.items():
        if inp is None or str(inp) == "":
            continue
        ip = Path(inp)
        for o in outs:
            if same_path(o, ip):
                raise InputError(
                    f"this output would overwrite the input given as {what} ({inp}); "
                    "refusing to overwrite an input: choose another output", o)
            if ip.is_dir() and _inside(o, ip):
                raise InputError(
                    f"this output lies inside the input folder given as {what} ({inp}); "
                    "refusing to write into an input", o)


def guard_not_input(out: str | Path, *inputs: str | Path) -> None:
    """Refuse to write an output onto one of the inputs."""
    from .errors import InputError

    for inp in inputs:
        if inp is not None and Path(inp).exists() and same_path(out, inp):
            raise InputError("output path is the same as an input; refusing to overwrite an input", out)


def check_writable_target(out: str | Path, *, folder: bool = False) -> None:
    """Fail early, with one line, when ``out`` cannot be written (before any work is done).

    Checks that ``out`` is not a folder (for a file output) or not a file (for a folder
    output), and that the nearest existing folder on its way accepts a new entry (a probe
    folder is created and removed): read-only mounts, ``/proc`` and missing permissions
    are reported here rather than after the work.
    """
    from .errors import InputError

    out = Path(out)
    if folder and out.exists() and not out.is_dir():
        raise InputError("output folder is an existing file; give a folder name", out)
    if not folder and out.is_dir():
        raise InputError("output path is a folder; give a file name", out)
    probe_in = out if (folder and out.is_dir()) else out.parent
    while not probe_in.exists():
        if probe_in.parent == probe_in:
            break
        probe_in = probe_in.parent
    if probe_in.exists() and not probe_in.is_dir():
        raise InputError(f"cannot create the output: {probe_in} is a file, not a folder", out)
    try:
        with defer_sigint():
            probe = tempfile.mkdtemp(prefix=".slam-lcd-probe.", dir=probe_in)
            os.rmdir(probe)
    except OSError as e:
        raise InputError(f"cannot write here ({e.strerror or e} in {probe_in})", out) from None
