"""Streaming reader of robot logs: ROS1 bags, rosbag2 directories (sqlite3/mcap) and MCAP files.

``open_log(path)`` detects the format from the bytes (not the suffix), opens it with
rosbags (or, for MCAP files that rosbags cannot take -- truncated files, non-ros2 profiles --
with the ``mcap`` library) and streams messages in log-time order without loading the
file. The layer over rosbags is kept thin on purpose: per message it deserialises with
rosbags and reads the header stamp, nothing else (see tools/bench_io.py for the cost).
"""
from __future__ import annotations

import logging
import struct
from pathlib import Path
from typing import Iterable, Iterator, NamedTuple

from ..errors import (
    CorruptLogError,
    SlamLcdError,
    FileMissingError,
    TopicNotFoundError,
    TruncatedLogError,
    UnsupportedFormatError,
)
from .config import IOConfig

log = logging.getLogger(__name__)

MCAP_MAGIC = b"\x89MCAP0\r\n"
ROSBAG1_MAGIC = b"#ROSBAG V2.0\n"
SQLITE_MAGIC = b"SQLite format 3\x00"
TF_TYPE = "tf2_msgs/msg/TFMessage"
_U32 = struct.Struct("<I")

class TopicInfo(NamedTuple):
    name: str
    msgtype: str  # e.g. 'sensor_msgs/msg/Image'
    count: int

class RawMessage(NamedTuple):
    topic: str
    msgtype: str
    log_time: int  # ns
    data: bytes | memoryview  # serialised (CDR, or ROS1 wire format for ROS1 logs)


class LogMessage(NamedTuple):
    topic: str
    msgtype: str
    stamp: int  # ns, from the header (fallback: log time)
    log_time: int  # ns, when the message was recorded
    msg: object  # rosbags message object

def detect_format(path: Path) -> tuple[str, str]:
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

def _build_typestore(connections, default_store, path):
    """Type store from the definitions embedded in the log, completed by a default store."""
    from rosbags.interfaces import MessageDefinitionFormat
    from rosbags.typesys import Stores, get_types_from_idl, get_types_from_msg, get_typestore
    from rosbags.typesys.base import TypesysError

    typs: dict = {}
    try:
        for c in connections:
            fmt, data = c.msgdef.format, c.msgdef.data
            if fmt == MessageDefinitionFormat.MSG:
                typs.update(get_types_from_msg(data, c.msgtype))
            elif fmt == MessageDefinitionFormat.IDL:
                sep = "=" * 80 + "\n"
                if data.startswith(f"{sep}IDL: "):
                    for part in data.split(sep)[1:]:
                        typs.update(get_types_from_idl(part.split("\n", 1)[1]))
                else:
                    typs.update(get_types_from_idl(data))
    except (TypesysError, ValueError, IndexError) as e:
        raise CorruptLogError(f"embedded message definition cannot be parsed ({e})", path) from None
    # complete with the default store's definitions of the types the log does not describe
    # (and what they use), registering only those: registering a whole store costs ~0.2 s
    need = [c.msgtype for c in connections if c.msgtype not in typs]
    while need:
        name = need.pop()
        if name in typs or name not in default_store.fielddefs:
            continue
        typs[name] = default_store.fielddefs[name]
        need.extend(_used_types(typs[name]))
    store = get_typestore(Stores.EMPTY)
    store.register(typs)
    return store

def _used_types(fielddef) -> list[str]:
    """Names of the message types a rosbags field definition refers to."""
    from rosbags.typesys.base import Nodetype

    out = []
    for _, desc in fielddef[1]:
        node, arg = desc
        if node in (Nodetype.SEQUENCE, Nodetype.ARRAY):
            node, arg = arg[0]
        if node == Nodetype.NAME:
            out.append(arg)
    return out


class LogReader:
    """An open log. Use :func:`open_log`; see the module docstring and docs/io.md."""

    def __init__(self, path: str | Path, stamp_source: str = "header", conf: IOConfig | None = None):
        self.path = Path(path)
        self.conf = conf or IOConfig()
        if stamp_source not in ("header", "log_time"):
            raise ValueError(f"stamp_source must be 'header' or 'log_time', not {stamp_source!r}")
        self.stamp_source = stamp_source
        self.format, self.storage = detect_format(self.path)
        self.truncated = False
        self.recovered = 0  # messages recovered from a truncated file
        self._backend = None
        self.typestore = None
        self._topics: dict[str, TopicInfo] = {}
        self._conns: dict[str, list] = {}  # topic -> backend connection handles
        self.start_ns = 0
        self.end_ns = 0

    # -- life cycle ---------------------------------------------------------------------
    def open(self) -> "LogReader":
        if self.format == "mcap":
            self._backend = _open_mcap(self)
        else:
            self._backend = _RosbagsBackend(self)
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

    # -- metadata -----------------------------------------------------------------------
    @property
    def topics(self) -> dict[str, TopicInfo]:
        return dict(self._topics)

    @property
    def message_count(self) -> int:
        return sum(t.count for t in self._topics.values())

    @property
    def duration_ns(self) -> int:
        return max(0, self.end_ns - self.start_ns) if self.message_count else 0

    def resolve_topics(self, topics: Iterable[str] | str | None) -> list[str]:
        """Topic names present in the log; a leading '/' may be added or left out. Unknown -> error."""
        if topics is None:
            return list(self._topics)
        if isinstance(topics, str):
            topics = [topics]
        out = []
        for t in topics:
            if t in self._topics:
                out.append(t)
                continue
            alt = t[1:] if t.startswith("/") else "/" + t
            if alt in self._topics:
                out.append(alt)
            else:
                raise TopicNotFoundError(t, self._topics, self.path)
        return list(dict.fromkeys(out))  # each topic once, in the order given

    def topics_of_type(self, *msgtypes: str) -> list[str]:
        return [t.name for t in self._topics.values() if t.msgtype in msgtypes]

    # -- streaming ----------------------------------------------------------------------
    def raw_messages(self, topics: Iterable[str] | str | None = None) -> Iterator[RawMessage]:
        """``RawMessage(topic, msgtype, log_time, data)`` in log-time order, without deserialising."""
        names = self.resolve_topics(topics)
        if not names:
            return iter(())
        return self._backend.raw(names)

    def messages(self, topics: Iterable[str] | str | None = None) -> Iterator[LogMessage]:
        """Deserialised messages of ``topics`` (default all) in log-time order, streaming."""
        names = self.resolve_topics(topics)
        if not names:
            return iter(())
        return self._backend.messages(names, self.stamp_source == "header")

    def __repr__(self):
        return f"LogReader({str(self.path)!r}, format={self.format!r}, topics={len(self._topics)})"

def open_log(path: str | Path, stamp_source: str = "header", conf: IOConfig | None = None) -> LogReader:
    """Open a ROS1 ``.bag``, a rosbag2 directory (or its .db3/.mcap file) or an ``.mcap`` file."""
    if conf is not None and stamp_source == "header":
        stamp_source = conf.stamp_source
    return LogReader(path, stamp_source, conf).open()

# ---- stamps -------------------------------------------------------------------------------

def _has_header(store, msgtype: str) -> bool:
    fields = store.fielddefs.get(msgtype, (None, []))[1]
    return bool(fields) and fields[0][0] == "header"

def _header_stamp(msg, has_header: bool, is_tf: bool, log_time: int) -> int:
    if has_header:
        st = msg.header.stamp
        s = st.sec * 1_000_000_000 + st.nanosec
        return s if s > 0 else log_time
    if is_tf and msg.transforms:
        st = msg.transforms[0].header.stamp
        s = st.sec * 1_000_000_000 + st.nanosec
        return s if s > 0 else log_time
    return log_time

def _deserialised(reader, records, deser, use_header: bool):
    """LogMessages from ``(meta, log_time, bytes)`` records, ``meta = (topic, msgtype, has_header, is_tf)``.

    Shared by both backends: a message that cannot be decoded is a one-line CorruptLogError.
    """
    from rosbags.serde import SerdeError

    for (topic, msgtype, has_header, is_tf), t, data in records:
        try:
            msg = deser(data, msgtype)
        except (SerdeError, KeyError, ValueError) as e:
            raise _deser_error(reader, topic, e) from None
        stamp = _header_stamp(msg, has_header, is_tf, t) if use_header else t
        yield LogMessage(topic, msgtype, stamp, t, msg)


def _deser_error(reader, topic, e):
    return CorruptLogError(f"message on topic {topic!r} cannot be decoded ({e})", reader.path)

# ---- rosbags backend (ROS1 bags, rosbag2 directories/files, indexed ros2 MCAP) ---------------

class _RosbagsBackend:
    def __init__(self, reader: LogReader):
        from rosbags.rosbag1 import Reader as Reader1
        from rosbags.rosbag1 import ReaderError as ReaderError1
        from rosbags.rosbag2 import Reader as Reader2
        from rosbags.rosbag2 import ReaderError as ReaderError2

        from .typestores import ros1_store, ros2_store

        self.reader = reader
        self.errors = (ReaderError1, ReaderError2)
        self.ros1 = reader.format == "rosbag1"
        try:
            self.bag = Reader1(reader.path) if self.ros1 else Reader2(reader.path)
            self.bag.open()
        except self.errors as e:
            raise CorruptLogError(f"cannot open {reader.format} log ({_one_line(e)})", reader.path) from None
        except (KeyError, ValueError, TypeError, OSError, IndexError) as e:
            raise CorruptLogError(f"cannot open {reader.format} log ({type(e).__name__}: {_one_line(e)})", reader.path) from None
        conns = list(self.bag.connections)
        store = _build_typestore(conns, ros1_store() if self.ros1 else ros2_store(), reader.path)
        reader.typestore = store
        self.deser = store.deserialize_ros1 if self.ros1 else store.deserialize_cdr
        by_topic: dict[str, list] = {}
        for c in conns:
            by_topic.setdefault(c.topic, []).append(c)
        for topic, cs in by_topic.items():
            types = {c.msgtype for c in cs}
            if len(types) > 1:
                log.warning("%s: topic %s carries several types %s; using %s", reader.path, topic, sorted(types), cs[0].msgtype)
            reader._topics[topic] = TopicInfo(topic, cs[0].msgtype, sum(max(c.msgcount, 0) for c in cs))
            reader._conns[topic] = cs
        if reader.message_count:
            reader.start_ns = int(self.bag.start_time)
            reader.end_ns = int(self.bag.end_time) - 1  # rosbags' end_time is one past the last message
        # per connection: (topic, msgtype, has_header, is_tf)
        self.meta = {
            id(c): (c.topic, c.msgtype, _has_header(store, c.msgtype), c.msgtype == TF_TYPE) for c in conns
        }

    def _conns(self, names):
        return [c for n in names for c in self.reader._conns[n]]

    def _stream(self, names):
        conns = self._conns(names)
        if self.ros1:
            return _ros1_messages(self.bag, conns, self.reader.conf.rosbag1_chunk_cache_mb << 20, self.reader.path)
        return self.bag.messages(connections=conns)

    def raw(self, names):
        meta = self.meta
        last = [None]
        try:
            for c, t, data in self._stream(names):
                m = meta[id(c)]
                last[0] = t
                yield RawMessage(m[0], m[1], t, data)
        except SlamLcdError:
            raise
        except Exception as e:  # rosbags, zstd/lz4 and struct raise many kinds on damaged bytes
            raise _unreadable(self.reader, e, last[0]) from None

    def messages(self, names, use_header):
        meta = self.meta
        last = [None]

        def records():
            for c, t, data in self._stream(names):
                last[0] = t
                yield meta[id(c)], t, data

        try:
            yield from _deserialised(self.reader, records(), self.deser, use_header)
        except SlamLcdError:
            raise
        except Exception as e:  # rosbags, zstd/lz4 and struct raise many kinds on damaged bytes
            raise _unreadable(self.reader, e, last[0]) from None

    def close(self):
        try:
            self.bag.close()
        except Exception:  # closing a reader that failed half-way must not mask the real error
            pass

def _ros1_record(buf: bytes, off: int) -> tuple[dict, int, int]:
    """(header fields, data start, data length) of the ROS1 bag record at ``off``."""
    (hlen,) = _U32.unpack_from(buf, off)
    p, end = off + 4, off + 4 + hlen
    fields = {}
    while p < end:
        (flen,) = _U32.unpack_from(buf, p)
        key, _, val = buf[p + 4 : p + 4 + flen].partition(b"=")
        fields[key] = val
        p += 4 + flen
    (dlen,) = _U32.unpack_from(buf, end)
    return fields, end + 4, dlen

def _ros1_messages(bag, connections, cache_bytes: int, path):
    """Messages of a rosbags ROS1 reader in time order, keeping each decompressed chunk only
    until its last message in that order has been yielded (bounded by ``cache_bytes``).
    rosbags itself re-reads a chunk whenever consecutive messages live in different chunks,
    which made bags whose chunks overlap in time (e.g. ROS_example.bag) ~20x slower."""
    import heapq

    connmap = {c.id: c for c in bag.connections}
    entries = list(heapq.merge(*[bag.indexes[c.id] for c in connections]))
    last_use = {e.chunk_pos: i for i, e in enumerate(entries)}
    cache: dict[int, bytes] = {}  # insertion order = least recently loaded first
    held = 0
    bio = bag.bio
    for i, entry in enumerate(entries):
        pos = entry.chunk_pos
        buf = cache.get(pos)
        if buf is None:
            ch = bag.chunks[pos]
            bio.seek(ch.datapos)
            raw = bio.read(ch.datasize)
            if len(raw) != ch.datasize:
                raise CorruptLogError("ROS1 bag ends inside a chunk (truncated file)", path)
            buf = ch.decompressor(raw)
            del raw
            while cache and held + len(buf) > cache_bytes:
                held -= len(cache.pop(next(iter(cache))))
            cache[pos] = buf
            held += len(buf)
        off = entry.offset
        while True:
            fields, dstart, dlen = _ros1_record(buf, off)
            if fields.get(b"op") != b"\x07":
                break
            off = dstart + dlen
        if fields.get(b"op") != b"\x02":
            raise CorruptLogError(f"ROS1 bag index points at a non-message record in chunk {pos}", path)
        (cid,) = _U32.unpack_from(fields[b"conn"])
        if last_use[pos] == i:  # no later message in this chunk: let it go
            held -= len(cache.pop(pos))
        yield connmap[cid], entry.time, memoryview(buf)[dstart : dstart + dlen]
        buf = None


def _one_line(e) -> str:
    return " ".join(str(e).split()) or type(e).__name__


def _unreadable(reader, e: Exception, last_log_time: int | None) -> CorruptLogError:
    """A one-line error for bytes that cannot be read (damaged chunk, bad compression, short file)."""
    from ..errors import stamp_text

    where = (f"after log time {stamp_text(last_log_time)}" if last_log_time is not None
             else "before its first readable message")
    kind = type(e).__name__
    text = _one_line(e)
    detail = text if kind in text or kind in ("ReaderError",) else f"{kind}: {text}"
    return CorruptLogError(f"damaged data in the log {where}; it cannot be read further ({detail})", reader.path)

# ---- MCAP files ---------------------------------------------------------------------------

def _mcap_profile_and_complete(path: Path) -> tuple[str, bool]:
    """(profile, has footer magic) of an MCAP file, read from its first and last bytes."""
    import struct

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

def _open_mcap(reader: LogReader):
    profile, complete = _mcap_profile_and_complete(reader.path)
    if not complete:
        if reader.conf.on_truncated == "error":
            raise TruncatedLogError("MCAP file is truncated (no footer); refusing it (io.on_truncated=error)", reader.path)
        return _McapStreamBackend(reader, truncated=True)
    if profile == "ros2":
        try:
            return _RosbagsBackend(reader)
        except CorruptLogError:
            log.debug("rosbags could not open %s; trying the mcap library", reader.path)
    return _McapStreamBackend(reader, truncated=False)

class _McapStreamBackend:
    """MCAP through the ``mcap`` library: indexed reading for complete files of any ROS
    profile (cdr or ros1 encoding), and a forward scan that recovers what a truncated file holds."""

    def __init__(self, reader: LogReader, truncated: bool):
        self.reader = reader
        self.truncated = truncated
        self.fh = open(reader.path, "rb")
        self.schemas: dict[int, object] = {}
        self.channels: dict[int, object] = {}
        self.end_reason = ""
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
            reader.truncated = True
            reader.recovered = n
            order = "" if monotone else "; messages are not in time order and are yielded in file order"
            log.warning(
                "%s: file is truncated (%s); recovered %d readable messages on %d topics%s",
                reader.path, self.end_reason, n, len(counts), order,
            )
        else:
            from mcap.reader import make_reader

            try:
                self.mreader = make_reader(self.fh)
                summary = self.mreader.get_summary()
            except Exception as e:  # the mcap library raises many kinds of errors on bad bytes
                self.fh.close()
                raise CorruptLogError(f"cannot open MCAP file ({_one_line(e)})", reader.path) from None
            if summary is None:
                self.fh.close()
                raise CorruptLogError("MCAP file has no summary section", reader.path)
            self.schemas = dict(summary.schemas)
            self.channels = dict(summary.channels)
            if summary.statistics is not None:
                counts = dict(summary.statistics.channel_message_counts)
                if summary.statistics.message_count:
                    start, end = summary.statistics.message_start_time, summary.statistics.message_end_time
        self._setup(counts, start, end)

    def _scan(self):
        """Forward scan of all message records; stops quietly where the readable bytes end."""
        from .mcap_recover import Channel, Message, Schema, ScanEnd, scan

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

        reader = self.reader
        encodings = {ch.message_encoding for ch in self.channels.values()}
        bad = encodings - {"cdr", "ros1"}
        if bad:
            raise UnsupportedFormatError(f"MCAP message encoding(s) {sorted(bad)} not supported (only cdr and ros1)", reader.path)
        if len(encodings) > 1:
            raise UnsupportedFormatError("MCAP file mixes cdr and ros1 message encodings", reader.path)
        self.ros1 = encodings == {"ros1"}
        fmts = {"ros2msg": MessageDefinitionFormat.MSG, "ros1msg": MessageDefinitionFormat.MSG, "ros2idl": MessageDefinitionFormat.IDL}
        pseudo = []
        for ch in self.channels.values():
            sc = self.schemas.get(ch.schema_id)
            if sc is None:
                raise CorruptLogError(f"channel {ch.topic!r} has no schema", reader.path)
            fmt = fmts.get(sc.encoding, MessageDefinitionFormat.NONE)
            data = sc.data.decode("utf-8", "replace") if isinstance(sc.data, (bytes, bytearray)) else sc.data
            pseudo.append(Connection(ch.id, ch.topic, _normalise_type(sc.name), MessageDefinition(fmt, data), "", 0, None, None))
        store = _build_typestore(pseudo, ros1_store() if self.ros1 else ros2_store(), reader.path)
        reader.typestore = store
        self.deser = store.deserialize_ros1 if self.ros1 else store.deserialize_cdr
        self.meta = {}
        for c in pseudo:
            self.meta[c.id] = (c.topic, c.msgtype, _has_header(store, c.msgtype), c.msgtype == TF_TYPE)
            prev = reader._topics.get(c.topic)
            n = counts.get(c.id, 0) + (prev.count if prev else 0)
            reader._topics[c.topic] = TopicInfo(c.topic, c.msgtype, n)
            reader._conns.setdefault(c.topic, []).append(c.id)
        if start is not None:
            reader.start_ns, reader.end_ns = int(start), int(end)

    def _records(self, names):
        ids = {cid for n in names for cid in self.reader._conns[n]}
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
                raise _unreadable(self.reader, e, last) from None

    def raw(self, names):
        meta = self.meta
        for cid, t, data in self._records(names):
            m = meta[cid]
            yield RawMessage(m[0], m[1], t, data)

    def messages(self, names, use_header):
        meta = self.meta
        records = ((meta[cid], t, data) for cid, t, data in self._records(names))
        yield from _deserialised(self.reader, records, self.deser, use_header)

    def close(self):
        self.fh.close()

def _normalise_type(name: str) -> str:
    """'pkg/Type' (ROS1 style) -> 'pkg/msg/Type'."""
    parts = name.split("/")
    return f"{parts[0]}/msg/{parts[1]}" if len(parts) == 2 else name
