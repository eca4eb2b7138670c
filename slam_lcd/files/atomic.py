"""Atomic output: write to a temporary name beside the target, then rename into place.

A Ctrl-C, SIGTERM or SIGHUP never leaves a half-written output under the final name, nor a
temporary folder beside it (creating the temporary folder and the final rename run with
those signals held back, :func:`slam_lcd.runtime.interrupts.defer_sigint`; removing it runs to its
end whatever arrives, :func:`slam_lcd.runtime.interrupts.finish`), and an input can never be
overwritten by accident (``guard_not_input``, :func:`check_no_clash`).
"""
from __future__ import annotations

import contextlib
import os
import re
import shutil
import tempfile
from collections.abc import Iterable, Iterator, Mapping
from pathlib import Path

from ..errors import InputError
from ..runtime.interrupts import defer_sigint, finish


@contextlib.contextmanager
def atomic_path(target: str | Path, *, directory: bool = False) -> Iterator[Path]:
    """Yield a temporary path beside ``target``; rename it to ``target`` on success.

    With ``directory=True`` the temporary path does not exist yet (writers such as the
    rosbag2 writer create the folder themselves); an existing target folder is replaced.
    """
    target = Path(target)
    target.parent.mkdir(parents=True, exist_ok=True)
    made: list[Path] = []
    try:  # from before the folder exists: a signal held while it is made is raised inside this try
        with defer_sigint():
            made.append(Path(tempfile.mkdtemp(prefix=f".{target.name}.", dir=target.parent)))
        tmp = made[0] / target.name
        yield tmp
        with defer_sigint():
            replace_path(tmp, target)
    finally:
        if made:
            finish(shutil.rmtree, made[0], True)


_TEMP_PART = re.compile(r"\.(?P<name>.+)\.[a-z0-9_]{8}")  # atomic_path's temporary folder: .<name>.XXXXXXXX
_STAGING_PART = ".slam-lcd-staging."  # an output set's staging folder (slam_lcd.outputs.output_set)


def user_path(path: str | Path) -> Path:
    """The path a user asked for, from a temporary or staging path that stands for it.

    Errors name what the user gave (docs/robustness.md): ``out/.x.tum.ab12cd34/x.tum`` is
    ``out/x.tum``, ``out/.slam-lcd-staging.host.1.ab12cd34/report.json`` is ``out/report.json``."""
    parts = list(Path(path).parts)
    out: list[str] = []
    i = 0
    while i < len(parts):
        part = parts[i]
        m = _TEMP_PART.fullmatch(part)
        if part.startswith(_STAGING_PART):
            i += 1
            continue
        if m and i + 1 < len(parts) and parts[i + 1] == m.group("name"):
            i += 1
            continue
        out.append(part)
        i += 1
    return Path(*out) if out else Path(path)


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


def _log_folder(path: Path) -> Path | None:
    """The rosbag2 folder a file belongs to (its ``.db3`` / ``.mcap`` beside ``metadata.yaml``), if any."""
    if path.is_file() and (path.parent / "metadata.yaml").is_file():
        return path.parent
    return None


def check_no_clash(outputs: Iterable[str | Path] | Mapping[str, str | Path | None],
                   inputs: Mapping[str, str | Path | None], *, merged: Iterable[str | Path] = ()) -> None:
    """Refuse, before any work, outputs that would change an input or each other.

    ``outputs`` maps what each output is (``'OUT'``, ``'--loops-csv'`` ...) to its path (a
    plain list names them by their paths); ``inputs`` maps what each input is (``'the log'``,
    ``'--gt'``, ``'--config'`` ...) to its path. None values are skipped. Refused:

    - an output that is an input (same file: symlinks and hard links included);
    - an output inside an input folder (a rosbag2 bag, an image folder; a file of a rosbag2
      bag counts as its whole folder);
    - an input inside an output folder, which the output would replace or remove;
    - two outputs on one path, or an output inside another output's folder.

    ``merged``: outputs that are folders merged into rather than replaced (an output set's
    folder, :class:`slam_lcd.outputs.output_set.OutputSet`): files of other names inside
    them (inputs, other outputs) are left alone, so only their own names count.
    The error names the output, its flag and the other path.
    """
    if isinstance(outputs, Mapping):
        outs = [(str(w), Path(o)) for w, o in outputs.items() if o is not None and str(o) != ""]
    else:
        outs = [(str(o), Path(o)) for o in outputs if o is not None and str(o) != ""]
    kept = {Path(m).resolve() for m in merged}
    replaced = [(w, o) for w, o in outs if o.resolve() not in kept]
    ins = []
    for what, inp in inputs.items():
        if inp is None or str(inp) == "":
            continue
        ip = Path(inp)
        ins.append((what, ip, inp))
        folder = _log_folder(ip)
        if folder is not None:
            ins.append((f"{what} (its rosbag2 folder)", folder, folder))
    for what, ip, inp in ins:
        for _, o in outs:
            if same_path(o, ip):
                raise InputError(
                    f"this output would overwrite the input given as {what} ({inp}); "
                    "refusing to overwrite an input: choose another output", o)
            if ip.is_dir() and _inside(o, ip):
                raise InputError(
                    f"this output lies inside the input folder given as {what} ({inp}); "
                    "refusing to write into an input", o)
        for _, o in replaced:
            if _inside(ip, o):
                raise InputError(
                    f"the input given as {what} ({inp}) lies inside this output folder, which would replace "
                    "it; refusing to write over an input: choose another output", o)
        if ip.is_dir():  # a merged output folder around an input folder: never nested, whatever the names
            for w, o in outs:
                if o.resolve() in kept and _inside(ip, o):
                    raise InputError(
                        f"the input folder given as {what} ({inp}) lies inside this output folder ({w}); input and "
                        "output folders are kept apart: choose another output", o)
    for i, (wa, a) in enumerate(outs):
        for wb, b in outs[i + 1:]:
            if same_path(a, b):
                raise InputError(f"two outputs on one path ({wa} and {wb}); give each its own path", b)
        for wb, b in replaced:
            if b is not a and not same_path(a, b) and _inside(a, b):
                raise InputError(f"this output ({wa}) lies inside the output folder {wb}, which is written as a "
                                 "whole; give each its own path", a)


def check_apart(what: str, folder: str | Path, others: Mapping[str, str | Path | None]) -> None:
    """Refuse ``folder`` (a map folder, flag ``what``) equal to, inside or around any of ``others``.

    Why a rule of its own: a map folder holds only its map, whether it is read (``localize``) or
    appended to (``run --map``), and whether or not it exists yet; an output folder around it or
    inside it would mix a run's files with the map's (a run's ``map/`` output replaced a map
    ``OUT/map``). The error names both paths."""
    f = Path(folder)
    for w, o in others.items():
        if o is None or str(o) == "":
            continue
        op = Path(o)
        if same_path(op, f) or _inside(op, f) or _inside(f, op):
            where = "is" if same_path(op, f) else "lies inside" if _inside(op, f) else "holds"
            raise InputError(f"{w} {o} {where} the map folder given as {what} ({folder}); a map folder holds only "
                             f"its map: give {w} a path outside it, and not around it", op)


def guard_not_input(out: str | Path, *inputs: str | Path) -> None:
    """Refuse to write an output onto one of the inputs."""
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
