"""Writers of new logs: a single MCAP file, a rosbag2 directory, or a ROS1 bag.

``open_writer(path, fmt)`` returns a :class:`LogWriter` (context manager). Output appears
under ``path`` only when the writer closes without error (written beside it under a
temporary name, then renamed), and never replaces an input log. The same messages in
the same order give byte-identical files: no wall-clock time is written anywhere
(rosbag2's metadata.yaml holds only message times; MCAP headers name the library).

Messages come from :mod:`slam_lcd.io.message_builders` (ROS2 objects); the ROS1 writer converts
them to ROS1 wire format. ``write_raw`` takes already-serialised bytes (used by
:func:`copy_topics`, so copied messages are passed through, not re-encoded).
"""
from __future__ import annotations

import contextlib
import logging
import os
import shutil
import tempfile
from collections.abc import Iterable
from pathlib import Path

import numpy as np

from ..errors import InputError, InvalidPoseError, UnsupportedFormatError
from ..files.atomic import guard_not_input
from ..runtime.interrupts import defer_sigint, finish
from ..types import Trajectory
from ..version import __version__
from . import message_builders as M
from .config import IOConfig
from .reader import open_log
from .typestores import ros1_store, ros2_store

log = logging.getLogger(__name__)

WRITE_FORMATS = ("mcap", "rosbag2", "rosbag1")


def format_for_path(path: str | Path) -> str:
    """Output format implied by a path: ``.mcap`` file, ``.bag`` file, otherwise a rosbag2 folder."""
    suffix = Path(path).suffix.lower()
    if suffix == ".mcap":
        return "mcap"
    if suffix == ".bag":
        return "rosbag1"
    if suffix in ("", ".rosbag2") or Path(path).is_dir():
        return "rosbag2"
    raise UnsupportedFormatError(
        f"cannot tell the output format from suffix {suffix!r}; use .mcap, .bag or a folder name", path
    )


class LogWriter:
    """Base writer: topics are registered on first write with the message's type."""

    fmt = ""

    def __init__(self, path: Path, conf: IOConfig):
        self.path = Path(path)
        self.conf = conf
        self.counts: dict[str, int] = {}
        self._types: dict[str, str] = {}
        self._closed = False

    # -- public -------------------------------------------------------------------------
    def write(self, topic: str, msg, log_time_ns: int) -> None:
        """Serialise and write one message object (from :mod:`slam_lcd.io.message_builders`)."""
        msgtype = msg.__msgtype__
        raw = ros2_store().serialize_cdr(msg, msgtype, little_endian=True)
        self.write_raw(topic, msgtype, raw, log_time_ns, ros1=False)

    def write_raw(self, topic: str, msgtype: str, data, log_time_ns: int, *, ros1: bool, typestore=None) -> None:
        """Write serialised bytes (CDR when ``ros1`` is False, ROS1 wire format otherwise).

        ``typestore`` is the store that knows ``msgtype`` if it is not a standard message.
        """
        if log_time_ns < 0:
            raise InvalidPoseError(f"negative log time {log_time_ns} ns for topic {topic!r}")
        known = self._types.get(topic)
        if known is None:
            self._add_topic(topic, msgtype, typestore)
            self._types[topic] = msgtype
            self.counts[topic] = 0
        elif known != msgtype:
            raise InputError(f"topic {topic!r} already carries {known}, cannot also write {msgtype}", self.path)
        self._write(topic, msgtype, data, int(log_time_ns), ros1, typestore)
        self.counts[topic] += 1

    def close(self) -> None:
        raise NotImplementedError

    def abort(self) -> None:
        raise NotImplementedError

    # -- per format ---------------------------------------------------------------------
    def _add_topic(self, topic, msgtype, typestore) -> None:
        raise NotImplementedError

    def _write(self, topic, msgtype, data, log_time, ros1, typestore) -> None:
        raise NotImplementedError


def _ros2_definition(msgtype: str, typestore) -> tuple[object, str]:
    """(store, ROS2 .msg definition text) of a type, looked up in ROS2 Humble, then ``typestore``."""
    for store in (ros2_store(), typestore):
        if store is not None and msgtype in store.fielddefs:
            return store, store.generate_msgdef(msgtype, ros_version=2)[0]
    raise UnsupportedFormatError(f"message type {msgtype} is unknown; cannot describe it in the output")


def describable(msgtype: str, typestore=None) -> bool:
    """Can a topic of ``msgtype`` be written (its definition known to ROS2 Humble or ``typestore``)?"""
    try:
        _ros2_definition(msgtype, typestore)
        return True
    except Exception:  # unknown type, or a definition rosbags cannot turn back into text
        return False


def _to_cdr(data, msgtype: str, ros1: bool, typestore):
    if not ros1:
        return data
    store = ros2_store() if msgtype in ros2_store().fielddefs else typestore
    return store.ros1_to_cdr(data, msgtype)


class McapLogWriter(LogWriter):
    """Single ``.mcap`` file, profile ros2, CDR messages with ``ros2msg`` schemas (Foxglove/rosbags/mcap)."""

    fmt = "mcap"

    def __init__(self, path: Path, conf: IOConfig):
        super().__init__(path, conf)
        from mcap.writer import CompressionType, Writer

        comp = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4, "none": CompressionType.NONE}
        self._fh = open(self.path, "xb")
        self._w = Writer(self._fh, chunk_size=4 * 1024 * 1024, compression=comp[conf.mcap_compression])
        self._w.start(profile="ros2", library=f"slam-lcd {__version__}")
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, int] = {}
        self._seq = 0

    def _add_topic(self, topic, msgtype, typestore):
        if msgtype not in self._schemas:
            _, text = _ros2_definition(msgtype, typestore)
            self._schemas[msgtype] = self._w.register_schema(name=msgtype, encoding="ros2msg", data=text.encode())
        self._channels[topic] = self._w.register_channel(
            topic=topic, message_encoding="cdr", schema_id=self._schemas[msgtype]
        )

    def _write(self, topic, msgtype, data, log_time, ros1, typestore):
        data = _to_cdr(data, msgtype, ros1, typestore)
        self._seq += 1
        self._w.add_message(self._channels[topic], log_time=log_time, data=bytes(data), publish_time=log_time,
                            sequence=self._seq)

    def close(self):
        self._w.finish()
        self._fh.close()

    def abort(self):
        with contextlib.suppress(Exception):
            self._fh.close()


class Rosbag2LogWriter(LogWriter):
    """rosbag2 directory (metadata.yaml version 8) with mcap (default) or sqlite3 storage."""

    fmt = "rosbag2"

    def __init__(self, path: Path, conf: IOConfig):
        super().__init__(path, conf)
        from rosbags.rosbag2 import CompressionFormat, CompressionMode, StoragePlugin, Writer

        plugin = StoragePlugin.MCAP if conf.rosbag2_storage == "mcap" else StoragePlugin.SQLITE3
        self._w = Writer(self.path, version=8, storage_plugin=plugin)
        if conf.rosbag2_storage == "mcap" and conf.mcap_compression != "none":
            # rosbags' mcap storage compresses chunks (zstd; lz4 is not offered there)
            self._w.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
        self._w.open()
        self._conns: dict[str, object] = {}

    def _add_topic(self, topic, msgtype, typestore):
        store, text = _ros2_definition(msgtype, typestore)
        self._conns[topic] = self._w.add_connection(
            topic, msgtype, msgdef=text, rihs01=store.hash_rihs01(msgtype)
        )

    def _write(self, topic, msgtype, data, log_time, ros1, typestore):
        self._w.write(self._conns[topic], log_time, _to_cdr(data, msgtype, ros1, typestore))

    def close(self):
        self._w.close()

    def abort(self):
        with contextlib.suppress(Exception):
            self._w.abort()


class Rosbag1LogWriter(LogWriter):
    """ROS1 bag (format 2.0) with ROS1 Noetic definitions and md5sums."""

    fmt = "rosbag1"

    def __init__(self, path: Path, conf: IOConfig):
        super().__init__(path, conf)
        from rosbags.rosbag1 import Writer

        self._w = Writer(self.path)
        if conf.rosbag1_compression != "none":
            self._w.set_compression(getattr(Writer.CompressionFormat, conf.rosbag1_compression.upper()))
        self._w.open()
        self._conns: dict[str, object] = {}

    def _add_topic(self, topic, msgtype, typestore):
        store = ros1_store() if msgtype in ros1_store().fielddefs else typestore
        if store is None or msgtype not in store.fielddefs:
            raise UnsupportedFormatError(f"message type {msgtype} has no ROS1 definition; "
                                         "cannot write it to a ROS1 bag")
        self._conns[topic] = self._w.add_connection(topic, msgtype, typestore=store)

    def _write(self, topic, msgtype, data, log_time, ros1, typestore):
        if not ros1:
            store = ros2_store() if msgtype in ros2_store().fielddefs else typestore
            data = store.cdr_to_ros1(data, msgtype)
        self._w.write(self._conns[topic], log_time, data)

    def close(self):
        self._w.close()

    def abort(self):
        with contextlib.suppress(Exception):
            self._w.abort()


_WRITERS = {"mcap": McapLogWriter, "rosbag2": Rosbag2LogWriter, "rosbag1": Rosbag1LogWriter}


@contextlib.contextmanager
def open_writer(path: str | Path, fmt: str | None = None, *, conf: IOConfig | None = None, inputs=()):
    """Open a new log for writing; it appears at ``path`` only if the ``with`` block succeeds.

    ``fmt`` is 'mcap' | 'rosbag2' | 'rosbag1' (default: from the path's suffix). An existing
    output is replaced; ``inputs`` (paths) are refused as outputs.
    """
    path = Path(path)
    fmt = fmt or format_for_path(path)
    if fmt not in _WRITERS:
        raise UnsupportedFormatError(f"unknown output format {fmt!r}; use one of {list(WRITE_FORMATS)}", path)
    guard_not_input(path, *inputs)
    if path.is_dir() and any(path.iterdir()) and not (fmt == "rosbag2" and (path / "metadata.yaml").is_file()):
        raise InputError("output exists and is a folder that is not a rosbag2 bag; refusing to replace it", path)
    conf = conf or IOConfig()
    path.parent.mkdir(parents=True, exist_ok=True)
    made: list[Path] = []
    writer = None
    try:  # a signal held while the temporary folder is made is raised inside this try
        with defer_sigint():
            made.append(Path(tempfile.mkdtemp(prefix=f".{path.name}.", dir=path.parent)))
        tmp = made[0] / path.name
        writer = _WRITERS[fmt](tmp, conf)
        yield writer
        writer.close()
        writer.path = path
        with defer_sigint():  # the old log goes and the new one comes together
            if path.exists():
                shutil.rmtree(path) if path.is_dir() else path.unlink()
            os.replace(tmp, path)
    except BaseException:
        if writer is not None:
            writer.abort()
        raise
    finally:
        if made:
            finish(shutil.rmtree, made[0], True)


def copy_topics(reader, writer: LogWriter, topics: Iterable[str] | None = None) -> dict[str, int]:
    """Copy the chosen topics (default: all) of an open :class:`LogReader` into ``writer``.

    Messages keep their bytes where the wire format allows (CDR to CDR, ROS1 to ROS1) and
    are converted between ROS1 and CDR otherwise; log times are kept. Returns counts.
    """
    counts: dict[str, int] = {}
    ros1 = reader.format == "rosbag1"
    store = reader.typestore
    for topic, msgtype, log_time, raw in reader.raw_messages(topics):
        writer.write_raw(topic, msgtype, raw, log_time, ros1=ros1, typestore=store)
        counts[topic] = counts.get(topic, 0) + 1
    return counts


def write_trajectory_log(
    path: str | Path,
    traj: Trajectory,
    fmt: str | None = None,
    topic: str = "/slam_lcd/corrected",
    frame_id: str = "map",
    child_frame_id: str = "base_link",
    copy_from: str | Path | None = None,
    copy_topics: Iterable[str] | None = None,
    conf: IOConfig | None = None,
) -> dict[str, int]:
    """Write a trajectory as a new log: ``<topic>/path`` (nav_msgs/Path, once, at the end),
    ``<topic>`` (a PoseStamped per stamp) and ``/tf`` (``frame_id -> child_frame_id`` per stamp),
    optionally with topics copied from the input log ``copy_from`` (all if ``copy_topics`` is None).

    Log times are the pose stamps (the Path at the last stamp); copied messages keep theirs.
    Messages are written in log-time order. A copied ``/tf`` is merged with ours: pick a
    ``child_frame_id`` that the input's TF tree does not already have a parent for.
    Returns message counts per topic.
    """
    path = Path(path)
    inputs = (copy_from,) if copy_from is not None else ()
    stamps = traj.stamps.tolist()
    poses = traj.poses
    if len(traj) and not np.all(np.isfinite(poses)):
        bad = int(np.nonzero(~np.isfinite(poses).all(axis=(1, 2)))[0][0])
        raise InvalidPoseError(f"trajectory pose {bad} (stamp {stamps[bad]} ns) has NaN/inf values")
    own = [(s, i) for i, s in enumerate(stamps)]  # messages are built lazily while writing
    path_topic = topic.rstrip("/") + "/path"
    with open_writer(path, fmt, conf=conf, inputs=inputs) as w:
        own_iter = iter(own)
        nxt = next(own_iter, None)

        def flush_until(t):
            nonlocal nxt
            while nxt is not None and (t is None or nxt[0] <= t):
                s, i = nxt
                w.write(topic, M.pose_stamped_msg(poses[i], s, frame_id), s)
                w.write("/tf", M.tf_message([(poses[i], s, frame_id, child_frame_id)]), s)
                nxt = next(own_iter, None)

        if copy_from is not None:
            with open_log(copy_from) as reader:
                chosen = list(copy_topics) if copy_topics is not None else None
                if chosen is not None:
                    chosen = [t for t in chosen if t not in (topic, path_topic)]
                ros1 = reader.format == "rosbag1"
                if chosen is None or chosen:
                    for t_name, msgtype, log_time, raw in reader.raw_messages(chosen):
                        if t_name in (topic, path_topic):
                            continue  # our own output topics replace the input's
                        flush_until(log_time)
                        w.write_raw(t_name, msgtype, raw, log_time, ros1=ros1, typestore=reader.typestore)
        flush_until(None)
        end = stamps[-1] if stamps else 0
        w.write(path_topic, M.path_msg(Trajectory(traj.stamps, traj.poses), frame_id), end)
        counts = dict(w.counts)
    log.info("wrote %s (%s)", path, ", ".join(f"{k}: {v}" for k, v in counts.items()))
    return counts
