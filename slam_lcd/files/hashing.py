"""The sha256 of a file, read in blocks: one helper for every stage that checks or names a file.

The weights check, the map's manifest and the log a session came from all compare the same
digest, so they compute it the same way; a file of any size is read a block at a time.
"""
from __future__ import annotations

import hashlib
from pathlib import Path
from typing import BinaryIO

CHUNK = 1 << 20


def sha256_of(path: str | Path, chunk: int = CHUNK) -> str:
    """The hex sha256 of the file at ``path``."""
    with open(path, "rb") as fh:
        return _digest(fh, chunk)


def sha256_of_file(fh: BinaryIO, chunk: int = CHUNK) -> str:
    """The hex sha256 of an open binary file, read from its start; ``fh`` is left at its start again,
    so whoever opened it can go on reading the bytes just checked."""
    fh.seek(0)
    digest = _digest(fh, chunk)
    fh.seek(0)
    return digest


def _digest(fh: BinaryIO, chunk: int) -> str:
    h = hashlib.sha256()
    while block := fh.read(chunk):
        h.update(block)
    return h.hexdigest()
