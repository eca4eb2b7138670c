"""Streaming reader of robot logs: ROS1 bags, rosbag2 directories (sqlite3/mcap) and MCAP files.

``open_log(path)`` detects the format from the bytes (not the suffix), opens it with
rosbags (:mod:`.rosbags_backend`; or, for MCAP files that rosbags cannot take -- truncated
files, non-ros2 profiles -- with the ``mcap`` library, :mod:`.mcap_backend`) and streams
messages in log-time order without loading the file. This module is the facade: the
backends return what they found (:class:`~slam_lcd.io.log_backend.LogContents`). The layer
over rosbags is kept thin on purpose: per message it deserialises with rosbags and reads
the header stamp, nothing else (see tools/bench_io.py for the cost).
"""
from __future__ import annotations

from collections.abc import Iterable, Iterator
from pathlib import Path

from ..errors import FileMissingError, TopicNotFoundError, UnsupportedFormatError
from .config import IOConfig
from .log_backend import LogBackend, LogContents, LogMessage, RawMessage, TopicInfo
from .mcap_backend import MCAP_MAGIC, open_mcap
from .rosbags_backend import RosbagsBackend

__all__ = ["LogMessage", "LogReader", "RawMessage", "TopicInfo", "detect_log_format", "open_log"]

ROSBAG1_MAGIC = b"#ROSBAG V2.0\n"
SQLITE_MAGIC = b"SQLite format 3\x00"


def detect_log_format(path: Path) -> tuple[str, str]:
    """(format, storage) of a log from its leading bytes: ('rosbag1'|'rosbag2'|'mcap', storage)."""
    if not path.exists():
        raise FileMissingError("no such file or directory", path)
    if path.is_dir():
        meta = path / "metadata.yaml"
        if not meta.is_file():
            raise UnsupportedFormatError("folder has no metadata.yaml, so it is not a rosbag2 directory", path)
        storage = "unknown"
        try:
            import yaml

            info = yaml.safe_load(meta.read_text(encoding="utf-8"))["rosbag2_bagfile_information"]
            storage = str(info.get("storage_identifier", "unknown"))
        except Exception:  # rosbags reports a damaged metadata.yaml precisely when opening
            pass
        return "rosbag2", storage
    try:
        with open(path, "rb") as fh:
            head = fh.read(16)
    except OSError as e:
        raise FileMissingError(f"cannot read ({e.strerror})", path) from None
    if head.startswith(MCAP_MAGIC):
        return "mcap", "mcap"
    if head.startswith(ROSBAG1_MAGIC):
        return "rosbag1", "rosbag1"
    if head.startswith(SQLITE_MAGIC):
        if path.suffix != ".db3":
            raise UnsupportedFormatError("an SQLite file that is not a rosbag2 .db3 storage file", path)
        return "rosbag2", "sqlite3"
    if not head:
        raise UnsupportedFormatError("file is empty, not a ROS bag or MCAP file", path)
    raise UnsupportedFormatError(
        f"not a ROS1 bag, rosbag2 or MCAP file (starts with {head[:12]!r})", path
    )


class LogReader:
    """An open log. Use :func:`open_log`; see the module docstring and docs/io.md."""

    def __init__(self, path: str | Path, stamp_source: str = "header", conf: IOConfig | None = None):
        self.path = Path(path)
        self.conf = conf or IOConfig()
        if stamp_source not in ("header", "log_time"):
            raise ValueError(f"stamp_source must be 'header' or 'log_time', not {stamp_source!r}")
        self.stamp_source = stamp_source
        self.format, self.storage = detect_log_format(self.path)
        self._backend: LogBackend | None = None
        self._contents = LogContents()

    # -- life cycle ---------------------------------------------------------------------
    def open(self) -> LogReader:
        if self.format == "mcap":
            self._backend = open_mcap(self.path, self.conf)
        else:
            self._backend = RosbagsBackend(self.path, self.format, self.conf)
        self._contents = self._backend.contents
        return self

    def close(self) -> None:
        if self._backend is not None:
            self._backend.close()
            self._backend = None

    def __enter__(self):
        if self._backend is None:
            self.open()
        return self

    def __exit__(self, *exc):
        self.close()
        return False

    # -- metadata (what the backend found) -----------------------------------------------
    @property
    def topics(self) -> dict[str, TopicInfo]:
        return dict(self._contents.topics)

    @property
    def message_count(self) -> int:
        return self._contents.message_count

    @property
    def typestore(self):
        return self._contents.typestore

    @property
    def start_ns(self) -> int:
        return self._contents.start_ns

    @property
    def end_ns(self) -> int:
        return self._contents.end_ns

    @property
    def truncated(self) -> bool:
        return self._contents.truncated

    @property
    def recovered(self) -> int:
        """Messages recovered from a truncated file."""
        return self._contents.recovered

    @property
    def duration_ns(self) -> int:
        return max(0, self.end_ns - self.start_ns) if self.message_count else 0

    def resolve_topics(self, topics: Iterable[str] | str | None, *, flag: str | None = None,
                       hint: str | None = None) -> list[str]:
        """Topic names present in the log; a leading '/' may be added or left out. Unknown -> error
        (naming ``flag``, the flag that gave the topics, and ``hint``, how else to supply them)."""
        if topics is None:
            return list(self._contents.topics)
        if isinstance(topics, str):
            topics = [topics]
        out = []
        for t in topics:
            if t in self._contents.topics:
                out.append(t)
                continue
            alt = t[1:] if t.startswith("/") else "/" + t
            if alt in self._contents.topics:
                out.append(alt)
            else:
                raise TopicNotFoundError(t, self._contents.topics, self.path, flag=flag, hint=hint)
        return list(dict.fromkeys(out))  # each topic once, in the order given

    def topics_of_type(self, *msgtypes: str) -> list[str]:
        return [t.name for t in self._contents.topics.values() if t.msgtype in msgtypes]

    # -- streaming ----------------------------------------------------------------------
    def raw_messages(self, topics: Iterable[str] | str | None = None) -> Iterator[RawMessage]:
        """``RawMessage(topic, msgtype, log_time, data)`` in log-time order, without deserialising."""
        names = self.resolve_topics(topics)
        if not names:
            return iter(())
        assert self._backend is not None, "the log is not open (open_log)"
        return self._backend.raw(names)

    def messages(self, topics: Iterable[str] | str | None = None, *, raw_topics: Iterable[str] | None = None,
                 raw_sink=None) -> Iterator[LogMessage]:
        """Deserialised messages of ``topics`` (default all) in log-time order, streaming.

        ``raw_topics`` with ``raw_sink``: the messages of those topics are also handed, undecoded,
        to ``raw_sink(RawMessage)`` as the same pass reaches them (what ``run`` copies into
        ``corrected.mcap``: the log is decompressed once, not twice)."""
        names = self.resolve_topics(topics)
        raw = self.resolve_topics(raw_topics) if raw_sink is not None and raw_topics else []
        if not names and not raw:
            return iter(())
        assert self._backend is not None, "the log is not open (open_log)"
        return self._backend.messages(names, self.stamp_source == "header", raw, raw_sink if raw else None)

    def deserialise(self, raw: RawMessage):
        """The message object of a :class:`RawMessage` read from this log."""
        assert self._backend is not None, "the log is not open (open_log)"
        return self._backend.deser(raw.data, raw.msgtype)

    def __repr__(self):
        return f"LogReader({str(self.path)!r}, format={self.format!r}, topics={len(self._contents.topics)})"



def open_log(path: str | Path, stamp_source: str = "header", conf: IOConfig | None = None) -> LogReader:
    """Open a ROS1 ``.bag``, a rosbag2 directory (or its .db3/.mcap file) or an ``.mcap`` file."""
    if conf is not None and stamp_source == "header":
        stamp_source = conf.stamp_source
    return LogReader(path, stamp_source, conf).open()
