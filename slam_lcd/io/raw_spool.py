"""Undecoded messages kept on disk during a run, to be copied into an output log afterwards.

Why: ``corrected.mcap`` carries the input log's topics (all but images by default) next to
the corrected trajectory, and the trajectory is known only at the end. Reading those topics
again then meant decompressing the whole log a second time: on the 2-lap demo 1.4 s of the
3.5 s the outputs took, almost all for image chunks the copy does not want; an hour-long log
decompresses for minutes. The run's one pass over the log hands the wanted topics' bytes to
a :class:`RawSpool` (:meth:`slam_lcd.io.reader.LogReader.messages` with ``raw_sink``) that
appends them to a file in the output's staging folder, so memory stays bounded; the writer
then reads them back in the order they came (log-time order).

The file is private to one run: a record is ``topic index (u32), log time (i64 ns), length
(u32)`` and the bytes; the topic table stays in memory. :attr:`complete` says whether the pass
reached the end of the log (an interrupted run's spool ends early and is not used).
"""
from __future__ import annotations

import struct
from collections.abc import Iterator
from pathlib import Path

from .log_backend import RawMessage

_HEAD = struct.Struct("<IqI")


class RawSpool:
    """Append-only file of :class:`RawMessage` records; iterate it after :meth:`finish`."""

    def __init__(self, path: str | Path, topics):
        self.path = Path(path)
        self.wanted = list(topics)  # the topics the pass hands over
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._topics: dict[str, int] = {}
        self._names: list[tuple[str, str]] = []  # index -> (topic, msgtype)
        self._fh = open(self.path, "wb", buffering=1 << 20)
        self.count = 0
        self.complete = False

    def add(self, m: RawMessage) -> None:
        i = self._topics.get(m.topic)
        if i is None:
            i = self._topics[m.topic] = len(self._names)
            self._names.append((m.topic, m.msgtype))
        self._fh.write(_HEAD.pack(i, int(m.log_time), len(m.data)))
        self._fh.write(m.data)
        self.count += 1

    def finish(self, complete: bool) -> None:
        """Stop writing; ``complete``: the pass read the log to its end."""
        if not self._fh.closed:
            self._fh.close()
        self.complete = bool(complete)

    def topics(self) -> list[str]:
        return [t for t, _ in self._names]

    def __iter__(self) -> Iterator[RawMessage]:
        if not self._fh.closed:
            raise RuntimeError("RawSpool: finish() before reading it back")
        names = self._names
        with open(self.path, "rb", buffering=1 << 20) as fh:
            while True:
                head = fh.read(_HEAD.size)
                if not head:
                    return
                if len(head) != _HEAD.size:
                    raise OSError(f"{self.path}: spool ends inside a record")
                i, t, n = _HEAD.unpack(head)
                data = fh.read(n)
                if len(data) != n:
                    raise OSError(f"{self.path}: spool ends inside a record")
                topic, msgtype = names[i]
                yield RawMessage(topic, msgtype, t, data)

    def discard(self) -> None:
        if not self._fh.closed:
            self._fh.close()
        self.path.unlink(missing_ok=True)
