"""A voxel grid that merges points into one centroid (and mean colour) per occupied voxel.

Why a sorted-key grid merged in batches: a map must not grow with the log's length, only with
the space it covers. Each batch of points is reduced to one entry per voxel at once (a
keyframe's tens of thousands of points become a few thousand), and batches are merged into
the grid's sorted arrays (a binary search, sums in place, new voxels inserted) only when they
add up to as many entries as the grid holds, so the merging costs O(n log n) in all (amortised)
and the memory is the grid's plus at most as much again. Voxel keys pack three 21-bit signed
indices into one int64 (+-1,048,575 voxels per axis: +-52 km at 5 cm); points beyond that are
dropped, never wrapped. Each voxel also counts the batches that reached it (the map adds one
batch per keyframe), so that a voxel seen by a single keyframe (more often a sensor outlier
than a surface) can be left out of the cloud.
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
    def empty(cls) -> Cloud:
        return cls(np.zeros((0, 3), np.float32), np.zeros((0, 3), np.uint8))


def voxel_keys(points: np.ndarray, voxel: float) -> tuple[np.ndarray, np.ndarray]:
    """``(keys, inside)``: one int64 key per point of ``inside`` (points outside the key range are dropped)."""
    idx = np.floor(np.asarray(points, np.float64) / voxel).astype(np.int64)
    idx += _HALF
    inside = (idx.min(axis=1) >= 0) & (idx.max(axis=1) <= _MASK) if len(idx) else np.zeros(0, bool)
    if not inside.all():
        idx = idx[inside]
    keys = (idx[:, 0] << (2 * _BITS)) | (idx[:, 1] << _BITS) | idx[:, 2]
    return keys, inside


def key_centres(keys: np.ndarray, voxel: float) -> np.ndarray:
    """The centre (m) of each voxel ``keys`` names (the inverse of :func:`voxel_keys`)."""
    idx = np.column_stack([(keys >> (2 * _BITS)) & _MASK, (keys >> _BITS) & _MASK, keys & _MASK]) - _HALF
    return (idx + 0.5) * voxel


def _reduce(keys: np.ndarray, *values: np.ndarray) -> tuple:
    """``(sorted unique keys, *values summed per key)``. A stable sort and one ``reduceat`` per array: the sums
    add up in input order (the same result for the same input, whatever the platform's sort)."""
    order = np.argsort(keys, kind="stable")
    k = keys[order]
    if len(k) == 0:
        return (k, *(v[:0] for v in values))
    start = np.flatnonzero(np.concatenate(([True], k[1:] != k[:-1])))
    return (k[start], *(np.add.reduceat(v[order], start, axis=0) for v in values))


def voxel_means(points: np.ndarray, colours: np.ndarray, voxel: float) -> tuple[np.ndarray, np.ndarray]:
    """One batch of points merged at once: ``(centroids (M, 3) float64, mean colours (M, 3) uint8)``, one per
    occupied voxel, in key order (what :meth:`VoxelGrid.cloud` gives for one :meth:`VoxelGrid.add`)."""
    points = np.asarray(points).reshape(-1, 3)
    keys, inside = voxel_keys(points, voxel)
    if not inside.all():
        points, colours = points[inside], np.asarray(colours)[inside]
    if len(keys) == 0:
        return np.zeros((0, 3)), np.zeros((0, 3), np.uint8)
    _, s, c, n = _reduce(keys, points.astype(np.float64), np.asarray(colours, np.float32),
                         np.ones(len(keys), np.int32))
    n = n[:, None]
    return s / n, np.clip(np.rint(c / n), 0, 255).astype(np.uint8)


class VoxelGrid:
    """Points in, one averaged point per voxel out (:meth:`cloud`); see the module docstring."""

    def __init__(self, voxel: float):
        if not voxel > 0:
            raise ValueError(f"voxel size must be positive, got {voxel}")
        self.voxel = float(voxel)
        self._keys = np.zeros(0, np.int64)
        self._sums = np.zeros((0, 3))
        self._csums = np.zeros((0, 3), np.float32)
        self._counts = np.zeros(0, np.int32)  # points merged into the voxel
        self._views = np.zeros(0, np.int32)  # batches (keyframes) that put a point into it
        self._pending: list[tuple[np.ndarray, ...]] = []
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
        batch = _reduce(keys, points, np.asarray(colours, np.float32), np.ones(len(keys), np.int32))
        self._pending.append((*batch, np.ones(len(batch[0]), np.int32)))
        self._n_pending += len(batch[0])
        if self._n_pending >= max(len(self._keys), 1 << 16):
            self._merge()

    def _merge(self) -> None:
        """The pending batches reduced among themselves, then merged into the grid's sorted arrays in place:
        voxels the grid holds are summed where they lie, new ones inserted at their sorted places (one array
        copied at a time). Why not one sort of grid and batches together: that holds several copies of
        the whole grid at once, the map's peak of memory on a long log."""
        if not self._pending:
            return
        keys, *values = _reduce(*(np.concatenate(p) for p in zip(*self._pending, strict=True)))
        self._pending, self._n_pending = [], 0
        pos = np.searchsorted(self._keys, keys)
        held = np.zeros(len(keys), bool)
        inside = pos < len(self._keys)
        held[inside] = self._keys[pos[inside]] == keys[inside]
        at = pos[held]
        fields = ("_sums", "_csums", "_counts", "_views")
        for name, v in zip(fields, values, strict=True):
            getattr(self, name)[at] += v[held]  # unique keys: no index twice
        new = ~held
        if new.any():
            at = pos[new]
            self._keys = np.insert(self._keys, at, keys[new])
            for name, v in zip(fields, values, strict=True):
                setattr(self, name, np.insert(getattr(self, name), at, v[new], axis=0))

    def __len__(self) -> int:
        self._merge()
        return len(self._keys)

    @property
    def nbytes(self) -> int:
        """Bytes the grid's arrays hold (pending batches included)."""
        arrays: list[np.ndarray] = [self._keys, self._sums, self._csums, self._counts, self._views]
        arrays += [a for b in self._pending for a in b]
        return int(sum(a.nbytes for a in arrays))

    def cloud(self, min_views: int = 1) -> Cloud:
        """One point per voxel that at least ``min_views`` batches (:meth:`add` calls: keyframes) put points into:
        the centroid of its points, coloured by their mean colour."""
        self._merge()
        keep = self._views >= min_views
        if not keep.any():
            return Cloud.empty()
        n = self._counts[keep, None]
        pts = (self._sums[keep] / n).astype(np.float32)
        col = np.clip(np.rint(self._csums[keep] / n), 0, 255).astype(np.uint8)
        return Cloud(pts, col)
