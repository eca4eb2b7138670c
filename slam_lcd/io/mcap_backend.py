"""MCAP files: through rosbags when it can take them, else through the ``mcap`` library.

The ``mcap`` library reads complete files of any ROS profile (cdr or ros1 encoding) by
their index, and a truncated file (no footer) by a forward scan that recovers what it holds.
"""
from __future__ import annotations

import logging
import struct
from pathlib import Path

from ..errors import CorruptLogError, TruncatedLogError, UnsupportedFormatError
from .config import IOConfig
from .log_backend import (
    TF_TYPE,
    LogContents,
    RawMessage,
    TopicInfo,
    build_typestore,
    deserialised,
    error_text,
    has_header,
    unreadable,
    with_raw_copies,
)
from .mcap_recover import Channel, Message, ScanEnd, Schema, scan
from .rosbags_backend import RosbagsBackend

log = logging.getLogger(__name__)

MCAP_MAGIC = b"\x89MCAP0\r\n"


def mcap_profile_and_complete(path: Path) -> tuple[str, bool]:
    """(profile, has footer magic) of an MCAP file, read from its first and last bytes."""
    with open(path, "rb") as fh:
        head = fh.read(8 + 1 + 8 + 4 + 64)
        fh.seek(0, 2)
        size = fh.tell()
        tail = b""
        if size >= 8 + 37:
            fh.seek(size - 8)
            tail = fh.read(8)
    profile = ""
    if len(head) >= 21 and head[8] == 0x01:
        (n,) = struct.unpack_from("<I", head, 17)
        profile = head[21 : 21 + n].decode("utf-8", "replace")
    return profile, tail == MCAP_MAGIC


def open_mcap(path: Path, conf: IOConfig):
    """The backend for an MCAP file (rosbags for complete ros2 files, else :class:`McapStreamBackend`)."""
    profile, complete = mcap_profile_and_complete(path)
    if not complete:
        if conf.on_truncated == "error":
            raise TruncatedLogError("MCAP file is truncated (no footer); refusing it (io.on_truncated=error)", path)
        return McapStreamBackend(path, truncated=True)
    if profile == "ros2":
        try:
            return RosbagsBackend(path, "mcap", conf)
        except CorruptLogError:
            log.debug("rosbags could not open %s; trying the mcap library", path)
    return McapStreamBackend(path, truncated=False)


class McapStreamBackend:
    """MCAP through the ``mcap`` library (see the module docstring); :attr:`contents` is what it holds."""

    def __init__(self, path: Path, truncated: bool):
        self.path = path
        self.truncated = truncated
        self.fh = open(path, "rb")
        self.schemas: dict[int, object] = {}
        self.channels: dict[int, object] = {}
        self.end_reason = ""
        self.contents = LogContents()
        counts: dict[int, int] = {}
        start, end = None, None
        if truncated:
            n, monotone, last = 0, True, -1
            for rec in self._scan():
                cid = rec.channel_id
                counts[cid] = counts.get(cid, 0) + 1
                t = rec.log_time
                start = t if start is None else min(start, t)
                end = t if end is None else max(end, t)
                monotone &= t >= last
                last = t
                n += 1
            self.contents.truncated = True
            self.contents.recovered = n
            order = "" if monotone else "; messages are not in time order and are yielded in file order"
            log.warning(
                "%s: file is truncated (%s); recovered %d readable messages on %d topics%s",
                path, self.end_reason, n, len(counts), order,
            )
        else:
            from mcap.reader import make_reader

            try:
                self.mreader = make_reader(self.fh)
                summary = self.mreader.get_summary()
            except Exception as e:  # the mcap library raises many kinds of errors on bad bytes
                self.fh.close()
                raise CorruptLogError(f"cannot open MCAP file ({error_text(e)})", path) from None
            if summary is None:
                self.fh.close()
                raise CorruptLogError("MCAP file has no summary section", path)
            self.schemas = dict(summary.schemas)
            self.channels = dict(summary.channels)
            if summary.statistics is not None:
                counts = dict(summary.statistics.channel_message_counts)
                if summary.statistics.message_count:
                    start, end = summary.statistics.message_start_time, summary.statistics.message_end_time
        self._setup(counts, start, end)

    def _scan(self):
        """Forward scan of all message records; stops quietly where the readable bytes end."""
        for rec in scan(self.fh):
            if isinstance(rec, Message):
                if rec.channel_id in self.channels:
                    yield rec
            elif isinstance(rec, Schema):
                self.schemas[rec.id] = rec
            elif isinstance(rec, Channel):
                self.channels[rec.id] = rec
            elif isinstance(rec, ScanEnd):
                self.end_reason = rec.reason

    def _setup(self, counts, start, end):
        from rosbags.interfaces import Connection, MessageDefinition, MessageDefinitionFormat

        from .typestores import ros1_store, ros2_store

        path, c = self.path, self.contents
        encodings = {ch.message_encoding for ch in self.channels.values()}
        bad = encodings - {"cdr", "ros1"}
        if bad:
            raise UnsupportedFormatError(f"MCAP message encoding(s) {sorted(bad)} not supported (only cdr and ros1)",
                                         path)
        if len(encodings) > 1:
            raise UnsupportedFormatError("MCAP file mixes cdr and ros1 message encodings", path)
        self.ros1 = encodings == {"ros1"}
        fmts = {"ros2msg": MessageDefinitionFormat.MSG, "ros1msg": MessageDefinitionFormat.MSG,
                "ros2idl": MessageDefinitionFormat.IDL}
        pseudo = []
        for ch in self.channels.values():
            sc = self.schemas.get(ch.schema_id)
            if sc is None:
                raise CorruptLogError(f"channel {ch.topic!r} has no schema", path)
            fmt = fmts.get(sc.encoding, MessageDefinitionFormat.NONE)
            data = sc.data.decode("utf-8", "replace") if isinstance(sc.data, (bytes, bytearray)) else sc.data
            pseudo.append(Connection(ch.id, ch.topic, _normalise_type(sc.name), MessageDefinition(fmt, data), "", 0,
                                     None, None))
        store = build_typestore(pseudo, ros1_store() if self.ros1 else ros2_store(), path)
        c.typestore = store
        self.deser = store.deserialize_ros1 if self.ros1 else store.deserialize_cdr
        self.meta = {}
        for x in pseudo:
            self.meta[x.id] = (x.topic, x.msgtype, has_header(store, x.msgtype), x.msgtype == TF_TYPE)
            prev = c.topics.get(x.topic)
            n = counts.get(x.id, 0) + (prev.count if prev else 0)
            c.topics[x.topic] = TopicInfo(x.topic, x.msgtype, n)
            c.conns.setdefault(x.topic, []).append(x.id)
        if start is not None:
            c.start_ns, c.end_ns = int(start), int(end)

    def _records(self, names):
        ids = {cid for n in names for cid in self.contents.conns[n]}
        if self.truncated:
            for rec in self._scan():
                if rec.channel_id in ids:
                    yield rec.channel_id, rec.log_time, rec.data
        else:
            topics = list(names)
            last = None
            try:
                for _sc, ch, msg in self.mreader.iter_messages(topics=topics, log_time_order=True):
                    last = msg.log_time
                    yield ch.id, msg.log_time, msg.data
            except Exception as e:  # the mcap library raises many kinds of errors on damaged bytes
                raise unreadable(self.path, e, last) from None

    def raw(self, names):
        meta = self.meta
        for cid, t, data in self._records(names):
            m = meta[cid]
            yield RawMessage(m[0], m[1], t, data)

    def messages(self, names, use_header, raw_names=(), raw_sink=None):
        meta = self.meta

        def records(topics):
            return ((meta[cid], t, data) for cid, t, data in self._records(topics))

        yield from deserialised(self.path, with_raw_copies(records, names, raw_names, raw_sink), self.deser, use_header)

    def close(self):
        self.fh.close()


def _normalise_type(name: str) -> str:
    """'pkg/Type' (ROS1 style) -> 'pkg/msg/Type'."""
    parts = name.split("/")
    return f"{parts[0]}/msg/{parts[1]}" if len(parts) == 2 else name
