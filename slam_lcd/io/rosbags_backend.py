"""Logs read through rosbags: ROS1 bags, rosbag2 directories / files, indexed ros2 MCAP files."""
from __future__ import annotations

import logging
from pathlib import Path

from ..errors import CorruptLogError, SlamLcdError
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
from .ros1_chunks import ros1_messages

log = logging.getLogger(__name__)


class RosbagsBackend:
    """Opens ``path`` (``fmt``: 'rosbag1', 'rosbag2' or 'mcap'); :attr:`contents` is what it holds."""

    def __init__(self, path: Path, fmt: str, conf: IOConfig):
        from rosbags.rosbag1 import Reader as Reader1
        from rosbags.rosbag1 import ReaderError as ReaderError1
        from rosbags.rosbag2 import Reader as Reader2
        from rosbags.rosbag2 import ReaderError as ReaderError2

        from .typestores import ros1_store, ros2_store

        self.path = path
        self.conf = conf
        self.errors = (ReaderError1, ReaderError2)
        self.ros1 = fmt == "rosbag1"
        try:
            self.bag = Reader1(path) if self.ros1 else Reader2(path)
            self.bag.open()
        except self.errors as e:
            raise CorruptLogError(f"cannot open {fmt} log ({error_text(e)})", path) from None
        except (KeyError, ValueError, TypeError, OSError, IndexError) as e:
            raise CorruptLogError(f"cannot open {fmt} log ({type(e).__name__}: {error_text(e)})", path) from None
        conns = list(self.bag.connections)
        store = build_typestore(conns, ros1_store() if self.ros1 else ros2_store(), path)
        self.contents = c = LogContents(typestore=store)
        self.deser = store.deserialize_ros1 if self.ros1 else store.deserialize_cdr
        by_topic: dict[str, list] = {}
        for conn in conns:
            by_topic.setdefault(conn.topic, []).append(conn)
        for topic, cs in by_topic.items():
            types = {x.msgtype for x in cs}
            if len(types) > 1:
                log.warning("%s: topic %s carries several types %s; using %s", path, topic, sorted(types),
                            cs[0].msgtype)
            c.topics[topic] = TopicInfo(topic, cs[0].msgtype, sum(max(x.msgcount, 0) for x in cs))
            c.conns[topic] = cs
        if c.message_count:
            c.start_ns = int(self.bag.start_time)
            c.end_ns = int(self.bag.end_time) - 1  # rosbags' end_time is one past the last message
        # per connection: (topic, msgtype, has_header, is_tf)
        self.meta = {
            id(x): (x.topic, x.msgtype, has_header(store, x.msgtype), x.msgtype == TF_TYPE) for x in conns
        }

    def _conns(self, names):
        return [x for n in names for x in self.contents.conns[n]]

    def _stream(self, names):
        conns = self._conns(names)
        if self.ros1:
            return ros1_messages(self.bag, conns, self.conf.rosbag1_chunk_cache_mb << 20, self.path)
        return self.bag.messages(connections=conns)

    def raw(self, names):
        meta = self.meta
        last = [None]
        try:
            for conn, t, data in self._stream(names):
                m = meta[id(conn)]
                last[0] = t
                yield RawMessage(m[0], m[1], t, data)
        except SlamLcdError:
            raise
        except Exception as e:  # rosbags, zstd/lz4 and struct raise many kinds on damaged bytes
            raise unreadable(self.path, e, last[0]) from None

    def messages(self, names, use_header, raw_names=(), raw_sink=None):
        meta = self.meta
        last = [None]

        def records(topics):
            for conn, t, data in self._stream(topics):
                last[0] = t
                yield meta[id(conn)], t, data

        stream = with_raw_copies(records, names, raw_names, raw_sink)
        try:
            yield from deserialised(self.path, stream, self.deser, use_header)
        except SlamLcdError:
            raise
        except Exception as e:  # rosbags, zstd/lz4 and struct raise many kinds on damaged bytes
            raise unreadable(self.path, e, last[0]) from None

    def close(self):
        try:
            self.bag.close()
        except Exception:  # closing a reader that failed half-way must not mask the real error
            pass
