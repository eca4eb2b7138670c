"""Messages of a ROS1 bag in time order, each decompressed chunk kept only as long as it is needed.

Why: rosbags re-reads a chunk whenever consecutive messages live in different chunks,
which made bags whose chunks overlap in time (e.g. ROS_example.bag) ~20x slower.
"""
from __future__ import annotations

import struct

from ..errors import CorruptLogError

_U32 = struct.Struct("<I")


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


def ros1_messages(bag, connections, cache_bytes: int, path):
    """``(connection, log_time, bytes)`` of a rosbags ROS1 reader in time order, keeping each
    decompressed chunk only until its last message in that order has been yielded (bounded
    by ``cache_bytes``)."""
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
