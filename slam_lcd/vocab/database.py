"""Bag-of-words keyframe database: tf-idf vectors, L1 score, inverted index, top-K queries.

A keyframe's vector has weight ``tf_w * idf_w`` per word, L1-normalised. The similarity of
two such vectors is ``s = 1 - 0.5 * ||v1 - v2||_1``, which for non-negative unit-L1 vectors
equals ``sum_w min(v1_w, v2_w)`` over the words they share: a query only visits the posting
lists (inverted index) of its own words, whatever the database size.

idf comes from the vocabulary's training images, or (``idf_source='database'``, and always in
online mode) from the database so far, smoothed as ``ln((1+N)/(1+n_w)) + 1``. With the
vocabulary's fixed idf a posting holds its keyframe's final weight ``tf*idf/norm``; with
database idf it holds the raw term count and each keyframe's normaliser is kept up to date
incrementally as document frequencies change, so old keyframes stay consistent while words and
keyframes are added.

Cost per keyframe: a query visits the postings of its words, and an insert refreshes the
normalisers of exactly the keyframes on those postings (the same entries), so neither touches
keyframes that share no word with it; both are vectorised over the postings (one flat arena,
:class:`~slam_lcd.vocab.postings._Postings`: the only Python steps are a slice copy per long
posting list). In online mode the nearest-word search is sub-linear in the word count above
``ann_min_words`` (:mod:`slam_lcd.vocab.word_index`).

The bag of words (:mod:`slam_lcd.vocab.bow`) and the inverted index (:mod:`slam_lcd.vocab.postings`)
have their own modules; the bag of words' names are importable from here too. The map snapshot
(:mod:`slam_lcd.vocab.snapshot`) reads and fills a database from outside, so this module does
not import it.
"""
from __future__ import annotations

import numpy as np

from ..errors import InputError
from ..types import LoopCandidate
from .bow import BowVector, bow_similarity
from .config import VocabConfig
from .descriptors import as_unit_vectors, descriptor_kind
from .postings import _Growable, _Postings
from .vocabulary import Vocabulary
from .word_index import WordIndex
from .words import IncrementalWords

__all__ = ["BowDatabase", "BowVector", "bow_similarity"]

# keyframes before / after the previous query's best whose words form the next search's pool (_pool)
_POOL_BEFORE = 1
_POOL_AFTER = 2


class BowDatabase:
    """Keyframe database over a vocabulary, or (``vocab=None``) online mode growing its own words.

    ``add(kf_id, stamp_ns, descriptors) -> BowVector``;
    ``query(descriptors_or_bow, top_k, exclude_recent_s, exclude_recent_n, ...) -> list[LoopCandidate]``.
    """

    def __init__(self, vocab: Vocabulary | None = None, conf: VocabConfig | None = None):
        self.vocab = vocab
        self.conf = conf or VocabConfig()
        self.online = vocab is None
        self.idf_from_database = self.online or self.conf.idf_source == "database"
        self.words: IncrementalWords | None = None  # online mode's growing vocabulary
        self._desc_kind: str | None = vocab.desc_kind if vocab else None
        self._desc_dim: int | None = vocab.desc_dim if vocab else None
        self.kf_ids: list[int] = []
        self._index_of: dict[int, int] = {}
        self._stamps = _Growable(np.int64)
        self._total = _Growable(np.float64)  # sum of term counts per keyframe
        self._logdf_sum = _Growable(np.float64)  # sum tf*ln(1+df) per keyframe (database idf)
        self._df = _Growable(np.float64)  # keyframes containing each word (database idf)
        # postings hold term counts with database idf (weights change as df does), the keyframe's final
        # weight tf*idf/norm with the vocabulary's fixed idf (what a query would compute per posting)
        self._post = _Postings()
        self._last_gather: tuple | None = None  # (keyframes then, words, kf, tf, at, runs) of the last scores()
        self._bow_words: list[np.ndarray] = []  # int32 word ids per keyframe (BowVector on access)
        self._bow_counts: list[np.ndarray] = []
        self._last_unit: tuple | None = None  # (descriptors, key, result) of the last conversion (_once)
        # online: the best keyframe (index) of the last query since the last add, and of the one before
        # that add: the keyframes around it lend their words to the next keyframe's search (_pool)
        self._query_best: int | None = None
        self._pool_at: int | None = None
        self._pool_cache: tuple | None = None  # (pool_at, keyframes, pool)
        # index of the current session's first keyframe: the recent-keyframe exclusion and the stamp
        # order apply within a session only (a map holds earlier sessions, recorded at other times)
        self.session_floor = 0

    def begin_session(self) -> None:
        """Keyframes added from now on belong to a new session (see :attr:`session_floor`)."""
        self.session_floor = len(self.kf_ids)
        self._query_best = self._pool_at = None

    def __len__(self) -> int:
        return len(self.kf_ids)

    @property
    def n_words(self) -> int:
        if self.vocab is not None:
            return len(self.vocab)
        return self.words.n_words if self.words is not None else 0

    # ---------------------------------------------------------------- weights
    def idf(self, words: np.ndarray | None = None) -> np.ndarray:
        """Current idf of ``words`` (all words when None)."""
        if not self.idf_from_database:
            assert self.vocab is not None  # the vocabulary's idf: not online, so there is a vocabulary
            return self.vocab.idf if words is None else self.vocab.idf[words]
        self._df.ensure(self.n_words)
        df = self._df.a[: max(self.n_words, self._df.n)] if words is None else self._df.a[words]
        return np.log((1.0 + len(self)) / (1.0 + df)) + 1.0

    def _database_norms(self) -> np.ndarray:
        """Normalisers ``sum_w tf_w * idf_w`` of every keyframe under the current database idf."""
        n = len(self)
        return (np.log(1.0 + n) + 1.0) * self._total.a[:n] - self._logdf_sum.a[:n]

    # ------------------------------------------------------------- quantising
    def _check(self, desc: np.ndarray) -> np.ndarray:
        d = np.asarray(desc)
        if d.ndim != 2:
            raise InputError(f"descriptors must be (N, D), got shape {d.shape}")
        kind = descriptor_kind(d)
        if self._desc_kind is None:
            self._desc_kind, self._desc_dim = kind, d.shape[1]
        elif (kind, d.shape[1]) != (self._desc_kind, self._desc_dim):
            raise InputError(f"descriptors {d.dtype}{tuple(d.shape)} differ from the database's "
                             f"({self._desc_kind}, {self._desc_dim} columns)")
        return d

    def _once(self, d: np.ndarray, what: str, compute):
        """``compute(d)``, kept for the same array: the loop detector transforms a keyframe, then adds
        the same descriptors, so their conversion (online: unit vectors, and the word search keyed
        on them; with a vocabulary: the tree descent) is done once."""
        # the sum catches a buffer refilled in place (in the array's own type: a float64 sum of 256k
        # float32 values took ~0.26 ms, twice per keyframe)
        key = (what, id(d), d.shape, float(d.sum()))
        c = self._last_unit
        if c is not None and c[0] is d and c[1] == key:
            return c[2]
        out = compute(d)
        self._last_unit = (d, key, out)
        return out

    def _unit(self, d: np.ndarray) -> np.ndarray:
        return self._once(d, "unit", as_unit_vectors)

    def _quantized(self, d: np.ndarray) -> np.ndarray:
        assert self.vocab is not None  # called with a vocabulary only
        return self._once(d, "words", self.vocab.quantize)

    def transform(self, descriptors: np.ndarray) -> BowVector:
        """Bag of words of descriptors without adding them (online mode: nearest existing word)."""
        d = self._check(descriptors)
        if self.vocab is not None:
            return BowVector.from_word_ids(self._quantized(d))
        if self.words is None or self.words.n_words == 0 or len(d) == 0:
            return BowVector.from_word_ids(np.zeros(0, dtype=np.int64))
        # online: nearest existing word (a tracked feature: its track's word once the index is active,
        # IncrementalWords.query_words); a feature farther than the word radius would found a new word
        # that no keyframe holds yet, so it is left out
        words = self.words.query_words(self._unit(d), self._pool())
        return BowVector.from_word_ids(words[words >= 0])

    # ------------------------------------------------------------------- add
    def add(self, kf_id: int, stamp_ns: int, descriptors: np.ndarray) -> BowVector:
        """Insert a keyframe (online mode also grows the words from it); returns its bag of words."""
        if kf_id in self._index_of:
            raise InputError(f"keyframe id {kf_id} is already in the database")
        if self._stamps.n > self.session_floor and stamp_ns < self._stamps.view[-1]:
            raise InputError(f"keyframe {kf_id}: stamp {stamp_ns} is older than the previous keyframe's")
        d = self._check(descriptors)
        if self.vocab is not None:
            bow = BowVector.from_word_ids(self._quantized(d))
        else:
            u = self._unit(d)
            if self.words is None:
                assert self._desc_kind is not None  # _check set it
                self.words = IncrementalWords(u.shape[1], self.conf.match_ratio, self.conf.match_max_distance,
                                              self._desc_kind, radius=self.conf.online_word_radius,
                                              index=WordIndex.from_config(u.shape[1], self.conf))
            bow = BowVector.from_word_ids(self.words.add_image(u, self._pool()))
        self._insert(kf_id, stamp_ns, bow)
        self._pool_at, self._query_best = self._query_best, None
        return bow

    def _pool(self) -> np.ndarray | None:
        """Words of the keyframes around the one the previous keyframe's query ranked first (online mode).

        Why: a keyframe that matched an earlier place is followed by keyframes that see that place's
        next landmarks; those words let most of the next keyframe's untracked features skip the
        graph search (:meth:`IncrementalWords._pool_hints`). Keyframes ``_POOL_BEFORE`` before to
        ``_POOL_AFTER`` after it (a revisit may run either way along the old route). Float
        descriptors only: with ORB's binary words (less distinct; the word radius is ~31 of 256 bits)
        a pool from an aliased place lent its words to the next query, and the corridor's ORB run
        accepted a false loop (precision 1.0 -> 0.977); ORB keeps the graph search.
        """
        j = self._pool_at
        if j is None or self.vocab is not None or not self.conf.ann_pool or self._desc_kind != "float":
            return None
        c = self._pool_cache
        if c is None or c[0] != j or c[1] != len(self):
            parts = self._bow_words[max(0, j - _POOL_BEFORE): j + _POOL_AFTER + 1]
            c = self._pool_cache = (j, len(self), np.unique(np.concatenate(parts)).astype(np.int64))
        return c[2]

    def add_bow(self, kf_id: int, stamp_ns: int, bow: BowVector) -> BowVector:
        """Insert a keyframe whose bag of words is already known (word ids of this database's vocabulary)."""
        if kf_id in self._index_of:
            raise InputError(f"keyframe id {kf_id} is already in the database")
        if self._stamps.n > self.session_floor and stamp_ns < self._stamps.view[-1]:
            raise InputError(f"keyframe {kf_id}: stamp {stamp_ns} is older than the previous keyframe's")
        if len(bow) and (bow.words.min() < 0 or bow.words.max() >= self.n_words):
            raise InputError(f"keyframe {kf_id}: word ids outside the vocabulary (0..{self.n_words - 1})")
        self._insert(kf_id, stamp_ns, bow)
        return bow

    def _insert(self, kf_id: int, stamp_ns: int, bow: BowVector) -> None:
        index = len(self.kf_ids)
        if self.idf_from_database:
            self._df.ensure(self.n_words)
            self._df.n = max(self._df.n, self.n_words)
            # df of this keyframe's words rises by one: refresh the normalisers of the keyframes on
            # their postings (only those: the cost is that of a query with these words)
            kf, tf, at, runs = self._gather(bow.words)
            self._last_gather = None
            old = self._df.a[bow.words]
            delta = np.log(2.0 + old) - np.log(1.0 + old)
            if len(kf):
                np.add.at(self._logdf_sum.a, kf, tf * np.repeat(delta[at], runs))
            self._df.a[bow.words] = old + 1.0
            self._logdf_sum.push(float((bow.counts * np.log(2.0 + old)).sum()))
            self._post.append(index, bow.words, bow.counts)
        else:
            assert self.vocab is not None  # the vocabulary's idf: not online, so there is a vocabulary
            w = bow.counts * self.vocab.idf[bow.words]
            norm = float(w.sum())
            self._logdf_sum.push(0.0)
            self._post.append(index, bow.words, w / norm if norm > 0 else np.zeros_like(w))
        self._total.push(float(bow.counts.sum()))
        self._stamps.push(int(stamp_ns))
        self.kf_ids.append(kf_id)
        self._index_of[kf_id] = index
        self._bow_words.append(bow.words.astype(np.int32))
        self._bow_counts.append(np.asarray(bow.counts, dtype=np.float64))

    def _gather(self, words: np.ndarray):
        """Postings of ``words`` (sorted unique) as :meth:`_Postings.gather` gives them, re-using what the
        last query gathered when no keyframe was added since (the loop detector queries a keyframe,
        then inserts it: mostly the same words). The cached words come first, then the others."""
        c = self._last_gather
        if c is None or c[0] != len(self) or not len(c[1]) or not len(words):
            return self._post.gather(words)
        c_words, c_kf, c_val, c_at, c_runs = c[1:]
        loc = np.searchsorted(words, c_words)
        hit = (loc < len(words)) & (words[np.minimum(loc, len(words) - 1)] == c_words)
        missing = np.ones(len(words), dtype=bool)
        missing[loc[hit]] = False
        fresh = np.flatnonzero(missing)
        kf, val, at, runs = self._post.gather(words[fresh])
        kept = hit[c_at]  # cached words with postings that are among ``words`` (usually all)
        if not kept.all():
            take = np.repeat(kept, c_runs)
            c_kf, c_val, c_at, c_runs = c_kf[take], c_val[take], c_at[kept], c_runs[kept]
        if not len(kf):
            return c_kf, c_val, loc[c_at], c_runs
        return (np.concatenate([c_kf, kf]), np.concatenate([c_val, val]), np.concatenate([loc[c_at], fresh[at]]),
                np.concatenate([c_runs, runs]))

    def bow(self, kf_id: int) -> BowVector:
        i = self._index_of[kf_id]
        return BowVector(self._bow_words[i].astype(np.int64), self._bow_counts[i])

    # ----------------------------------------------------------------- query
    def _query_weights(self, bow: BowVector):
        """(words, their idf, the query's L1-normalised tf-idf weights), or None when the query weighs nothing.

        Online, words founded after ``bow`` was made (ids beyond the vocabulary) are left out.
        """
        words = bow.words[bow.words < max(self.n_words, 1)] if self.online else bow.words
        counts = bow.counts[: len(words)] if self.online else bow.counts
        idf_q = self.idf(words)
        wq = counts * idf_q
        sq = wq.sum()
        if sq <= 0:
            return None
        return words, idf_q, wq / sq

    def scores(self, bow: BowVector) -> np.ndarray:
        """Similarity ``1 - 0.5 ||v_q - v_k||_1`` of ``bow`` with every keyframe (inverted index)."""
        n = len(self)
        out = np.zeros(n)
        weighed = self._query_weights(bow) if n and len(bow) else None
        if weighed is None:
            return out
        words, idf_q, a = weighed
        kf, val, at, runs = self._post.gather(words)
        if self.idf_from_database:
            self._last_gather = (n, words, kf, val, at, runs)
        if not len(kf):
            return out
        if not self.idf_from_database:  # the postings hold the keyframes' weights
            return np.bincount(kf, weights=np.minimum(np.repeat(a[at], runs), val), minlength=n)
        norms = self._database_norms()  # per keyframe, then looked up: the same numbers, fewer operations
        norms[~(norms > 0)] = np.inf  # weight 0, as the direct formula gives an empty keyframe
        b = np.repeat(idf_q[at], runs) * val
        b /= norms[kf]
        return np.bincount(kf, weights=np.minimum(np.repeat(a[at], runs), b, out=b), minlength=n)

    def query(self, descriptors_or_bow, top_k: int = 5, exclude_recent_s: float = 0.0,
              exclude_recent_n: int = 0, *, query_id: int | None = None, stamp_ns: int | None = None,
              normalise_by_previous: bool | None = None) -> list[LoopCandidate]:
        """Top-K keyframes by score, best first, skipping the recent window (and the query itself).

        The window is relative to ``stamp_ns`` (default: the newest keyframe's stamp). With
        ``normalise_by_previous`` scores are divided by the score against the newest keyframe
        that is not the query (DBoW2's alpha); below ``min_previous_score`` nothing is returned.
        """
        c = self.conf
        ex_s, ex_n = exclude_recent_s, exclude_recent_n
        norm_prev = c.normalise_by_previous if normalise_by_previous is None else normalise_by_previous
        bow = descriptors_or_bow if isinstance(descriptors_or_bow, BowVector) else self.transform(descriptors_or_bow)
        n = len(self)
        if n == 0 or top_k <= 0:
            return []
        s = self.scores(bow)
        keep = np.ones(n, dtype=bool)
        self_index = self._index_of.get(query_id) if query_id is not None else None
        if self_index is not None:
            keep[self_index] = False
        floor = min(self.session_floor, n)
        if ex_n > 0:
            keep[max(floor, n - ex_n):] = False
        stamps = self._stamps.view
        ref = stamps[-1] if stamp_ns is None else int(stamp_ns)
        if ex_s > 0:
            keep[floor:] &= stamps[floor:] < ref - int(round(ex_s * 1e9))
        if norm_prev:
            prev = n - 1 if self_index != n - 1 else n - 2
            if prev < 0 or s[prev] < c.min_previous_score:
                return []
            s = s / s[prev]
        cand = np.flatnonzero(keep & (s > 0))
        if not len(cand):
            return []
        if len(cand) > top_k:
            cand = cand[np.argpartition(-s[cand], top_k - 1)[:top_k]]
        cand = cand[np.argsort(-s[cand], kind="stable")]
        self._query_best = int(cand[0])
        qid = -1 if query_id is None else int(query_id)
        return [LoopCandidate(query_id=qid, match_id=int(self.kf_ids[i]), bow_score=float(s[i])) for i in cand]
