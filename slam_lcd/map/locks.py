"""The map folder's writer lock, taken without changing anything that is not yet a map.

Two locks, both ``flock`` (released by the kernel when the process ends, however it ends):

- a **map's own lock**, ``DIR/.lock``: a file of the map, created with its first commit. Writers of
  an existing map (``DIR/map.json`` present) wait on it, so concurrent appends land one after the
  other;
- a **creation lock** for a folder that holds no map yet (absent, empty, or what a killed first
  commit left): a file in the system's temporary folder named after the folder's resolved path.
  Why not ``DIR/.lock``: a command that is refused or fails before its first commit must leave the
  user's folder exactly as it was (no lock file, no new empty map folder), and a folder that does
  not exist cannot hold a lock. Two first appends to one new map still wait for each other.

After a first commit the writer takes the map's own lock too (the folder holds a map now) and lets
the creation lock go: a second creator that waited on it finds the map and waits on ``DIR/.lock``.
The creation lock works on one machine; the map's own lock works wherever ``flock`` does.

The creation lock's file is removed by its holder when it lets the lock go, so the temporary folder
does not collect one file per map ever made. A waiter may then hold a lock on a file that no longer
has a name, so whoever takes the creation lock checks that the path still names the file it locked,
and otherwise opens the path again: two creators never both hold it.
"""
from __future__ import annotations

import contextlib
import errno
import fcntl
import hashlib
import os
import tempfile
import time
from pathlib import Path

from .contents import LOCK, MANIFEST, MapLockedError


def _flock(path: Path, deadline: float, root: Path, timeout_s: float, *, removable: bool = False) -> int:
    """Open (creating) ``path`` and hold an exclusive ``flock`` on it; wait until ``deadline``.

    ``removable``: the lock's holder may remove the file when it lets go (the creation lock), so a
    lock taken on a file that has lost its name is dropped and the path opened again."""
    while True:
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            _wait_for(fd, deadline, root, timeout_s)
        except BaseException:
            os.close(fd)
            raise
        if not removable or _names(path, fd):
            return fd
        os.close(fd)


def _wait_for(fd: int, deadline: float, root: Path, timeout_s: float) -> None:
    while True:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            return
        except OSError as e:
            if e.errno not in (errno.EAGAIN, errno.EACCES):
                raise
            if time.monotonic() >= deadline:
                raise MapLockedError(f"another slam-lcd process is writing this map (waited {timeout_s:g} s); "
                                     "try again when it has finished", root) from None
            time.sleep(0.2)


def _names(path: Path, fd: int) -> bool:
    """Whether ``path`` still names the open file ``fd``."""
    try:
        st = os.stat(path)
    except FileNotFoundError:
        return False
    own = os.fstat(fd)
    return (st.st_dev, st.st_ino) == (own.st_dev, own.st_ino)


def creation_lock_path(root: str | Path) -> Path:
    """The creation lock of ``root``: in the temporary folder, named by the folder's resolved path."""
    key = hashlib.sha256(str(Path(root).resolve()).encode()).hexdigest()[:24]
    return Path(tempfile.gettempdir()) / f"slam-lcd-new-map-{key}.lock"


class WriterLock:
    """The writer lock of the map folder ``root`` (module docstring). ``acquire`` waits up to ``timeout_s``."""

    def __init__(self, root: str | Path, timeout_s: float = 60.0):
        self.root = Path(root)
        self.timeout_s = max(0.0, float(timeout_s))
        self._map_fd: int | None = None  # DIR/.lock
        self._new_fd: int | None = None  # the creation lock
        self._created: list[Path] = []  # what a first commit's preparation made (removed if it fails)

    def acquire(self) -> WriterLock:
        deadline = time.monotonic() + self.timeout_s
        while True:
            if (self.root / MANIFEST).is_file():
                self._map_fd = _flock(self.root / LOCK, deadline, self.root, self.timeout_s)
                return self
            self._new_fd = _flock(creation_lock_path(self.root), deadline, self.root, self.timeout_s, removable=True)
            if not (self.root / MANIFEST).is_file():
                return self
            self._close_new()  # a first commit landed while we waited: the map's own lock from now on

    def before_first_write(self) -> None:
        """Make the folder (with its parents) and take the map's own lock, right before a commit writes
        into a folder that holds no map yet; :meth:`undo_first_write` removes what this and the commit
        created when the commit fails, :meth:`after_first_commit` keeps it."""
        if self._map_fd is not None:
            return
        created: list[Path] = []
        p = self.root
        while not p.exists():
            created.insert(0, p)
            p = p.parent
        self.root.mkdir(parents=True, exist_ok=True)
        for name in ("sessions", LOCK):  # the commit makes sessions/; this makes the lock file
            if not (self.root / name).exists():
                created.append(self.root / name)
        self._created = created
        self._map_fd = _flock(self.root / LOCK, time.monotonic(), self.root, 0.0)

    def after_first_commit(self) -> None:
        """The folder holds a map now: writers wait on its own lock, the creation lock can go."""
        self._created = []
        self._close_new()

    def undo_first_write(self) -> None:
        """A first commit failed: remove the lock file and the folders made for it (the commit's own
        clean-up has emptied them); the folder is as it was before."""
        if (self.root / MANIFEST).exists() or self._new_fd is None:
            return
        if self._map_fd is not None:
            os.close(self._map_fd)
            self._map_fd = None
        for p in reversed(self._created):
            with contextlib.suppress(OSError):
                p.rmdir() if p.is_dir() else p.unlink()
        self._created = []

    def release(self) -> None:
        if self._map_fd is not None:
            os.close(self._map_fd)  # closing releases the lock
            self._map_fd = None
        self._close_new()

    def _close_new(self) -> None:
        """Let the creation lock go, removing its file first (while still holding it: module docstring)."""
        if self._new_fd is not None:
            path = creation_lock_path(self.root)
            if _names(path, self._new_fd):
                with contextlib.suppress(OSError):
                    path.unlink()
            os.close(self._new_fd)
            self._new_fd = None
