"""What every log backend shares: the message records, the type store, header stamps, errors.

A backend (:mod:`.rosbags_backend`, :mod:`.mcap_backend`) opens a log and returns a
:class:`LogContents` (topics, connection handles, time span, type store); it streams
``(meta, log_time, bytes)`` records that :func:`deserialised` turns into
:class:`LogMessage` objects the same way for all of them.
"""
from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any, NamedTuple, Protocol

from ..errors import CorruptLogError, stamp_text

TF_TYPE = "tf2_msgs/msg/TFMessage"


class TopicInfo(NamedTuple):
    name: str
    msgtype: str  # e.g. 'sensor_msgs/msg/Image'
    count: int  # type: ignore[assignment]  # a field named as tuple.count, which it hides


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
    msg: Any  # rosbags message object: its attributes are the message type's fields


@dataclass

class LogContents:
    """What a backend found when it opened a log (the reader's metadata)."""

    typestore: object = None
    topics: dict[str, TopicInfo] = field(default_factory=dict)
    conns: dict[str, list] = field(default_factory=dict)  # topic -> backend connection handles
    start_ns: int = 0
    end_ns: int = 0
    truncated: bool = False
    recovered: int = 0  # messages recovered from a truncated file

    @property
    def message_count(self) -> int:
        return sum(t.count for t in self.topics.values())


class LogBackend(Protocol):
    """What the reader uses of an open backend (:class:`~.rosbags_backend.RosbagsBackend`,
    :class:`~.mcap_backend.McapStreamBackend`)."""

    contents: LogContents
    deser: Callable[[Any, str], Any]  # (serialised bytes, message type) -> message object

    def raw(self, names) -> Iterator[RawMessage]: ...

    def messages(self, names, use_header, raw_names=(), raw_sink=None) -> Iterator[LogMessage]: ...

    def close(self) -> None: ...


def build_typestore(connections, default_store, path):
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

# ---- stamps and deserialisation ----------------------------------------------------------


def has_header(store, msgtype: str) -> bool:
    fields = store.fielddefs.get(msgtype, (None, []))[1]
    return bool(fields) and fields[0][0] == "header"


def message_stamp(msg, has_header: bool, is_tf: bool, log_time: int) -> int:
    if has_header:
        st = msg.header.stamp
        s = st.sec * 1_000_000_000 + st.nanosec
        return s if s > 0 else log_time
    if is_tf and msg.transforms:
        st = msg.transforms[0].header.stamp
        s = st.sec * 1_000_000_000 + st.nanosec
        return s if s > 0 else log_time
    return log_time


def deserialised(path, records, deser, use_header: bool):
    """LogMessages from ``(meta, log_time, bytes)`` records, ``meta = (topic, msgtype, has_header, is_tf)``.

    Shared by both backends: a message that cannot be decoded is a one-line CorruptLogError.
    """
    from rosbags.serde import SerdeError

    for (topic, msgtype, has_hdr, is_tf), t, data in records:
        try:
            msg = deser(data, msgtype)
        except (SerdeError, KeyError, ValueError) as e:
            raise deser_error(path, topic, e) from None
        stamp = message_stamp(msg, has_hdr, is_tf, t) if use_header else t
        yield LogMessage(topic, msgtype, stamp, t, msg)


def with_raw_copies(read, names, raw_names=(), raw_sink=None):
    """``read(topics)``'s ``(meta, log_time, bytes)`` records of ``names``; with ``raw_sink``, the one
    pass also reads ``raw_names`` and hands their records to it as :class:`RawMessage` (shared by
    both backends' ``messages``)."""
    if raw_sink is None:
        return read(list(names))
    extra = [n for n in raw_names if n not in names]
    return _copying(read(list(names) + extra), frozenset(names), frozenset(raw_names), raw_sink)


def _copying(records, wanted: frozenset, raw_topics: frozenset, raw_sink):
    for rec in records:
        (topic, msgtype, _, _), t, data = rec
        if topic in raw_topics:
            raw_sink(RawMessage(topic, msgtype, t, data))
        if topic in wanted:
            yield rec


def deser_error(path, topic, e):
    return CorruptLogError(f"message on topic {topic!r} cannot be decoded ({e})", path)


def error_text(e) -> str:
    return " ".join(str(e).split()) or type(e).__name__


def unreadable(path, e: Exception, last_log_time: int | None) -> CorruptLogError:
    """A one-line error for bytes that cannot be read (damaged chunk, bad compression, short file)."""
    where = (f"after log time {stamp_text(last_log_time)}" if last_log_time is not None
             else "before its first readable message")
    kind = type(e).__name__
    text = error_text(e)
    detail = text if kind in text or kind in ("ReaderError",) else f"{kind}: {text}"
    return CorruptLogError(f"damaged data in the log {where}; it cannot be read further ({detail})", path)

