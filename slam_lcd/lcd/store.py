"""Where the loop detector keeps past keyframes' descriptors: compact in memory, or in a temp file.

Why: descriptors are nearly all of what a keyframe costs the detector (1000 SuperPoint
descriptors: 1 MB as float32), and an hour-long log has thousands of keyframes. Verification
only ever needs the descriptors of the few candidates of each query, so they can live

- ``memory``: in RAM, SuperPoint descriptors as float16 (half the bytes; the L2 distances
  they give differ from float32 ones by ~1e-3, far below the 0.8 match bound and the ratio
  test's margins: same verdicts on the corridor and demo tests);
- ``disk``: in an anonymous temporary file (deleted by the OS when closed or when the
  process ends), read back with one ``pread`` per candidate: resident memory per keyframe is
  then its keypoints and 3-D points only. Same float16 values as ``memory``.

ORB descriptors (uint8, 32 bytes) are kept as they are.

A keyframe remembered from a map keeps its descriptors where the map holds them
(:class:`DescriptorSource`): they are read and converted only when the keyframe is a
candidate, so loading a map copies none of them.
"""
from __future__ import annotations

import os
import tempfile
from collections.abc import Callable
from dataclasses import dataclass
from typing import IO

import numpy as np

from ..errors import InputError

STORAGE_MODES = ("memory", "disk")
DESCRIPTOR_DTYPES = ("float16", "float32")


def compact_descriptors(desc: np.ndarray, dtype: str) -> np.ndarray:
    """Descriptors in their stored precision: float ones as ``dtype``, uint8 ones unchanged."""
    desc = np.asarray(desc)
    if desc.dtype == np.uint8:
        return np.ascontiguousarray(desc)
    return np.ascontiguousarray(desc, dtype=np.dtype(dtype))


@dataclass(frozen=True)
class DescriptorSource:
    """Float descriptors held elsewhere (a map's session arrays): ``load()`` gives them (N, dim)."""

    load: Callable[[], np.ndarray]
    dim: int


def compact_loaded(load: Callable[[], np.ndarray], dtype: str) -> np.ndarray:
    """What ``load()`` gives, in the stored precision (a :class:`DescriptorSource` read on demand)."""
    return compact_descriptors(load(), dtype)


class DescriptorStore:
    """Descriptors by keyframe id, in memory or in a temporary file (see the module note)."""

    def __init__(self, mode: str = "memory", directory: str | None = None):
        if mode not in STORAGE_MODES:
            raise InputError(f"lcd.descriptor_storage must be one of {list(STORAGE_MODES)}, got {mode!r}")
        self.mode = mode
        self._directory = directory
        self._arrays: dict[int, np.ndarray] = {}
        self._slots: dict[int, tuple[int, tuple[int, ...], np.dtype]] = {}
        self._file: IO[bytes] | None = None
        self._end = 0
        self._sources: dict[int, Callable[[], np.ndarray]] = {}

    def __len__(self) -> int:
        return len(self._arrays) + len(self._slots) + len(self._sources)

    def put_source(self, key: int, load: Callable[[], np.ndarray]) -> None:
        """Keep only how to read ``key``'s descriptors (already in their stored precision when read)."""
        self._sources[key] = load

    def put(self, key: int, desc: np.ndarray) -> None:
        if self.mode == "memory":
            self._arrays[key] = desc
            return
        data = np.ascontiguousarray(desc).tobytes()
        try:
            if self._file is None:
                self._file = tempfile.TemporaryFile(prefix="slam-lcd-descriptors-", dir=self._directory)
            written = os.pwrite(self._file.fileno(), data, self._end)
        except OSError as e:
            where = self._directory or tempfile.gettempdir()
            raise InputError(f"cannot write the loop detector's descriptor store there ({e.strerror or e}); "
                             f"set TMPDIR or lcd.descriptor_storage=memory", where) from None
        if written != len(data):
            raise InputError(f"short write to the loop detector's descriptor store ({written} of {len(data)} bytes)",
                             self._directory or tempfile.gettempdir())
        self._slots[key] = (self._end, desc.shape, desc.dtype)
        self._end += len(data)

    def __del__(self):
        self.close()

    def get(self, key: int) -> np.ndarray:
        load = self._sources.get(key)
        if load is not None:
            return load()
        if self.mode == "memory":
            return self._arrays[key]
        offset, shape, dtype = self._slots[key]
        n = int(np.prod(shape)) * dtype.itemsize
        assert self._file is not None  # a slot is made only after its bytes went into the file
        data = os.pread(self._file.fileno(), n, offset)
        if len(data) != n:
            raise OSError(f"short read from the descriptor store ({len(data)} of {n} bytes)")
        return np.frombuffer(data, dtype=dtype).reshape(shape)

    def resident_bytes(self) -> int:
        """Bytes of descriptors held in RAM (0 for ``disk``: those are in the file)."""
        return sum(a.nbytes for a in self._arrays.values())

    def file_bytes(self) -> int:
        return self._end

    def close(self) -> None:
        file = getattr(self, "_file", None)  # also when __init__ raised
        if file is not None:
            file.close()
            self._file = None
