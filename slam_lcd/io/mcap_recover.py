"""Forward scan of an MCAP file that recovers what a truncated file still holds.

A recorder that dies (or a copy that stops early) leaves an MCAP file without summary
and footer, often ending inside a compressed chunk. The ``mcap`` library then gives up on
the whole chunk; here a cut chunk is decompressed as a stream (zstd and lz4 frames can
be decoded up to where the bytes end), and every complete record in the readable prefix
is returned. Memory: one chunk at a time.
"""
from __future__ import annotations

import struct
from collections.abc import Iterator
from typing import BinaryIO, NamedTuple

OP_SCHEMA, OP_CHANNEL, OP_MESSAGE, OP_CHUNK, OP_FOOTER, OP_DATA_END = 0x03, 0x04, 0x05, 0x06, 0x02, 0x0F
_U16 = struct.Struct("<H")
_U32 = struct.Struct("<I")
_U64 = struct.Struct("<Q")
_MSG = struct.Struct("<HIQQ")  # channel id, sequence, log time, publish time


class Schema(NamedTuple):
    id: int
    name: str
    encoding: str
    data: bytes


class Channel(NamedTuple):
    id: int
    schema_id: int
    topic: str
    message_encoding: str


class Message(NamedTuple):
    channel_id: int
    log_time: int
    data: bytes


class ScanEnd(NamedTuple):
    """Last item of a scan: whether the data ended cleanly and, if not, why."""

    clean: bool
    reason: str


def _string(buf, p):
    (n,) = _U32.unpack_from(buf, p)
    return bytes(buf[p + 4 : p + 4 + n]).decode("utf-8", "replace"), p + 4 + n


def _parse(op: int, body) -> Schema | Channel | Message | None:
    if op == OP_MESSAGE:
        cid, _seq, log_time, _pub = _MSG.unpack_from(body, 0)
        return Message(cid, log_time, bytes(body[_MSG.size :]))
    if op == OP_SCHEMA:
        (sid,) = _U16.unpack_from(body, 0)
        name, p = _string(body, 2)
        enc, p = _string(body, p)
        (n,) = _U32.unpack_from(body, p)
        return Schema(sid, name, enc, bytes(body[p + 4 : p + 4 + n]))
    if op == OP_CHANNEL:
        cid, sid = struct.unpack_from("<HH", body, 0)
        topic, p = _string(body, 4)
        enc, p = _string(body, p)
        return Channel(cid, sid, topic, enc)
    return None


def _records_in(buf) -> Iterator:
    """Complete records of a (possibly cut) decompressed chunk body."""
    p, n = 0, len(buf)
    while p + 9 <= n:
        op = buf[p]
        (ln,) = _U64.unpack_from(buf, p + 1)
        if p + 9 + ln > n:
            return
        rec = _parse(op, memoryview(buf)[p + 9 : p + 9 + ln])
        if rec is not None:
            yield rec
        p += 9 + ln


def _decompress_prefix(compression: str, data: bytes, full_size: int, complete: bool) -> bytes:
    if compression == "":
        return data
    if compression == "zstd":
        try:
            from compression import zstd  # Python >= 3.14
        except ImportError:
            from backports import zstd
        d = zstd.ZstdDecompressor()
        return d.decompress(data) if data else b""
    if compression == "lz4":
        import lz4.frame

        return lz4.frame.LZ4FrameDecompressor().decompress(data) if data else b""
    raise ValueError(f"unknown chunk compression {compression!r}")


def scan(fh: BinaryIO) -> Iterator:
    """Yield Schema / Channel / Message records in file order, then one :class:`ScanEnd`."""
    fh.seek(0)
    magic = fh.read(8)
    if magic != b"\x89MCAP0\r\n":
        yield ScanEnd(False, "bad magic")
        return
    while True:
        head = fh.read(9)
        if len(head) == 0:
            yield ScanEnd(False, "file ends without footer")
            return
        if len(head) < 9:
            yield ScanEnd(False, "file ends inside a record header")
            return
        op = head[0]
        (ln,) = _U64.unpack_from(head, 1)
        if op == OP_FOOTER:
            yield ScanEnd(True, "footer")
            return
        if op == OP_DATA_END:
            yield ScanEnd(True, "data end")
            return
        if op not in (OP_CHUNK, OP_SCHEMA, OP_CHANNEL, OP_MESSAGE):
            fh.seek(ln, 1)  # index/summary/attachment records are not needed here
            continue
        body = fh.read(ln)
        complete = len(body) == ln
        if op != OP_CHUNK:
            if not complete:
                yield ScanEnd(False, "file ends inside a record")
                return
            rec = _parse(op, body)
            if rec is not None:
                yield rec
            continue
        # chunk: start, end, uncompressed size, crc, compression, records length, records
        if len(body) < 8 * 3 + 4 + 4:
            yield ScanEnd(False, "file ends inside a chunk header")
            return
        (usize,) = _U64.unpack_from(body, 16)
        compression, p = _string(body, 28)
        if p + 8 > len(body):
            yield ScanEnd(False, "file ends inside a chunk header")
            return
        (clen,) = _U64.unpack_from(body, p)
        data = body[p + 8 : p + 8 + clen]
        try:
            plain = _decompress_prefix(compression, data, usize, complete)
        except Exception as e:  # corrupt compressed bytes: keep what came before
            yield ScanEnd(False, f"chunk cannot be decompressed ({e})")
            return
        yield from _records_in(plain)
        if not complete:
            yield ScanEnd(False, "file ends inside a chunk")
            return
