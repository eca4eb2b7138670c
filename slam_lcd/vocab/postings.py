"""The database's storage: the inverted index in one flat arena, and growable per-keyframe arrays.

:class:`_Postings` holds every word's posting list (keyframe index and a value per posting) in
one arena; :class:`_Growable` is an amortised append-only array. Both are used by
:class:`~slam_lcd.vocab.database.BowDatabase` (docs/vocab_postings.md).
"""
from __future__ import annotations

import numpy as np

from .arrays import grow_in_place


def _ranges(starts: np.ndarray, lens: np.ndarray) -> np.ndarray:
    """Concatenation of ``arange(s, s + n)`` for every (s, n) pair, without a Python loop."""
    ends = np.cumsum(lens)
    idx = np.repeat(starts - (ends - lens), lens)
    idx += np.arange(len(idx))
    return idx


class _Postings:
    """Inverted index in one flat arena: word ``w``'s postings are ``kf[start[w] : start[w] + size[w]]``
    (keyframe index, int32) and ``val[...]`` (a number per posting: the database chooses), in
    insertion order, i.e. keyframe order.

    Each word owns a block of ``cap[w]`` slots; appending to a full block moves it to the arena's end
    with 1.5 times the room (so an entry is copied about twice on average), leaving a hole behind;
    when the holes exceed 1/8 of the blocks' room one compacting copy closes them. The slots written
    are then ~1.3 (at most ~1.4) times the postings, against ~1.4 times plus two numpy objects per
    word for per-word growable arrays. Appending a keyframe is a few vectorised numpy
    operations whatever its number of words, and a query's postings are copied out of contiguous
    blocks (see :meth:`gather`).

    Values are stored as uint16 while every value is an integer in 0..65535 (term counts always
    are), else as float64 (the first other value widens the arena, exactly); either way they take
    part in float64 arithmetic unchanged, so results do not depend on the storage.
    """

    _MIN_ROOM = 2  # slots of a word's first block
    _HOLES_DEN = 8  # compact when the holes exceed 1/8 of the blocks' room
    _LONG_RUN = 384  # postings from which one slice copy of a word beats its share of an index array
    _COPY_CHUNK = 1 << 18  # arena slots per step of a compaction

    def __init__(self):
        self.start = np.zeros(0, dtype=np.int64)  # per word: first slot of its block
        self.size = np.zeros(0, dtype=np.int64)  # per word: entries
        self.cap = np.zeros(0, dtype=np.int64)  # per word: slots of its block
        self.kf = np.empty(1024, dtype=np.int32)
        self.val = np.empty(1024, dtype=np.uint16)
        self.end = 0  # arena slots in use (blocks and holes)
        self.held = 0  # slots owned by blocks (sum of cap); end - held are holes

    @property
    def nbytes(self) -> int:
        """Memory the index holds: per-word arrays and the arena (all of it: a grown arena's tail is zeroed)."""
        return sum(a.nbytes for a in (self.start, self.size, self.cap, self.kf, self.val))

    def append(self, kf_index: int, words: np.ndarray, values: np.ndarray) -> None:
        """Postings of keyframe ``kf_index`` (newer than every keyframe so far): ``words`` sorted unique."""
        if not len(words):
            return
        top = int(words[-1]) + 1
        if top > len(self.size):
            grow = max(top, 2 * len(self.size)) - len(self.size)
            self.start, self.size, self.cap = (np.concatenate([a, np.zeros(grow, np.int64)])
                                               for a in (self.start, self.size, self.cap))
        if self.val.dtype == np.uint16 and not (values.min() >= 0 and values.max() <= 65535
                                                and np.array_equal(values, np.floor(values))):
            self.val = self.val.astype(np.float64)
        n = self.size[words]
        full = n == self.cap[words]
        if full.any():
            self._move(words[full], n[full])
        at = self.start[words] + n
        self.kf[at] = kf_index
        self.val[at] = values
        self.size[words] = n + 1

    def _move(self, words: np.ndarray, n: np.ndarray) -> None:
        """Move the full blocks of ``words`` (``n`` entries each) to the arena's end, with 1.5 times the room."""
        room = np.maximum(n + np.maximum(n >> 1, 1), self._MIN_ROOM)
        need = int(room.sum())
        if self._HOLES_DEN * (self.end - self.held) > self.held:
            self._compact()
        if self.end + need > len(self.kf):
            self._grow(need)
        new_start = self.end + np.cumsum(room) - room
        some = n > 0
        if some.any():
            src, dst = _ranges(self.start[words[some]], n[some]), _ranges(new_start[some], n[some])
            self.kf[dst] = self.kf[src]
            self.val[dst] = self.val[src]
        self.start[words] = new_start
        self.held += need - int(self.cap[words].sum())
        self.cap[words] = room
        self.end += need

    def _grow(self, need: int) -> None:
        """Room for ``need`` more slots: the arena grows by a quarter (or what is needed), in place.

        In place (:mod:`slam_lcd.vocab.arrays`) because a fresh array of this size is slow to fill:
        measured 140-360 ms at 3-4 million slots against 5-12 ms. The zeroed tail is resident at
        once, hence the small step."""
        length = max(self.end + need, int(1.25 * len(self.kf)))
        grow_in_place(self, "kf", (length,), self.end)
        grow_in_place(self, "val", (length,), self.end)

    def _compact(self) -> None:
        """Close the holes in place: blocks slide down in arena order with their room.

        A chunk of the arena at a time: mark the slots inside blocks, copy those down. No Python step
        per block (online, tens of thousands of small blocks move between compactions) and no large
        fresh array (first-touch page faults cost more than the copy itself).
        """
        owned = np.flatnonzero(self.cap)
        owned = owned[np.argsort(self.start[owned])]
        starts, caps = self.start[owned], self.cap[owned]
        ends = starts + caps
        to, inside_before = 0, 0
        for lo in range(0, self.end, self._COPY_CHUNK):
            hi = min(self.end, lo + self._COPY_CHUNK)
            edge = np.zeros(hi - lo + 1, dtype=np.int8)  # +1 where a block begins, -1 where one ends
            edge[0] = inside_before
            edge[starts[np.searchsorted(starts, lo):np.searchsorted(starts, hi)] - lo] += 1
            edge[ends[np.searchsorted(ends, lo):np.searchsorted(ends, hi)] - lo] -= 1
            inside = np.cumsum(edge[:-1], dtype=np.int8).view(bool)
            inside_before = int(inside[-1])
            kf, val = self.kf[lo:hi][inside], self.val[lo:hi][inside]
            self.kf[to:to + len(kf)] = kf
            self.val[to:to + len(kf)] = val
            to += len(kf)
        self.start[owned] = np.cumsum(caps) - caps
        self.end = self.held

    def gather(self, words: np.ndarray):
        """Concatenated postings of ``words`` (sorted): (keyframe index int64, value, at, runs).

        Word by word in the order of ``words``, each word's postings in keyframe order; ``runs[j]``
        postings belong to ``words[at[j]]`` (words without postings are left out). A word with many
        postings is one slice copy; the others share one vectorised index array (a Python step per
        word would cost more than their copy, an index array over long lists costs more memory
        traffic than the slices).
        """
        size = self.size
        if len(words) and words[-1] < len(size):
            lens = size[words]
        else:
            lens = np.zeros(len(words), dtype=np.int64)
            inside = words < len(size)
            lens[inside] = size[words[inside]]
        at = np.flatnonzero(lens)
        runs = lens[at]
        starts = self.start[words[at]]
        long = runs >= self._LONG_RUN
        if not long.any():
            src = _ranges(starts, runs)
            return self.kf[src].astype(np.int64), self.val[src], at, runs
        ends = np.cumsum(runs)
        offs = ends - runs
        kf = np.empty(int(ends[-1]), dtype=np.int64)
        val = np.empty(len(kf), dtype=self.val.dtype)
        for s, o, m in zip(starts[long].tolist(), offs[long].tolist(), runs[long].tolist(), strict=True):
            kf[o:o + m] = self.kf[s:s + m]
            val[o:o + m] = self.val[s:s + m]
        short = ~long
        if short.any():
            src, dst = _ranges(starts[short], runs[short]), _ranges(offs[short], runs[short])
            kf[dst] = self.kf[src]
            val[dst] = self.val[src]
        return kf, val, at, runs


class _Growable:
    def __init__(self, dtype, fill=0):
        self.a = np.full(64, fill, dtype=dtype)
        self.fill = fill
        self.n = 0

    def ensure(self, n: int) -> None:
        if n > len(self.a):
            b = np.full(max(n, 2 * len(self.a)), self.fill, dtype=self.a.dtype)
            b[: len(self.a)] = self.a
            self.a = b

    def push(self, v) -> None:
        self.ensure(self.n + 1)
        self.a[self.n] = v
        self.n += 1

    @property
    def view(self) -> np.ndarray:
        return self.a[: self.n]
