"""A voxel grid that merges points into one centroid (and mean colour) per occupied voxel.

Why a sorted-key grid merged in batches: a map must not grow with the log's length, only with
the space it covers. Each batch of points is reduced to one entry per voxel at once (a
keyframe's tens of thousands of points become a few thousand), and batches are merged into
the grid's sorted arrays only when they add up to as many entries as the grid holds, so the
merging costs O(n log n) in all (amortised) and the memory is the grid's plus at most as much
again. Voxel keys pack three 21-bit signed indices into one int64 (+-1,048,575 voxels per
axis: +-52 km at 5 cm); points beyond that are dropped, never wrapped.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

_BITS = 21
_HALF = 1 << (_BITS - 1)
_MASK = (1 << _BITS) - 1


@dataclass
class Cloud:
    """Points (N, 3) float32 in metres and their colours (N, 3) uint8 RGB."""

    points: np.ndarray
    colours: np.ndarray

    def __len__(self) -> int:
        return len(self.points)

    @classmethod
    def empty(cls) -> "Cloud":
        return cls(np.zeros((0, 3), np.float32), np.zeros((0, 3), np.uint8))


def voxel_keys(points: np.ndarray, voxel: float) -> tuple[np.ndarray, np.ndarray]:
    """``(keys, inside)``: one int64 key per point of ``inside`` (points outside the key range are dropped)."""
    idx = np.floor(np.asarray(points, np.float64) / voxel).astype(np.int64)
    inside = np.all((idx >= -_HALF) & (idx < _HALF), axis=1) if len(idx) else np.zeros(0, bool)
    idx = idx[inside] + _HALF
    keys = (idx[:, 0] << (2 * _BITS)) | (idx[:, 1] << _BITS) | idx[:, 2]
    return keys, inside


def key_centres(keys: np.ndarray, voxel: float) -> np.ndarray:
    """The centre (m) of each voxel ``keys`` names (the inverse of :func:`voxel_keys`)."""
    idx = np.column_stack([(keys >> (2 * _BITS)) & _MASK, (keys >> _BITS) & _MASK, keys & _MASK]) - _HALF
    return (idx + 0.5) * voxel


def _reduce(keys: np.ndarray, sums: np.ndarray, csums: np.ndarray, counts: np.ndarray):
    """Entries of equal key summed; keys sorted."""
    uk, inv = np.unique(keys, return_inverse=True)
    n = len(uk)
    s = np.column_stack([np.bincount(inv, sums[:, i], n) for i in range(3)])
    c = np.column_stack([np.bincount(inv, csums[:, i], n) for i in range(3)]).astype(np.float32)
    return uk, s, c, np.bincount(inv, counts, n).astype(np.int64)


class VoxelGrid:
    """Points in, one averaged point per voxel out (:meth:`cloud`); see the module docstring."""

    def __init__(self, voxel: float):
        if not voxel > 0:
            raise ValueError(f"voxel size must be positive, got {voxel}")
        self.voxel = float(voxel)
        self._keys = np.zeros(0, np.int64)
        self._sums = np.zeros((0, 3))
        self._csums = np.zeros((0, 3), np.float32)
        self._counts = np.zeros(0, np.int64)
        self._pending: list[tuple] = []
        self._n_pending = 0
        self.points_in = 0

    def add(self, points: np.ndarray, colours: np.ndarray | None = None) -> None:
        """Merge ``points`` (N, 3) with their ``colours`` (N, 3) uint8 (grey 128 when None)."""
        points = np.asarray(points, np.float64).reshape(-1, 3)
        if len(points) == 0:
            return
        if colours is None:
            colours = np.full((len(points), 3), 128, np.uint8)
        keys, inside = voxel_keys(points, self.voxel)
        if not inside.all():
            points, colours = points[inside], np.asarray(colours)[inside]
        if len(keys) == 0:
            return
        self.points_in += len(keys)
        batch = _reduce(keys, points, np.asarray(colours, np.float32), np.ones(len(keys), np.int64))
        self._pending.append(batch)
        self._n_pending += len(batch[0])
        if self._n_pending >= max(len(self._keys), 1 << 16):
            self._merge()

    def _merge(self) -> None:
        if not self._pending:
            return
        parts = [(self._keys, self._sums, self._csums, self._counts), *self._pending]
        self._pending, self._n_pending = [], 0
        self._keys, self._sums, self._csums, self._counts = _reduce(*(np.concatenate(p) for p in zip(*parts)))

    def __len__(self) -> int:
        self._merge()
        return len(self._keys)

    @property
    def nbytes(self) -> int:
        """Bytes the grid's arrays hold (pending batches included)."""
        arrays = [self._keys, self._sums, self._csums, self._counts] + [a for b in self._pending for a in b]
        return int(sum(a.nbytes for a in arrays))

    def cloud(self) -> Cloud:
        """One point per voxel: the centroid of its points, coloured by their mean colour."""
        self._merge()
        if len(self._keys) == 0:
            return Cloud.empty()
        n = self._counts[:, None]
        pts = (self._sums / n).astype(np.float32)
        col = np.clip(np.rint(self._csums / n), 0, 255).astype(np.uint8)
        return Cloud(pts, col)
