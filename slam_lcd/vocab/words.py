"""Incremental word learning (paper §III-C): words are feature tracks between consecutive images.

The first image's descriptors found the initial words. Every next image is matched to the
previous one (mutual nearest neighbours, ratio and distance tests): a matched feature joins
the word of the feature it matched, whose centre moves (running mean of the members,
re-normalised); an unmatched feature founds a new word. The number of words therefore
follows the scene, not a k chosen in advance.

Training keeps each word's member sum in float64 and normalises it (exactly reproducible). In
online mode (``radius`` set: long runs, up to ~10^6 words) a word keeps its unit centre
(float32) and the length of its member sum instead: the sum is ``centre * length``, updated in
float32 (:func:`_moved_centres`), so the running mean needs no float64 copy of every centre (1 kB
instead of 3 kB per word). In online mode the nearest existing
word of an unmatched feature comes from a :class:`~slam_lcd.vocab.word_index.WordIndex`
(exact for small vocabularies, sub-linear above a size).
"""
from __future__ import annotations

import numpy as np

from ..errors import ConfigError
from ..vision.column_best import first_in_column
from .arrays import grow_in_place
from .descriptors import default_match_distance, group_sums, normalise_rows, unit_distance
from .word_index import WordIndex, exact_nearest

# most words the per-word arrays grow by at once (see IncrementalWords._grow)
_GROW_STEP = 16384
# a pool that decides fewer than this share of the rows it scores (at least _POOL_JUDGED of them) is not
# a revisit: the next _POOL_PAUSE images search without it (IncrementalWords._pool_hints)
_POOL_MIN_YIELD = 0.2
_POOL_JUDGED = 32
_POOL_PAUSE = 3


def mutual_nn_unit(d1: np.ndarray, d2: np.ndarray, ratio: float | None, max_distance: float | None,
                   return_distances: bool = False):
    """:func:`slam_lcd.features.matching.mutual_nn_match` for unit vectors, from one similarity product.

    Same rule (mutual nearest neighbours, ``best < ratio * second``, ``best < max_distance``)
    with the distance ``sqrt(2 - 2 s)`` of unit vectors; no full distance matrix is formed
    (the product is most of the cost of growing the words, so the passes over it are few).
    Why float32 only: candidates from a bfloat16 or int8 product, decided in float32, saved less than
    15 % of a keyframe's database time at 10,000 keyframes even on a CPU with VNNI and BF16, and
    both are emulated (slower) on AVX2-only CPUs (docs/vocab_online.md).
    """
    n1, n2 = len(d1), len(d2)
    if n1 == 0 or n2 == 0:
        m = np.zeros((0, 2), dtype=np.int64)
        return (m, np.zeros(0, np.float32)) if return_distances else m
    s = d1 @ d2.T
    nn12 = s.argmax(axis=1)
    i1 = np.arange(n1)
    best = s[i1, nn12]
    keep = first_in_column(s, nn12, best, largest=True)
    d_best = unit_distance(best)
    if ratio is not None and n2 > 1:
        s[i1, nn12] = -np.inf
        d_second = unit_distance(s.max(axis=1))
        keep &= d_best < ratio * np.maximum(d_second, 1e-12)
    if max_distance is not None:
        keep &= d_best < max_distance
    m = np.stack([i1[keep], nn12[keep]], axis=1).astype(np.int64)
    return (m, d_best[keep].astype(np.float32)) if return_distances else m


def _moved_centres(centres: np.ndarray, lengths: np.ndarray, desc: np.ndarray, inv: np.ndarray,
                   per: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(unit centres, member-sum lengths) of the touched words after this image, float32.

    ``centres``, ``lengths``: the touched words' before (a gathered copy, overwritten);
    ``inv``: row of ``desc`` -> touched word, ``per``: rows per touched word. The member sum is
    ``centre * length`` plus the new members; most words get one member per image (added in
    place), the rest are accumulated with ``np.add.at``.

    Why float32: the sum of a word's members is only ever normalised again, and float32 keeps
    its direction to ~1e-7, far below the ~0.3 spread of the members themselves; the float64
    expression took ~2.5x longer per keyframe (twice the bytes for every pass over ~1000 x 256
    values, plus a conversion each way), which was ~10 % of a keyframe's database time.
    """
    sums = centres
    sums *= lengths.astype(np.float32)[:, None]
    single = per[inv] == 1
    sums[inv[single]] += desc[single]
    if not single.all():
        multi = ~single
        np.add.at(sums, inv[multi], desc[multi])
    length = np.sqrt(np.einsum("ij,ij->i", sums, sums))
    sums *= (np.float32(1.0) / np.maximum(length, np.float32(1e-12)))[:, None]
    return sums, length


class IncrementalWords:
    """Growing set of words over a sequence of images (training and online mode share it).

    ``radius``: in online mode, an unmatched feature whose nearest existing word is closer
    than this joins that word instead of founding a new one (so a revisited place reuses its
    old words); ``None`` is the paper's training rule (unmatched always founds a word).
    ``index``: the nearest-word search used with ``radius`` (default: exact search).
    """

    def __init__(self, dim: int, ratio: float | None = 0.9, max_distance: float | None = None,
                 kind: str = "float", radius: float | None = None, index: WordIndex | None = None):
        self.dim = dim
        self.ratio = ratio
        self.max_distance = default_match_distance(kind) if max_distance is None else max_distance
        self.radius = radius
        self.index = index
        self.version = 0  # bumped whenever words move or are founded (invalidates cached searches)
        # training: float64 member sums; online: |sum of members| per word (sum = centre * length)
        self._sums = np.zeros((1024, dim), dtype=np.float64) if radius is None else None
        self._lengths = np.zeros(1024, dtype=np.float64)
        self._centres = np.zeros((1024, dim), dtype=np.float32)
        self._counts = np.zeros(1024, dtype=np.int64)  # features per word
        self._images = np.zeros(1024, dtype=np.int64)  # images in which the word occurs
        self.n_words = 0
        self.n_images = 0
        self._prev_desc: np.ndarray | None = None
        self._prev_words: np.ndarray | None = None
        self._prev_cands: np.ndarray | None = None  # each previous feature's candidate words (index mode)
        self._prev_age: np.ndarray | None = None  # images since that feature's candidates came from the index
        # (index mode, ``index.hint_gap``) the features of the image before the previous one that no
        # feature of the previous image matched: (unit descriptors, candidates, words, ages)
        self._gap: tuple | None = None
        self._pool_pause = 0  # images left that search without the pool (see _pool_hints)
        self._pool_missed = False  # this image's pool decided few of the rows it scored
        self._match_cache: tuple | None = None  # (n_images, descriptors, matches, distances)
        self._search_cache: tuple | None = None  # (version, descriptors, pool, ids, sims, candidates, age)

    # ------------------------------------------------------------------ state
    @property
    def centres(self) -> np.ndarray:
        return self._centres[: self.n_words]

    @property
    def counts(self) -> np.ndarray:
        return self._counts[: self.n_words]

    @property
    def image_counts(self) -> np.ndarray:
        return self._images[: self.n_words]

    def _grow(self, need: int) -> None:
        """Room for ``need`` words: the per-word arrays grow in place by a quarter, at most ``_GROW_STEP`` words.

        In place and in small steps, not doubled into fresh copies (:mod:`slam_lcd.vocab.arrays`:
        at 260k words doubling the centres cost 263 ms on one keyframe of the 10-lap log). A step
        of at most 16k words (16 MB of centres) keeps each pause short; the total is the same.
        """
        cap = len(self._counts)
        if need <= cap:
            return
        new = max(need, cap + min(cap // 4, _GROW_STEP))
        for name in ("_sums", "_lengths", "_centres", "_counts", "_images"):
            if getattr(self, name) is not None:
                grow_in_place(self, name, (new,) + getattr(self, name).shape[1:], cap)

    # ----------------------------------------------------------------- search
    @staticmethod
    def _same(cached: np.ndarray, desc: np.ndarray) -> bool:
        return cached is desc or (cached.shape == desc.shape and np.array_equal(cached, desc))

    @classmethod
    def _same_pool(cls, cached: np.ndarray | None, pool: np.ndarray | None) -> bool:
        return cached is pool or (cached is not None and pool is not None and cls._same(cached, pool))

    def _match(self, desc: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Matches (row, previous row) of ``desc`` to the previous image and their distances.

        Kept for the same image.
        """
        c = self._match_cache
        if c is not None and c[0] == self.n_images and self._same(c[1], desc):
            return c[2], c[3]
        if len(desc) and self._prev_desc is not None and len(self._prev_desc):
            m, dist = mutual_nn_unit(desc, self._prev_desc, self.ratio, self.max_distance, return_distances=True)
        else:
            m, dist = np.zeros((0, 2), dtype=np.int64), np.zeros(0, np.float32)
        self._match_cache = (self.n_images, desc, m, dist)
        return m, dist

    def nearest(self, desc: np.ndarray, pool: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """(word id, similarity) of the nearest existing word of each unit-vector row.

        With an active index, a feature that matches one of the previous image's is decided
        among that feature's candidate words and its word (see ``ann_hint_images``); the others
        search the index. ``pool``: word ids likely to be seen (the words of the keyframes around
        the place the previous keyframe was retrieved at): a row still to search whose best pool
        word lies within ``radius`` takes that word's neighbourhood in the pool as its candidates
        instead of searching the graph (:meth:`_pool_hints`). The answer is kept until the words
        change, so a keyframe's query followed by its insertion (the loop detector's order, the same
        pool) searches once.
        """
        desc = np.ascontiguousarray(desc, dtype=np.float32)
        return self._searched(desc, pool, tracked=False)[:2]

    def query_words(self, desc: np.ndarray, pool: np.ndarray | None = None) -> np.ndarray:
        """Each unit-vector row's word for a query, -1 where :meth:`add_image` would found a new word.

        A row's nearest existing word when within ``radius`` (online mode), except, with the index
        active, a row handed over by its match to the previous image (a track younger than
        ``ann_hint_images``, matched closer than ``ann_hint_max_distance``): it takes its track's word,
        the word :meth:`add_image` gives it. Why: the index decides such a row among its track's few
        candidate words anyway, and that re-ranking (~800 of ~1,000 rows of a keyframe) was the
        largest part of a revisit's word search (docs/vocab_online.md); the row's own word is known.
        Without the index every row gets its exact nearest word.
        """
        if self.radius is None:
            raise ConfigError("IncrementalWords.query_words needs the online mode (a word radius)")
        desc = np.ascontiguousarray(desc, dtype=np.float32)
        ids, sims = self._searched(desc, pool, tracked=True)[:2]
        held = np.isnan(sims)  # rows that kept their track's word (see _searched)
        with np.errstate(invalid="ignore"):
            return np.where((unit_distance(sims) < self.radius) | held, ids, -1)

    def _searched(self, desc: np.ndarray, pool: np.ndarray | None = None, tracked: bool = False) -> tuple:
        """(ids, similarities, candidates, ages) of each row's nearest word; ``tracked``: rows handed over
        by their match to the previous image keep that feature's word and candidates undecided (similarity
        NaN): their word is the track's anyway (:meth:`query_words`, :meth:`add_image`)."""
        c = self._search_cache
        if c is not None and c[0] == (self.version, tracked) and self._same(c[1], desc) and self._same_pool(c[2], pool):
            return c[3:]
        n = len(desc)
        cands = age = None
        if self.index is None or not self.index.active:
            ids, sims = exact_nearest(self.centres, desc)
        else:
            hints: np.ndarray | None = None
            search: np.ndarray | None = None
            age = np.zeros(n, dtype=np.int64)
            m, dist = self._match(desc)
            held = None  # rows that keep their track's word and candidates (tracked=True)
            if self._prev_cands is not None and len(m):
                hints = np.full((n, self._prev_cands.shape[1] + 1), -1, dtype=np.int64)
                search = np.ones(n, dtype=bool)
                self._hand_over(m[:, 0], m[:, 1], dist, (self._prev_cands, self._prev_words, self._prev_age), 1,
                                hints, search, age)
                if tracked:
                    held = ~search
                if self._gap is not None:
                    self._gap_hints(desc, hints, search, age)
            if pool is not None and len(pool) and self.radius is not None and self._pool_pause == 0:
                if hints is None:
                    hints = np.full((n, self.index.hint_candidates + 1), -1, dtype=np.int64)
                    search = np.ones(n, dtype=bool)
                assert search is not None  # made with hints
                self._pool_hints(desc, pool, hints, search)
            if held is None or not held.any():
                ids, sims, cands = self.index.nearest(self.centres, desc, hints, search)
            else:
                assert hints is not None and search is not None  # held is made from them
                rest = np.flatnonzero(~held)
                k = self.index.hint_candidates
                ids, sims = hints[:, k].copy(), np.full(n, np.nan, dtype=np.float32)
                cands = hints[:, :k].copy()
                if len(rest):
                    ids[rest], sims[rest], cands[rest] = self.index.nearest(self.centres, desc[rest], hints[rest],
                                                                            search[rest])
        self._search_cache = ((self.version, tracked), desc, pool, ids, sims, cands, age)
        return ids, sims, cands, age

    def _gap_hints(self, desc: np.ndarray, hints: np.ndarray, search: np.ndarray, age: np.ndarray) -> None:
        """Hints for features lost for one image: rows still to search, matched to the features of the
        image before the previous one that the previous image did not match (a landmark missed once).

        Same rule as a match to the previous image (mutual nearest neighbours, ratio and distance
        tests, then ``hint_max_distance`` and the track's age), between the two small sets only:
        a few hundred rows against the few hundred lost features, instead of a graph search each.
        """
        assert self._gap is not None  # _searched calls this with one
        g_desc, g_cands, g_words, g_age = self._gap
        rows = np.flatnonzero(search)
        if len(rows) == 0 or len(g_desc) == 0:
            return
        m, dist = mutual_nn_unit(desc[rows], g_desc, self.ratio, self.max_distance, return_distances=True)
        self._hand_over(rows[m[:, 0]], m[:, 1], dist, (g_cands, g_words, g_age), 2, hints, search, age)

    def _pool_hints(self, desc: np.ndarray, pool: np.ndarray, hints: np.ndarray, search: np.ndarray) -> None:
        """Rows still to search whose best candidate in ``pool`` (by the index's projected scoring, then
        exactly) lies within ``radius`` take those candidates as hints instead of a graph search.

        Why: on a revisit most rows left to search are landmarks entering the view again (or lost for
        a few images); their words were seen in the keyframes around the place just retrieved. On a
        revisit of the synthetic stream 136 of ~200 graph searches per keyframe are replaced this way
        (58 % of all searches over 3,000 keyframes), and for ~1 of those 136 the exhaustive nearest word
        is another word (a near-duplicate of the same landmark) than the pool's (docs/vocab_online.md).

        On a new route the previous query's best keyframe is no revisit: its words decided ~3.5 of ~200
        rows per keyframe, for ~1.5 ms of scoring. A pool that decides fewer than ``_POOL_MIN_YIELD`` of
        the rows it scores pauses the pool for the next ``_POOL_PAUSE`` images (decided per image in
        :meth:`add_image`, so an image's query and insertion see the same pool).
        """
        assert self.index is not None  # _searched calls this in index mode
        rows = np.flatnonzero(search)
        if len(rows) == 0:
            return
        cand = self.index.pool_candidates(desc[rows], pool)
        best, sim = self.index.decide(self.centres, desc[rows], cand)
        ok = (cand[:, 0] >= 0) & (unit_distance(sim) < self.radius)
        self._pool_missed = len(ok) >= _POOL_JUDGED and ok.mean() < _POOL_MIN_YIELD
        rows = rows[ok]
        hints[rows, : cand.shape[1]] = cand[ok]  # a row still to search has no hints yet: the rest stays -1
        search[rows] = False
        self.index.n_pooled += len(rows)

    def _hand_over(self, i: np.ndarray, j: np.ndarray, dist: np.ndarray, track: tuple, steps: int,
                   hints: np.ndarray, search: np.ndarray, age: np.ndarray) -> None:
        """Rows ``i`` matched (at ``dist``) to features ``j`` of an earlier image ``steps`` images back
        take those features' candidates and word as hints instead of a graph search, when the match is
        closer than ``hint_max_distance`` and the candidates are younger than ``hint_images`` images.
        ``track``: (candidates, words, ages) of that image's features.
        """
        assert self.index is not None  # _searched calls this in index mode
        cands, words, ages = track
        ok = (ages[j] < self.index.hint_images) & (dist < self.index.hint_max_distance)
        i, j = i[ok], j[ok]
        kc = cands.shape[1]
        hints[i, :kc] = cands[j]
        hints[i, kc] = words[j]
        search[i] = False
        age[i] = ages[j] + steps

    def _nearest_rows(self, desc: np.ndarray, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Nearest words of ``desc[rows]`` (exhaustive search, or the cached answer for ``desc``)."""
        c = self._search_cache
        if c is not None and c[0] == self.version and self._same(c[1], desc):
            return c[3][rows], c[4][rows]
        return exact_nearest(self.centres, desc[rows])

    # ----------------------------------------------------------------- update
    def add_image(self, desc: np.ndarray, pool: np.ndarray | None = None) -> np.ndarray:
        """Assign each unit-vector descriptor of the next image to a word (creating words); returns word ids.

        ``pool``: as for :meth:`nearest` (the same as the image's query used, or the search is redone).
        """
        desc = np.ascontiguousarray(desc, dtype=np.float32)
        n = len(desc)
        words = np.full(n, -1, dtype=np.int64)
        m, _ = self._match(desc)
        if len(m):  # (matches are to the previous image's features)
            assert self._prev_words is not None
            words[m[:, 0]] = self._prev_words[m[:, 1]]
        cands = age = None
        if self.radius is not None and self.n_words:
            free = np.flatnonzero(words < 0)
            if self.index is not None and self.index.active:
                # every row's candidates are kept for the next image's tracked features
                ids, sims, cands, age = self._searched(desc, pool, tracked=True)
                best, sim = ids[free], sims[free]
            else:
                best, sim = self._nearest_rows(desc, free) if len(free) else (free, np.zeros(0, np.float32))
            dist = unit_distance(sim)
            near = dist < self.radius
            words[free[near]] = best[near]
        new = np.flatnonzero(words < 0)
        if len(new):
            self._grow(self.n_words + len(new))
            words[new] = np.arange(self.n_words, self.n_words + len(new))
            self.n_words += len(new)
        touched, moved = words[:0], None
        if n:
            touched, inv, per = np.unique(words, return_inverse=True, return_counts=True)
            if self._sums is not None:
                self._sums[touched] += group_sums(desc, inv, len(touched))
                self._centres[touched] = normalise_rows(self._sums[touched])
            else:
                moved, self._lengths[touched] = _moved_centres(self._centres[touched], self._lengths[touched], desc,
                                                               inv, per)
                self._centres[touched] = moved
            self._counts[touched] += per
            self._images[touched] += 1
            self.version += 1
        if self.index is not None:
            self.index.update(self.centres, touched, moved)
        self.n_images += 1
        self._pool_pause = _POOL_PAUSE if self._pool_missed else max(0, self._pool_pause - 1)
        self._pool_missed = False
        self._gap = None
        # (candidates come from the index; the previous image's arrays are set together)
        if cands is not None and self.index is not None and self.index.hint_gap and self._prev_cands is not None:
            assert self._prev_desc is not None and self._prev_words is not None and self._prev_age is not None
            lost = np.ones(len(self._prev_desc), dtype=bool)
            lost[m[:, 1]] = False
            self._gap = (self._prev_desc[lost], self._prev_cands[lost], self._prev_words[lost], self._prev_age[lost])
        self._prev_desc, self._prev_words = desc, words
        self._prev_cands, self._prev_age = cands, age
        self._match_cache = self._search_cache = None
        return words
