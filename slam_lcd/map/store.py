"""The map folder on disk: a manifest, one file per session, one file for the joint graph.

Layout (``schema`` 1)::

    DIR/map.json                  manifest: schema, feature kind, sessions table, files with sha256
    DIR/sessions/NNNN-<tag>.npz   one session's keyframes (again under a new name when views of it drop)
    DIR/graph-<tag>.npz           loops of every session and the map-frame keyframe poses
    DIR/vocab-<tag>.npz           the online vocabulary and every keyframe's bag of words (optional)
    DIR/.lock                     the writers' lock (flock; made with the first commit, slam_lcd.map.locks)

Why this shape: appending a session writes only new files (the session's keyframes and a new
graph file under a fresh name), then replaces ``map.json`` in one ``os.replace``: that rename is
the commit. Before it the map is exactly the old one (a reader only opens files the manifest
names); after it, the whole new session. Files that no manifest names (a failed append's, an
old graph; a new map's first append that never committed) are removed by the next writer, under
the lock. Every file is checked against the size and sha256 the manifest gives before it is
used, and arrays load with ``allow_pickle=False``: a truncated, tampered or foreign file is one
:class:`MapError` naming it.
"""
from __future__ import annotations

import contextlib
import json
import os
import re
import secrets
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from ..files.hashing import sha256_of
from ..files.npz import write_npz
from ..runtime.interrupts import defer_sigint
from .contents import (  # noqa: F401 - the folder's names, read and written here
    FORMAT_NAME,
    LOCK,
    MANIFEST,
    MISSING,
    SCHEMA,
    LogAlreadyInMapError,
    MapError,
    MapGraph,
    MapLockedError,
    MapManifest,
    SessionKeyframes,
)
from .locks import WriterLock
from .reader import (  # noqa: F401 - reading the folder (slam_lcd.map.reader), one face with writing it
    VOCAB_ARRAYS,
    is_map,
    open_listed,
    read_graph,
    read_manifest,
    read_session,
    read_vocab,
)


def check_map_target(root: str | Path, *, create: bool = True) -> None:
    """Refuse, without writing anything, a folder a writer cannot use as a map: a file in the way, a
    folder that holds something else than a map (or a new map's leftovers), a place that cannot be
    written (read-only, no permission). ``create``: a folder without a map is to become one."""
    root = Path(root)
    if root.exists() and not root.is_dir():
        raise MapError("a file is in the way of the map folder", root)
    if is_map(root) or not create:
        where = root if root.is_dir() else None
    else:
        if unfinished_files(root) is None:
            raise MapError("the folder is not empty and holds no map: give an empty or new folder", root)
        where = root
        while not where.exists() and where.parent != where:
            where = where.parent
    if where is not None and not os.access(where, os.W_OK | os.X_OK):
        raise MapError(f"cannot write the map here ({'read-only' if _read_only(where) else 'no permission'}"
                       f" in {where})", root)


def _read_only(path: Path) -> bool:
    try:
        return bool(os.statvfs(path).f_flag & os.ST_RDONLY)
    except OSError:
        return False


def _fsync_dir(path: Path) -> None:
    with contextlib.suppress(OSError):
        fd = os.open(path, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


# dense arrays that hardly deflate (quantised descriptors, keypoints, points, vocabulary centres):
# stored as they are; every other array of a map file is deflated (slam_lcd.files.npz)
STORED = frozenset({"keypoints", "descriptors", "scales", "points3d", "centres_q", "centres_scale", "centres_f16",
                    "proj"})


def _write_npz(path: Path, arrays: dict[str, np.ndarray]) -> dict:
    """Write arrays to ``path`` (a fresh name), fsync; returns its manifest entry. An interrupt held back
    while the archive is written (:mod:`slam_lcd.files.npz`) is raised after it, and the ``finally``
    removes the file."""
    tmp = path.with_name(f".{path.name}.tmp")
    try:
        with open(tmp, "wb") as fh:
            write_npz(fh, arrays, STORED)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    finally:
        with defer_sigint():
            tmp.unlink(missing_ok=True)
    return {"sha256": sha256_of(path), "bytes": path.stat().st_size}


@contextlib.contextmanager
def write_lock(root: Path, timeout_s: float = 60.0) -> Iterator[WriterLock]:
    """Hold the map's writer lock (:class:`slam_lcd.map.locks.WriterLock`); wait up to ``timeout_s``, then refuse.

    Nothing is created in a folder that holds no map yet: :func:`commit` makes the folder and its
    lock file when it writes the first session."""
    lock = WriterLock(root, timeout_s).acquire()
    try:
        yield lock
    finally:
        lock.release()


def remove_unlisted(root: Path, manifest: MapManifest | None) -> None:
    """Remove files of ours that the manifest does not name (a failed append's, an old graph). Under the lock."""
    keep = set(manifest.files) if manifest else set()
    for path in (list(root.glob("graph-*.npz")) + list(root.glob("vocab-*.npz"))
                 + list((root / "sessions").glob("*.npz"))
                 + list(root.glob(".*.tmp")) + list((root / "sessions").glob(".*.tmp"))):
        rel = path.relative_to(root).as_posix()
        if rel not in keep:
            with contextlib.suppress(OSError):
                path.unlink()


# the names a commit writes (see commit): nothing else is ever removed as an unfinished map's leftover
_ROOT_FILE = re.compile(r"(\.?(graph|vocab)-\d{6}-[0-9a-f]{8}\.npz(\.tmp)?|\.map\.json\.tmp)")
_SESSION_FILE = re.compile(r"\.?\d{4}-[0-9a-f]{8}\.npz(\.tmp)?")


def unfinished_files(root: Path) -> list[Path] | None:
    """What an unfinished first commit left in ``root`` (no manifest): its files; None when the folder
    holds anything else (not ours to empty). An absent or empty folder gives ``[]``."""
    if not root.is_dir() or (root / MANIFEST).exists():
        return []
    sessions = root / "sessions"
    ours: list[Path] = []
    for p in root.iterdir():
        if p.name == LOCK:
            continue
        if p == sessions and p.is_dir() and not p.is_symlink():
            inner = list(p.iterdir())
            if not all(q.is_file() and _SESSION_FILE.fullmatch(q.name) for q in inner):
                return None
            ours += inner
        elif p.is_file() and not p.is_symlink() and _ROOT_FILE.fullmatch(p.name):
            ours.append(p)
        else:
            return None
    return ours


def remove_unfinished(root: Path) -> None:
    """Empty a folder that holds only what an unfinished first commit leaves (no manifest). Under the lock.

    Why: a new map's first append that was killed before its manifest's rename leaves its session
    file, graph file or just ``sessions/`` behind; the map is then "no map", as it was before, and the
    folder must take a new one. A folder holding anything else is left alone (the caller refuses it:
    it is not ours to empty).
    """
    ours = unfinished_files(root)
    if not ours:
        return
    for p in ours:
        with contextlib.suppress(OSError):
            p.unlink()
    with contextlib.suppress(OSError):
        (root / "sessions").rmdir()


def commit(root: Path, manifest: MapManifest, new_sessions: list[tuple[dict, SessionKeyframes]], graph: MapGraph,
           sessions_table: list[dict], vocab: dict[str, np.ndarray] | None = None,
           lock: WriterLock | None = None, rewritten: dict[str, SessionKeyframes] | None = None) -> MapManifest:
    """Write new sessions' files and a new graph file, then the manifest (the commit). Hold the lock.

    ``manifest``: the one on disk (or an empty one for a new map); ``sessions_table``: every
    session's entry after the commit (new ones last, without their ``file``). A failure before
    the manifest's rename removes the files it wrote: the folder is as it was (an ``OSError``,
    such as a full disk, is raised as :class:`MapError` naming the map). ``vocab``: the online
    vocabulary's snapshot after these sessions (``vocab-<gen>-<tag>.npz``); None: the map has
    none (it is replayed when loaded), and an older one is dropped. ``lock``: the writer's lock; a
    first commit makes the folder and its lock file through it, and removes them again when it fails.
    ``rewritten``: sessions already in the map whose keyframes changed (a map that keeps places drops
    a variant's descriptors): each gets a new file under a new name, the old one goes with the commit.
    """
    if lock is None:
        return _commit(root, manifest, new_sessions, graph, sessions_table, vocab, rewritten)
    try:
        lock.before_first_write()
        new = _commit(root, manifest, new_sessions, graph, sessions_table, vocab, rewritten)
    except OSError as e:  # making the folder: one error naming the map
        lock.undo_first_write()
        raise MapError(f"cannot write the map ({e.strerror or e}); nothing was added to it", root) from e
    except BaseException:
        lock.undo_first_write()
        raise
    lock.after_first_commit()
    return new


def _commit(root: Path, manifest: MapManifest, new_sessions: list[tuple[dict, SessionKeyframes]], graph: MapGraph,
            sessions_table: list[dict], vocab: dict[str, np.ndarray] | None,
            rewritten: dict[str, SessionKeyframes] | None = None) -> MapManifest:
    tag = secrets.token_hex(4)
    files = dict(manifest.files)
    written: list[Path] = []
    (root / "sessions").mkdir(parents=True, exist_ok=True)
    table = [dict(s) for s in sessions_table]
    known = {s["name"]: s.get("file") for s in manifest.sessions}
    try:
        n_before = len(manifest.sessions)
        for i, (meta, sess) in enumerate(new_sessions):
            name = f"sessions/{n_before + i + 1:04d}-{tag}.npz"
            written.append(root / name)
            files[name] = _write_npz(root / name, sess.arrays())
            known[meta["name"]] = name
        for index, s in enumerate(table):
            if s["name"] in (rewritten or {}) and s["name"] not in {m["name"] for m, _ in new_sessions}:
                name = f"sessions/{index + 1:04d}-{tag}.npz"
                files.pop(known.get(s["name"]) or "", None)
                written.append(root / name)
                files[name] = _write_npz(root / name, rewritten[s["name"]].arrays())  # type: ignore[index]
                known[s["name"]] = name
        for s in table:
            s["file"] = known[s["name"]]
        gname = f"graph-{manifest.generation + 1:06d}-{tag}.npz"
        if manifest.graph_file:
            files.pop(manifest.graph_file, None)
        written.append(root / gname)
        files[gname] = _write_npz(root / gname, graph.arrays())
        if manifest.vocab_file:
            files.pop(manifest.vocab_file, None)
        vname = None
        if vocab is not None:
            vname = f"vocab-{manifest.generation + 1:06d}-{tag}.npz"
            written.append(root / vname)
            files[vname] = _write_npz(root / vname, {k: vocab[k] for k in VOCAB_ARRAYS})
        now = time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())
        new = MapManifest(features=manifest.features, sessions=table, graph_file=gname, vocab_file=vname, files=files,
                          created=manifest.created or now, updated=now, generation=manifest.generation + 1)
        text = json.dumps(new.to_json(), indent=1, default=_json_default)
        tmp = root / f".{MANIFEST}.tmp"
        written.append(tmp)
        with open(tmp, "w", encoding="utf-8") as fh:
            fh.write(text)
            fh.flush()
            os.fsync(fh.fileno())
        _fsync_dir(root / "sessions")
        with defer_sigint():  # the commit: the old map or the whole new one
            os.replace(tmp, root / MANIFEST)
            written.clear()
            _fsync_dir(root)
    except OSError as e:  # a full disk, a quota, a read-only folder: one error naming the map
        raise MapError(f"cannot write the map ({e.strerror or e}); nothing was added to it", root) from e
    finally:
        with defer_sigint():
            for path in written:  # not committed: leave the folder as it was
                with contextlib.suppress(OSError):
                    path.unlink()
    remove_unlisted(root, new)
    return new


def _json_default(o):
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, (np.integer,)):
        return int(o)
    if isinstance(o, (np.floating,)):
        return float(o)
    raise TypeError(f"not JSON: {type(o).__name__}")
