"""The BoW database's inverted index (one flat arena of per-word blocks) against straightforward references.

The references are a dict of Python lists (what a posting list is) and the direct L1 formula
(``bow_similarity``); the bags are random, over many keyframes, so that blocks move and the arena
is compacted several times, with words that first appear late, words never seen, and empty bags.
"""
from __future__ import annotations

import numpy as np
import pytest

from slam_lcd.vocab import BowDatabase, BowVector, VocabConfig, bow_similarity, train_hkmeans
from slam_lcd.vocab.database import _Postings


class ListPostings:
    """Reference posting lists: word -> Python list of (keyframe index, value), in insertion order."""

    def __init__(self):
        self.lists: dict[int, list[tuple[int, float]]] = {}

    def append(self, kf_index, words, values):
        for w, v in zip(words.tolist(), values.tolist(), strict=True):
            self.lists.setdefault(w, []).append((kf_index, v))

    def gather(self, words):
        kf, val, at, runs = [], [], [], []
        for i, w in enumerate(words.tolist()):
            postings = self.lists.get(w, [])
            if postings:
                at.append(i)
                runs.append(len(postings))
            for k, v in postings:
                kf.append(k)
                val.append(v)
        return (np.array(kf, np.int64), np.array(val, np.float64), np.array(at, np.int64),
                np.array(runs, np.int64))


def random_bag(rng, k, n_words, zipf=1.3):
    """Bag of keyframe ``k``: Zipf-distributed word ids (long and short posting lists); the words
    reachable grow with ``k`` (later keyframes bring new words); every 17th bag is empty."""
    if k % 17 == 5:
        return BowVector.from_word_ids(np.zeros(0, np.int64))
    reach = min(n_words, 40 + 6 * k)
    ids = (rng.zipf(zipf, size=int(rng.integers(1, 120))) - 1) % reach
    ids = (ids * 7919 + k // 50) % reach  # frequent words are not all small ids; the mix shifts slowly
    return BowVector.from_word_ids(ids)


def count_compactions(monkeypatch):
    calls = []
    real = _Postings._compact

    def counted(self):
        calls.append(self.end - self.held)
        return real(self)

    monkeypatch.setattr(_Postings, "_compact", counted)
    monkeypatch.setattr(_Postings, "_COPY_CHUNK", 37)  # many chunks, blocks across their borders
    return calls


def same_gather(got, want):
    """Same postings in the same order; values equal as float64 (they are stored compactly when they can be)."""
    kf, val, at, runs = got
    assert kf.dtype == at.dtype == runs.dtype == np.int64
    return all(np.array_equal(x, y) for x, y in zip((kf, val.astype(np.float64), at, runs), want, strict=True))


def append(store, k, bow):
    store.append(k, bow.words, bow.counts)


@pytest.mark.parametrize("long_run", [3, _Postings._LONG_RUN, 10**9])
def test_gather_equals_posting_lists_across_moves_and_compactions(monkeypatch, long_run):
    """Long posting lists are copied as slices, short ones through one index array: both, and the mix."""
    rng = np.random.default_rng(21)
    compactions = count_compactions(monkeypatch)
    monkeypatch.setattr(_Postings, "_LONG_RUN", long_run)
    store, ref = _Postings(), ListPostings()
    n_words = 2500
    for k in range(700):
        bow = random_bag(rng, k, n_words)
        append(store, k, bow)
        append(ref, k, bow)
        if k % 7 == 0:
            # a query's words: a recent bag's, random ones (some never seen, some beyond every word so far)
            q = np.unique(np.concatenate([bow.words, rng.integers(0, n_words + 50, size=int(rng.integers(0, 80)))]))
            assert same_gather(store.gather(q), ref.gather(q)), k
    assert len(compactions) >= 3
    assert store.end >= store.held == int(store.cap.sum()) >= int(store.size.sum())
    assert store.val.dtype == np.uint16  # integer counts stay compact
    # every word, and no word
    every = np.arange(n_words + 10)
    assert same_gather(store.gather(every), ref.gather(every))
    assert same_gather(store.gather(np.zeros(0, np.int64)), ref.gather(np.zeros(0, np.int64)))


def test_counts_that_uint16_cannot_hold_widen_the_store_exactly():
    rng = np.random.default_rng(22)
    store, ref = _Postings(), ListPostings()
    held = []
    for k in range(200):
        if k % 40 == 0:
            held.append(store.kf)  # another reference: the arena cannot grow in place, it is copied
        bow = random_bag(rng, k, 400)
        if k == 90:
            bow = BowVector(bow.words, bow.counts * 0.37)  # hand-made weights, not counts
        if k == 150 and len(bow):
            bow = BowVector(bow.words, bow.counts + 70000.0)
        append(store, k, bow)
        append(ref, k, bow)
    assert store.val.dtype == np.float64
    every = np.arange(410)
    assert same_gather(store.gather(every), ref.gather(every))


def vocab_of(n_words_at_least, rng):
    vocab = train_hkmeans([rng.normal(size=(60, 8)).astype(np.float32) for _ in range(40)], 12, 3)
    assert len(vocab) >= n_words_at_least
    return vocab


@pytest.mark.parametrize("idf_source", ["vocabulary", "database"])
def test_database_scores_identical_to_list_postings_and_equal_direct_formula(idf_source, monkeypatch):
    """Query then insert each keyframe (the loop detector's order, whose insert re-uses the query's
    postings; here also a query with other words first): scores bit-identical to the same database
    over reference posting lists, equal to the direct formula for every keyframe, and the same
    top-K as the direct scores rank them."""
    rng = np.random.default_rng(23)
    compactions = count_compactions(monkeypatch)
    monkeypatch.setattr(_Postings, "_LONG_RUN", 20)  # both ways of gathering in every query
    vocab = vocab_of(1000, rng)
    conf = VocabConfig(idf_source=idf_source)
    db, ref = BowDatabase(vocab, conf), BowDatabase(vocab, conf)
    ref._post = ListPostings()
    n_words = len(vocab)
    bags = []
    for k in range(900):
        bow = random_bag(rng, k, n_words)
        if len(db):
            # every third keyframe is queried with other words than it brings (part of them, and new ones)
            q = bow if k % 3 else BowVector.from_word_ids(np.concatenate(
                [bow.words[::2], bow.words[::3], rng.integers(0, n_words, size=5)]))
            got = db.query(q, top_k=5, exclude_recent_n=20)
            want = ref.query(q, top_k=5, exclude_recent_n=20)
            assert [(c.match_id, c.bow_score) for c in got] == [(c.match_id, c.bow_score) for c in want], k
        db.add_bow(k, k * 10**8, bow)
        ref.add_bow(k, k * 10**8, bow)
        bags.append(bow)
        if k % 150 == 149:
            probe = bags[int(rng.integers(0, len(bags)))] if k % 300 else bags[5]  # bags[5] is empty
            s = db.scores(probe)
            assert np.array_equal(s, ref.scores(probe))
            idf = db.idf()
            direct = np.array([bow_similarity(probe, db.bow(j), idf) for j in range(len(db))])
            assert np.allclose(s, direct, atol=1e-9)
            top = db.query(probe, top_k=8)
            rank = np.argsort(-direct, kind="stable")[:8]
            rank = rank[direct[rank] > 0]
            assert [c.bow_score for c in top] == pytest.approx(direct[rank].tolist(), abs=1e-9)
            gaps = np.diff(direct[rank])
            if np.all(np.abs(gaps) > 1e-9):  # no near-tie that rounding may order either way
                assert [c.match_id for c in top] == rank.tolist()
    assert len(compactions) >= 2
