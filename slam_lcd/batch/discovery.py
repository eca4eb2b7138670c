"""Which logs a batch runs, and the folder name each one's outputs get.

Each argument is one of:

- a path to a log (ROS1 ``.bag``, ``.mcap``, a rosbag2 folder): taken as given, even when it
  does not exist or is not a log, so that it becomes an error row naming it (the others go on);
- a folder that is not a rosbag2 folder: the logs directly inside it (not recursive: a
  batch's own output folder may sit below it and hold ``corrected.mcap`` files);
- a glob pattern (``logs/*.bag``, ``fleet/**/*.mcap``): the log-like entries it matches; a
  pattern that matches no log is an error before any work (a typo, not a failing log).

Output names are the log's name without its suffix (``drive_03.bag`` -> ``drive_03``). Logs
of the same name in different folders (``day1/log.bag``, ``day2/log.bag``) get the folder
names in front until the names differ (``day1__log``, ``day2__log``), so no log's outputs
overwrite another's.
"""
from __future__ import annotations

import glob
import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

from ..errors import InputError

LOG_SUFFIXES = (".bag", ".mcap", ".db3")
# names the batch itself writes into --out: a log may not take them as its folder name
RESERVED_NAMES = ("summary.csv", "summary.md", "ate_before_after.png", "PARTIAL.txt")
_GLOB_CHARS = re.compile(r"[*?\[]")


@dataclass(frozen=True)
class LogEntry:
    """One log of the batch: where it is, and its output folder name inside ``--out``."""

    path: Path
    name: str


def is_log_like(path: Path) -> bool:
    """A file with a log suffix, or a rosbag2 folder (one holding metadata.yaml)."""
    if path.is_dir():
        return (path / "metadata.yaml").is_file()
    return path.suffix.lower() in LOG_SUFFIXES


def expand_log_args(args: Iterable[str | Path]) -> list[Path]:
    """The logs named by ``args`` (see the module docstring), in the order given, each once."""
    found: list[Path] = []
    for arg in args:
        text = str(arg)
        p = Path(text).expanduser()
        if _GLOB_CHARS.search(text) and not p.exists():
            matches = [Path(m) for m in sorted(glob.glob(str(p), recursive=True))]
            logs = [m for m in matches if is_log_like(m)]
            if not logs:
                what = f"{len(matches)} entries, none a log" if matches else "nothing"
                raise InputError(f"pattern matches {what} (logs: {', '.join(LOG_SUFFIXES)} files and "
                                 "rosbag2 folders)", text)
            found += logs
        elif p.is_dir() and not is_log_like(p):
            logs = sorted(c for c in p.iterdir() if is_log_like(c) and not c.name.startswith("."))
            if not logs:
                raise InputError("folder holds no log (no .bag/.mcap file, no rosbag2 folder) and is not a "
                                 "rosbag2 folder itself", p)
            found += logs
        else:
            found.append(p)
    unique: dict[Path, Path] = {}
    for p in found:
        unique.setdefault(p.resolve(), p)
    return list(unique.values())


def _stem(path: Path) -> str:
    name = path.name.rstrip("/")
    for suffix in LOG_SUFFIXES:
        if name.lower().endswith(suffix) and len(name) > len(suffix):
            return name[: -len(suffix)]
    return name


def output_names(paths: Sequence[Path]) -> list[str]:
    """One distinct folder name per log (see the module docstring)."""
    parts = [[*(_safe(x) for x in p.resolve().parent.parts[1:]), _safe(_stem(p))] for p in paths]
    depth = [1] * len(paths)
    while True:
        names = ["__".join(pp[-d:]) for pp, d in zip(parts, depth, strict=True)]
        seen: dict[str, list[int]] = {}
        for i, n in enumerate(names):
            seen.setdefault(n, []).append(i)
        clashes = [ix for ix in seen.values() if len(ix) > 1]
        if not clashes:
            break
        grew = False
        for ix in clashes:
            for i in ix:
                if depth[i] < len(parts[i]):
                    depth[i] += 1
                    grew = True
        if not grew:  # the same path twice cannot happen (deduplicated); be safe anyway
            names = [f"{n}__{i}" for i, n in enumerate(names)]
            break
    return [f"{n}_log" if n in RESERVED_NAMES or n.startswith(".") else n for n in names]


def _safe(part: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.+-]", "_", part) or "_"


def discover_logs(args: Iterable[str | Path]) -> list[LogEntry]:
    """The batch's logs with their output names; an empty list of arguments is an InputError."""
    paths = expand_log_args(args)
    if not paths:
        raise InputError("no log given: name logs, folders of logs or glob patterns")
    return [LogEntry(p, n) for p, n in zip(paths, output_names(paths), strict=True)]


def ground_truth_in(gt_dir: Path, entry: LogEntry) -> Path | None:
    """The ground-truth file of a log in ``gt_dir``: ``<output name>.<suffix>``, else
    ``<log name without suffix>.<suffix>`` (any trajectory suffix; logs are never taken), or None.

    Several candidates (``a.tum`` and ``a.txt``) are an InputError naming them: which one
    is meant is not ours to guess.
    """
    for name in dict.fromkeys([entry.name, _stem(entry.path)]):
        cands = sorted(c for c in Path(gt_dir).glob(f"{glob.escape(name)}.*")
                       if c.is_file() and c.suffix.lower() not in LOG_SUFFIXES)
        if cands:
            break
    if len(cands) > 1:
        raise InputError(f"several ground-truth files for log {name!r}: {', '.join(c.name for c in cands)}; "
                         "keep one", gt_dir)
    return cands[0] if cands else None
