"""Every keyframe's points in its body frame, kept on disk until the final poses are known.

Why on disk: the corrected poses exist only after the last loop, so the map cannot be merged
once and for all while the log streams. Each keyframe's points, already merged per voxel in
its own frame (a few thousand), go to an anonymous file (removed when closed, or when the
process dies) as int16 coordinates in 1/16 of a voxel (+-2,047 voxels: +-102 m at 5 cm; a
point beyond is dropped) and uint8 colours: 9 bytes a point. The map is then built by
reading them back one keyframe at a time with any set of poses (odometry and corrected),
so resident memory is that of the voxel grid, whatever the log's length.
"""
from __future__ import annotations

import os
import tempfile

import numpy as np

_Q = 16  # quantisation steps per voxel
_DT = np.dtype([("xyz", "<i2", (3,)), ("rgb", "u1", (3,))])


class KeyframeCloudStore:
    """Append-only file of per-keyframe points; :meth:`items` reads them back in order."""

    def __init__(self, voxel: float, folder: str | os.PathLike[str] | None = None):
        self.unit = float(voxel) / _Q
        self._fh = tempfile.TemporaryFile(prefix="slam-lcd-cloud-", dir=folder)
        self.index: list[tuple[int, int, int, int]] = []  # (keyframe id, stamp, offset, count)
        self._end = 0

    def add(self, kf_id: int, stamp: int, points_body: np.ndarray, colours: np.ndarray) -> None:
        q = np.rint(np.asarray(points_body, np.float64) / self.unit)
        keep = np.all(np.abs(q) <= np.iinfo(np.int16).max, axis=1)
        rec = np.empty(int(keep.sum()), _DT)
        rec["xyz"] = q[keep]
        rec["rgb"] = np.asarray(colours)[keep]
        self._fh.seek(self._end)
        self._fh.write(rec.tobytes())
        self.index.append((int(kf_id), int(stamp), self._end, len(rec)))
        self._end += rec.nbytes

    def read(self, i: int) -> tuple[np.ndarray, np.ndarray]:
        """Points (N, 3) float64 in the body frame and colours of entry ``i``."""
        _, _, off, n = self.index[i]
        self._fh.seek(off)
        rec = np.frombuffer(self._fh.read(n * _DT.itemsize), _DT)
        return rec["xyz"].astype(np.float64) * self.unit, rec["rgb"]

    @property
    def nbytes(self) -> int:
        return self._end

    def __len__(self) -> int:
        return len(self.index)

    def close(self) -> None:
        self._fh.close()
