"""A folder of outputs that appears as one set: complete, or marked partial, never mixed.

Why: a run writes a dozen files that only make sense together (the config beside the
trajectories it produced, the report that counts the loops in ``loops.csv``). Written one
by one into the user's folder, a failure half-way would leave a new config beside an
earlier run's results. Here every file is written into a hidden staging folder first;
:meth:`OutputSet.publish` then moves the set into place:

- a folder that does not exist yet is created by renaming the staging folder: one
  atomic step;
- into an existing folder, ``PARTIAL.txt`` is put in place first, the earlier run's
  files of the same names are replaced (and ones this run did not produce removed),
  and ``PARTIAL.txt`` is removed last, unless the new set is itself partial. Files of
  other names (the user's own) are left alone. A declared folder (``loops/``) is
  replaced as a whole.

So at the final names there is, at every instant, a complete set or a set that says it is
partial. A run that fails before :meth:`publish` removes its staging folder and leaves an
earlier run's folder exactly as it was. Publishing holds Ctrl-C back until it is done.

Names starting with ``.`` in the staging folder are the run's working files (the keyframe
album of the loop pictures): never published, removed before the set is moved.

A staging folder's name carries the host and process that own it
(``.slam-lcd-staging.<host>.<pid>.<random>``). A process killed outright (SIGKILL, a power
cut) cannot remove its own; :meth:`OutputSet.check` removes, in the output folder and the
folder it is created in, the staging folders of this host whose process is gone (and ones
without an owner in their name, older than an hour). Nothing else is touched: another
host's, a live process's, and every name that is not ours stay.
"""
from __future__ import annotations

import os
import shutil
import socket
import tempfile
import time
from collections.abc import Iterable, Mapping
from pathlib import Path

from ..errors import InputError
from ..files.atomic import check_no_clash, check_writable_target
from ..runtime.interrupts import defer_sigint, finish

PARTIAL_MARKER = "PARTIAL.txt"
STAGING_PREFIX = ".slam-lcd-staging."
LEGACY_STALE_S = 3600.0  # a staging folder without an owner in its name is stale after this long


def _host() -> str:
    return (socket.gethostname() or "host").replace(".", "_")


def staging_prefix() -> str:
    """The name prefix of this process's staging folders: ``.slam-lcd-staging.<host>.<pid>.``."""
    return f"{STAGING_PREFIX}{_host()}.{os.getpid()}."


def _process_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OSError):
        return True
    try:  # a zombie (dead, not yet reaped by its parent) holds nothing
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
        return state not in ("Z", "X")
    except (OSError, IndexError):
        return True


def is_stale_staging(path: Path) -> bool:
    """Is ``path`` a staging folder of ours whose process is gone (see the module docstring)?"""
    name = path.name
    if not name.startswith(STAGING_PREFIX) or not path.is_dir() or path.is_symlink():
        return False
    parts = name[len(STAGING_PREFIX):].rsplit(".", 2)
    if len(parts) == 3 and parts[1].isdigit():
        host, pid = parts[0], int(parts[1])
        return host == _host() and pid != os.getpid() and not _process_alive(pid)
    try:
        return time.time() - path.stat().st_mtime > LEGACY_STALE_S
    except OSError:
        return False


def remove_stale_staging(*folders: str | Path) -> list[Path]:
    """Remove the stale staging folders of ours found directly in ``folders``; the ones removed."""
    removed = []
    for folder in folders:
        folder = Path(folder)
        if not folder.is_dir():
            continue
        try:
            entries = [p for p in folder.iterdir() if p.name.startswith(STAGING_PREFIX)]
        except OSError:
            continue
        for p in entries:
            if is_stale_staging(p):
                shutil.rmtree(p, ignore_errors=True)
                removed.append(p)
    return removed


class OutputSet:
    """Outputs named ``names`` inside folder ``target`` (see the module docstring)."""

    def __init__(self, target: str | Path, names: Iterable[str]):
        self.target = Path(target)
        self.names = tuple(dict.fromkeys([*names, PARTIAL_MARKER]))
        self._staging: Path | None = None

    # ------------------------------------------------------------------ before any work
    def check(self, inputs: Mapping[str, str | Path | None]) -> None:
        """Refuse clashes with inputs and unwritable targets, writing nothing."""
        # clashes first: the writability probe must not touch an input folder either
        check_no_clash({"the output folder": self.target, **{n: self.target / n for n in self.names}}, inputs,
                       merged=[self.target])
        check_writable_target(self.target, folder=True)
        # what a killed run left (its staging folder) goes before this run starts
        remove_stale_staging(self.target, self.target.parent)

    # ------------------------------------------------------------------ writing
    @property
    def staging(self) -> Path:
        """The hidden folder the outputs are written into (created on first use)."""
        if self._staging is None:
            where = self.target if self.target.is_dir() else self.target.parent
            try:
                where.mkdir(parents=True, exist_ok=True)
                with defer_sigint():
                    self._staging = Path(tempfile.mkdtemp(prefix=staging_prefix(), dir=where))
            except OSError as e:
                raise InputError(f"cannot write the outputs ({e.strerror or e})", self.target) from None
        return self._staging

    def mark_partial(self, text: str) -> None:
        """Say in the set itself that it is incomplete (written before anything else can fail)."""
        path = self.staging / PARTIAL_MARKER
        with open(path, "w", encoding="utf-8") as fh:
            fh.write(text.rstrip("\n") + "\n")

    @property
    def is_partial(self) -> bool:
        return self._staging is not None and (self._staging / PARTIAL_MARKER).exists()

    def discard(self) -> None:
        if self._staging is not None:
            finish(shutil.rmtree, self._staging, True)  # whatever signal arrives meanwhile
            self._staging = None

    # ------------------------------------------------------------------ publishing
    def publish(self) -> list[str]:
        """Move the staged files to ``target``; returns the names published."""
        staging = self.staging
        for p in staging.iterdir():
            if p.name.startswith("."):  # a working folder of the run, not an output
                shutil.rmtree(p, ignore_errors=True) if p.is_dir() else p.unlink()
        produced = sorted(p.name for p in staging.iterdir())
        unknown = [n for n in produced if n not in self.names]
        if unknown:  # a programming error: every output must be declared
            raise RuntimeError(f"outputs {unknown} are not declared in the output set")
        partial = PARTIAL_MARKER in produced
        t = self.target
        with defer_sigint():
            if not t.exists():  # a new folder: the staging folder becomes it in one rename
                os.replace(staging, t)
            else:
                if partial:
                    os.replace(staging / PARTIAL_MARKER, t / PARTIAL_MARKER)
                else:
                    with open(t / PARTIAL_MARKER, "w", encoding="utf-8") as fh:
                        fh.write("slam-lcd is replacing this folder's outputs with a new run's; "
                                 "the set is incomplete while this file exists\n")
                for name in self.names:
                    if name == PARTIAL_MARKER or name in produced:
                        continue
                    old = t / name
                    if old.is_file() or old.is_symlink():
                        old.unlink()  # an earlier run's output that this run did not produce
                    elif old.is_dir():
                        shutil.rmtree(old)
                for name in produced:
                    if name != PARTIAL_MARKER:
                        if (t / name).is_dir() and not (t / name).is_symlink():
                            shutil.rmtree(t / name)  # a folder output is replaced as a whole
                        os.replace(staging / name, t / name)
                if not partial:
                    os.unlink(t / PARTIAL_MARKER)
                shutil.rmtree(staging, ignore_errors=True)
            self._staging = None
        return produced
