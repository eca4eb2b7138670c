"""Nearest-word search of the online vocabulary at scale: index vs exhaustive search.

The inverted file only switches on above ``ann_min_words`` (20k by default, beyond the
corridor's few thousand words); these tests force a low threshold so that the index decides
while the real sequences grow their words, and compare every decision with exhaustive search
on the same words.
"""
from __future__ import annotations

import functools
import itertools
from pathlib import Path

import numpy as np
import pytest

from slam_lcd.vocab import BowDatabase, VocabConfig, as_unit_vectors
from slam_lcd.vocab.word_index import WordIndex, exact_nearest
from slam_lcd.vocab.words import IncrementalWords, mutual_nn_unit

FORCED = dict(idf_source="database", ann_min_words=1000)


def unit(x):
    x = np.asarray(x, np.float32)
    return x / np.linalg.norm(x, axis=1, keepdims=True)


@functools.cache
def frame_descriptors(folder: str, weights: str) -> tuple:
    """SuperPoint descriptors (default settings, at most 1000 per frame) of an image folder, via the feature cache."""
    from slam_lcd.features import FeatureCache, FeaturesConfig, load_extractor
    from slam_lcd.io.image_folder import folder_frames

    ex = load_extractor(FeaturesConfig(), weights=weights, device="cpu")
    cache = FeatureCache(ex)
    _, _, frames = folder_frames(folder)
    return tuple(cache.extract(Path(folder), "images", fr.stamp, fr.image).descriptors for fr in frames)


@pytest.fixture(scope="module")
def real_sequences(shared_data, superpoint_weights):
    """(name, descriptor sets) of the real sequences: 20 KITTI frames (~870 features each, long
    tracks), 20 TUM desk frames, the 84 corridor frames (~100 features, a revisit)."""
    from support.lcd_corridor_cache import corridor_features

    out = []
    for name in ("kitti", "tum_fr2_desk"):
        folder = shared_data / "frames" / name
        if not folder.is_dir():
            pytest.skip(f"{folder} not found")
        out.append((name, frame_descriptors(str(folder), str(superpoint_weights))))
    root = shared_data / "rtabmap_corridor"
    if not (root / "samples_GT.bmp").is_file():
        pytest.skip("corridor frames not found")
    feats = corridor_features(str(root), "superpoint", str(superpoint_weights))
    out.append(("corridor", tuple(f.descriptors for f in feats)))
    return out


def assignment(ids, sims, radius):
    """The online rule: the nearest word if within the radius, else -1 (a new word)."""
    return np.where(np.sqrt(np.maximum(2.0 - 2.0 * sims, 0.0)) < radius, ids, -1)


def grow_and_compare(sets, conf):
    """Grow an online database over ``sets``; before each image, compare the index's decision
    with exhaustive search over the same words. Returns (assignment agreement, nearest-word
    recall, descriptors compared, the database)."""
    db = BowDatabase(None, VocabConfig(**conf))
    same = same_nn = total = 0
    for i, d in enumerate(sets):
        u = as_unit_vectors(d)
        if db.words is not None and db.words.index.active:
            ids, sims = db.words.nearest(u)
            ex_ids, ex_sims = exact_nearest(db.words.centres, u)
            r = db.conf.online_word_radius
            same += int((assignment(ids, sims, r) == assignment(ex_ids, ex_sims, r)).sum())
            same_nn += int((ids == ex_ids).sum())
            total += len(u)
        if len(db):
            db.query(d, top_k=5, exclude_recent_n=5)
        db.add(i, i * 10**9, d)
    return same / max(total, 1), same_nn / max(total, 1), total, db


def test_index_agrees_with_exhaustive_search_on_real_superpoint(real_sequences):
    # one stream through all three sequences: the graph is built on KITTI words, then grows on TUM
    # and corridor words; tracked features are decided by their match's candidates part of the time
    sets = [d for _, seq in real_sequences for d in seq]
    agree, recall, total, db = grow_and_compare(sets, FORCED)
    stats = db.words.index.stats()
    print(f"\nreal SuperPoint, {len(sets)} images, {db.n_words} words, {total} descriptors decided by the index: "
          f"same assignment as exhaustive {agree:.4f}, same nearest word {recall:.4f}, index {stats}")
    assert stats["active"] and stats["hinted"] > 0.2 * total and total > 30000
    assert agree >= 0.98 and recall >= 0.95


def test_a_query_holds_the_words_its_keyframe_is_inserted_with(real_sequences):
    """With the index active a feature tracked from the previous image queries with its track's word,
    the word its insertion gives it (IncrementalWords.query_words), instead of a nearest word re-ranked
    among its track's candidates: on the 20 KITTI frames 96 % of the query's words are the inserted
    ones (the rest: matches too far or tracks too old to hand over), against 89 % for the nearest word."""
    _, sets = real_sequences[0]  # kitti: ~870 features per frame, long tracks
    db = BowDatabase(None, VocabConfig(**FORCED))
    same_query = same_nearest = total = 0
    for i, d in enumerate(sets):
        u = as_unit_vectors(d)
        active = db.words is not None and db.words.index.active
        if active:
            n_before = db.words.n_words
            ids, sims = db.words.nearest(u)
            nearest = assignment(ids, sims, db.conf.online_word_radius)
            query = db.words.query_words(u, db._pool())
            assert np.array_equal(db.transform(d).words, np.unique(query[query >= 0]))
        db.add(i, i * 10**9, d)
        if active:
            inserted = np.where(db.words._prev_words < n_before, db.words._prev_words, -1)
            same_query += int((query == inserted).sum())
            same_nearest += int((nearest == inserted).sum())
            total += len(u)
    assert total > 5000
    assert same_query / total >= 0.95 and same_query / total >= same_nearest / total + 0.04


def test_every_feature_searches_the_index_when_hints_are_off(real_sequences):
    # ann_hint_images=0: tracked features search the index too (the pure inverted-file recall)
    kitti = dict(real_sequences)["kitti"]
    agree, recall, total, _ = grow_and_compare(list(kitti), dict(FORCED, ann_hint_images=0))
    assert total > 5000 and agree >= 0.98 and recall >= 0.95


def test_same_input_gives_the_same_words(real_sequences):
    sets = list(dict(real_sequences)["kitti"])
    runs = []
    for _ in range(2):
        db = BowDatabase(None, VocabConfig(**FORCED))
        bows = [db.add(i, i * 10**9, d) for i, d in enumerate(sets)]
        runs.append((db, bows))
    (a, bows_a), (b, bows_b) = runs
    assert a.words.index.active and a.n_words == b.n_words
    assert all(np.array_equal(x.words, y.words) and np.array_equal(x.counts, y.counts)
               for x, y in zip(bows_a, bows_b, strict=True))
    assert np.array_equal(a.words.centres, b.words.centres)
    q = as_unit_vectors(sets[3])
    assert np.array_equal(a.words.nearest(q)[0], b.words.nearest(q)[0])


def test_unit_vector_matching_equals_the_shared_matcher(real_sequences):
    from slam_lcd.features.matching import mutual_nn_match

    kitti = [as_unit_vectors(d) for d in dict(real_sequences)["kitti"][:6]]
    for b, a in itertools.pairwise(kitti):
        m1 = mutual_nn_match(a, b, ratio=0.9, max_distance=0.8)
        m2 = mutual_nn_unit(a, b, 0.9, 0.8)
        assert len(m1) > 300 and np.array_equal(m1, m2)


# ----------------------------------------------------------------------------- synthetic, fast
def clustered_words(rng, n, dim=32):
    return unit(rng.normal(size=(n, dim)))


@pytest.mark.parametrize("storage", ["sq8", "flat"])
def test_moved_words_are_found_at_their_new_place(storage):
    rng = np.random.default_rng(0)
    centres = clustered_words(rng, 3000)
    ix = WordIndex(32, min_words=1000, pca_dims=16, fresh_images=0, storage=storage)
    ix.update(centres, np.arange(3000))
    assert ix.active and ix.n_indexed == ix.graph.ntotal == 3000
    # members join 300 words and move their centres by ~0.3 (a revisit's worth): the graph holds the
    # new projected positions, and queries near the new centres find them
    moved = np.arange(0, 3000, 10)
    centres[moved] = unit(centres[moved] + 0.3 / np.sqrt(32) * rng.normal(size=(len(moved), 32)))
    ix.update(centres, moved)
    if storage == "flat":
        assert np.allclose(ix._storage()[moved], centres[moved] @ ix.proj, atol=1e-6)
    else:  # the 8-bit codes of the new positions (decoded: within one quantisation step)
        import faiss

        sq = faiss.downcast_index(ix.graph.storage)
        codes = ix._storage()[moved]
        assert np.array_equal(codes, sq.sa_encode(np.ascontiguousarray(centres[moved] @ ix.proj)))
        vdiff = faiss.vector_to_array(sq.sq.trained)[16:]  # (per-dimension minimum, range)
        err = np.abs(sq.sa_decode(codes) - np.clip(centres[moved] @ ix.proj, *faiss.vector_to_array(sq.sq.trained)
                                                   .reshape(2, 16).cumsum(axis=0)))
        assert np.all(err <= vdiff / 255 + 1e-6)
    q = unit(centres[moved] + 0.02 * rng.normal(size=(len(moved), 32)))
    ids, sims, _ = ix.nearest(centres, q)
    ex_ids, ex_sims = exact_nearest(centres, q)
    assert (ids == ex_ids).mean() >= 0.97
    assert np.allclose(sims[ids == ex_ids], ex_sims[ids == ex_ids], atol=1e-5)  # exact similarity, current centre


def test_a_pool_that_decides_few_rows_pauses_for_three_images():
    # a pool of words unrelated to the images (a new route: the previous query's best keyframe is no
    # revisit) decides none of the rows it scores: the next three images search without it; a pool
    # holding the images' landmarks (a revisit) decides them and stays in use
    rng = np.random.default_rng(7)
    words = IncrementalWords(32, radius=0.7, index=WordIndex(32, min_words=200, pca_dims=16, fresh_images=0))
    seen = []
    for _ in range(3):
        seen.append(unit(rng.normal(size=(300, 32))))
        words.add_image(seen[-1])
    assert words.index.active
    calls = []
    scored = words.index.pool_candidates
    words.index.pool_candidates = lambda u, pool: calls.append(len(u)) or scored(u, pool)

    def used(images, pool):
        out = []
        for d in images:
            n = len(calls)
            words.add_image(d, pool)
            out.append(len(calls) > n)
        return out

    assert used([unit(rng.normal(size=(300, 32))) for _ in range(6)], np.arange(100)) == [True, False, False, False,
                                                                                         True, False]
    # revisit: noisy views of the first images' landmarks (different ones each image: nothing tracked)
    views = [unit(seen[j % 3] + 0.05 * rng.normal(size=(300, 32))) for j in range(1, 6)]
    assert used(views, np.arange(900)) == [False, False, True, True, True]  # the pause runs out, then in use


def test_fresh_words_are_searched_exhaustively_then_indexed():
    rng = np.random.default_rng(1)
    centres = clustered_words(rng, 2000)
    ix = WordIndex(32, min_words=1000, pca_dims=16, fresh_images=2)
    for k in range(4):  # four images of 500 new words each
        ix.update(centres[: 500 * (k + 1)], np.arange(500 * k, 500 * (k + 1)))
    assert ix.active and ix.n_indexed == 1000  # the last two images' words are still fresh
    q = unit(centres[1500:1600] + 0.01 * rng.normal(size=(100, 32)))
    ids, _, _ = ix.nearest(centres, q)
    assert np.array_equal(ids, np.arange(1500, 1600))
    ix.update(centres, np.zeros(0, np.int64))
    assert ix.n_indexed == 1500


def _grow_words(background: bool):
    """An online database over a sliding window of landmarks (new words every image, old ones moving)."""
    rng = np.random.default_rng(5)
    landmarks = clustered_words(rng, 2600)
    db = BowDatabase(None, VocabConfig(idf_source="database", ann_min_words=500, ann_pca_dims=16,
                                       ann_background_insert=background))
    words, cands = [], []
    for k in range(40):
        u = unit(landmarks[50 * k: 50 * k + 400] + 0.05 * rng.normal(size=(400, 32)))
        db.query(u, top_k=3, exclude_recent_n=5) if len(db) else None
        db.add(k, k * 10**9, u)
        words.append(db.words._prev_words.copy())
        cands.append(None if db.words._prev_cands is None else db.words._prev_cands.copy())
    return db, words, cands


def test_words_inserted_beside_the_next_image_give_the_same_graph_and_words():
    """vocab.ann_background_insert: the graph insertion runs on a worker thread, and every use of the
    graph waits for it: the same words, candidates and graph as inserting in place."""
    (db_bg, w_bg, c_bg), (db_fg, w_fg, c_fg) = _grow_words(True), _grow_words(False)
    ix_bg, ix_fg = db_bg.words.index, db_fg.words.index
    assert ix_bg.active and ix_bg.background_insert and not ix_fg.background_insert
    assert all(np.array_equal(a, b) for a, b in zip(w_bg, w_fg, strict=True))
    assert all((a is None and b is None) or np.array_equal(a, b) for a, b in zip(c_bg, c_fg, strict=True))
    assert ix_bg.n_indexed == ix_fg.n_indexed == ix_bg.graph.ntotal == ix_fg.graph.ntotal
    assert ix_bg.insert_cpu_s > 0 and ix_fg.insert_cpu_s > 0
    import faiss

    links = [faiss.vector_to_array(ix.graph.hnsw.neighbors) for ix in (ix_bg, ix_fg)]
    assert np.array_equal(*links)  # identical links


def test_an_insertion_that_fails_on_the_worker_raises_at_the_next_use():
    rng = np.random.default_rng(6)
    centres = clustered_words(rng, 1200)
    ix = WordIndex(32, min_words=1000, pca_dims=16, fresh_images=0)
    ix.update(centres[:1100], np.arange(1100))
    assert ix.active

    class Broken:
        def add(self, rows):
            raise RuntimeError("insertion failed")

    ix._graph = Broken()
    ix.update(centres, np.zeros(0, np.int64))  # hands words 1100-1199 to the worker
    with pytest.raises(RuntimeError, match="insertion failed"):
        ix.wait()


def test_a_forked_child_inserts_on_its_own_worker_thread():
    """The insertion thread is the process's own: a child forked after it started (a fork without
    exec, as multiprocessing's 'fork') must not queue its insertions on a thread it does not have."""
    import os

    if not hasattr(os, "fork"):
        pytest.skip("no fork on this platform")
    rng = np.random.default_rng(7)
    centres = clustered_words(rng, 1300)
    ix = WordIndex(32, min_words=1000, pca_dims=16, fresh_images=0)
    ix.update(centres[:1100], np.arange(1100))
    ix.update(centres[:1200], np.zeros(0, np.int64))  # the parent's worker thread runs now
    ix.wait()
    pid = os.fork()
    if pid == 0:  # child: insert and search, then leave without the parent's cleanup
        import signal

        signal.alarm(30)  # a child waiting on a thread it does not have dies instead of hanging
        ok = False
        try:
            ix.update(centres, np.zeros(0, np.int64))
            ok = (ix.graph.ntotal == 1300
                  and ix.nearest(centres, centres[1250:1260])[0].tolist() == list(range(1250, 1260)))
        finally:
            os._exit(0 if ok else 1)
    _, status = os.waitpid(pid, 0)
    assert os.WIFEXITED(status) and os.WEXITSTATUS(status) == 0


def test_index_is_refitted_as_the_vocabulary_grows():
    rng = np.random.default_rng(2)
    centres = clustered_words(rng, 9000)
    ix = WordIndex(32, min_words=1000, pca_dims=32, fresh_images=0, rebuild_growth=2.0)
    sizes = [1000, 1500, 2100, 4500, 9000]
    for n in sizes:
        ix.update(centres[:n], np.arange(n))
    assert ix.n_builds == 4  # at 1000, 2100 (>= 2x1000), 4500 (>= 2x2100), 9000 (>= 2x4500)
    assert ix.n_indexed == ix.graph.ntotal == 9000
    grows = WordIndex(32, min_words=1000, pca_dims=32, fresh_images=0)  # default: the graph just grows
    for n in sizes:
        grows.update(centres[:n], np.arange(n))
    assert grows.n_builds == 1 and grows.graph.ntotal == 9000
    q = unit(centres[::9] + 0.02 * rng.normal(size=(1000, 32)))
    for index in (ix, grows):
        assert (index.nearest(centres, q)[0] == exact_nearest(centres, q)[0]).mean() > 0.97


def test_ties_go_to_the_lowest_word_id_like_argmax():
    # ORB-like vectors (+-1/16): many exact ties in similarity
    rng = np.random.default_rng(3)
    bits = rng.integers(0, 2, size=(1500, 64)).astype(np.float32)
    centres = ((2 * bits - 1) / 8.0).astype(np.float32)
    centres = np.concatenate([centres, centres[:200]])  # duplicates: equal similarity, higher id
    ix = WordIndex(64, min_words=1000, pca_dims=32, fresh_images=0)
    ix.update(centres, np.arange(len(centres)))
    ids, _, _ = ix.nearest(centres, centres[:200])
    assert np.array_equal(ids, np.arange(200))


def test_online_words_with_index_keep_scores_exact():
    from slam_lcd.vocab import bow_similarity

    rng = np.random.default_rng(4)
    landmarks = unit(rng.normal(size=(3000, 64)))
    db = BowDatabase(None, VocabConfig(idf_source="database", ann_min_words=500))
    for i in range(30):
        lm = landmarks[(i * 90 + np.arange(150)) % 3000]
        db.add(i, i * 10**9, unit(lm + 0.03 * rng.normal(size=lm.shape)))
    assert db.words.index.active
    idf = db.idf()
    for k in (0, 13, 29):
        direct = [bow_similarity(db.bow(k), db.bow(j), idf) for j in range(30)]
        assert np.allclose(db.scores(db.bow(k)), direct, atol=1e-9)
    # revisit of image 4: found, and its words are old ones
    lm = landmarks[(4 * 90 + np.arange(150)) % 3000]
    n_before = db.n_words
    bow = db.add(30, 30 * 10**9, unit(lm + 0.03 * rng.normal(size=lm.shape)))
    assert db.n_words == n_before
    assert db.query(bow, top_k=1, exclude_recent_n=1)[0].match_id in (3, 4, 5)


def test_training_words_need_no_index():
    rng = np.random.default_rng(5)
    w = IncrementalWords(128)
    for _ in range(3):
        w.add_image(unit(rng.normal(size=(40, 128))))
    assert w.index is None and w.n_words == 120


def _mutual_nn_by_column_argmax(d1, d2, ratio, max_distance):
    """The rule written the plain way (a column argmax): what the faster column-max form must equal."""
    s = d1 @ d2.T
    i1 = np.arange(len(d1))
    nn12, nn21 = s.argmax(axis=1), s.argmax(axis=0)
    best = s[i1, nn12]
    keep = nn21[nn12] == i1
    d_best = np.sqrt(np.maximum(2.0 - 2.0 * best, 0.0))
    if ratio is not None and s.shape[1] > 1:
        s[i1, nn12] = -np.inf
        keep &= d_best < ratio * np.maximum(np.sqrt(np.maximum(2.0 - 2.0 * s.max(axis=1), 0.0)), 1e-12)
    if max_distance is not None:
        keep &= d_best < max_distance
    return np.stack([i1[keep], nn12[keep]], axis=1)


def test_mutual_matching_equals_the_column_argmax_rule_with_ties_and_duplicates():
    rng = np.random.default_rng(3)
    for t in range(150):
        n1, n2 = rng.integers(1, 200, 2)
        q = int(rng.integers(2, 6))  # coarse coordinates: many exactly equal similarities
        d1 = unit(rng.integers(-q, q + 1, (n1, 6)) + 0.5)
        d2 = unit(rng.integers(-q, q + 1, (n2, 6)) + 0.5)
        if t % 3 == 0:
            d2[: n2 // 2] = d1[rng.integers(0, n1, n2 // 2)]  # the same descriptor in both images
        if t % 5 == 0:
            d1 = np.repeat(d1[: max(1, n1 // 3)], 3, axis=0)  # repeated descriptors within an image
        for ratio, max_distance in ((None, None), (0.9, 0.8), (0.99, None)):
            got = mutual_nn_unit(d1.copy(), d2.copy(), ratio, max_distance)
            assert np.array_equal(got, _mutual_nn_by_column_argmax(d1.copy(), d2.copy(), ratio, max_distance)), t


def test_word_arrays_grow_in_place_and_keep_their_words():
    rng = np.random.default_rng(4)
    w = IncrementalWords(32, radius=0.3)
    for _ in range(12):
        w.add_image(unit(rng.normal(size=(400, 32))))
    before = w.centres.copy(), w.counts.copy(), w.image_counts.copy()
    arrays = [id(getattr(w, n)) for n in ("_lengths", "_centres", "_counts", "_images")]
    cap = len(w._counts)
    w._grow(cap + 1)
    assert len(w._counts) == cap + cap // 4  # a quarter more, not double
    assert [id(getattr(w, n)) for n in ("_lengths", "_centres", "_counts", "_images")] == arrays  # resized, not copied
    held = w.centres  # a view someone holds: the arrays are copied instead, the view stays valid
    w._grow(2 * len(w._counts))
    assert np.array_equal(held, before[0])
    assert all(np.array_equal(a, b) for a, b in zip((w.centres, w.counts, w.image_counts), before, strict=True))
    assert not w._centres[w.n_words:].any()
    w.add_image(unit(rng.normal(size=(50, 32))))
    assert w.n_words == len(before[0]) + 50


def _grow_with_a_missed_image(gap: bool):
    """Images of a sliding window over landmarks; image 9 misses 60 landmarks that images 8 and 10 see.

    Returns (graph searches of image 10, image 10's words of the missed landmarks, image 8's words of
    them, image 10's nearest words by exhaustive search).
    """
    rng = np.random.default_rng(5)
    landmarks = clustered_words(rng, 2400)
    missed = np.arange(420, 480)
    words = IncrementalWords(32, radius=0.7, index=WordIndex(32, min_words=500, pca_dims=16, hint_gap=gap))
    out = {}
    for k in range(11):
        ids = np.arange(40 * k, 40 * k + 400)
        if k == 9:
            ids = ids[~np.isin(ids, missed)]
        u = unit(landmarks[ids] + 0.02 * rng.normal(size=(len(ids), 32)))
        before = words.index.n_searched
        if k == 10:
            out["exhaustive"] = exact_nearest(words.centres, u)[0][np.isin(ids, missed)]
        w = words.add_image(u)
        out[k] = (words.index.n_searched - before, w[np.isin(ids, missed)])
    assert words.index.active
    return out[10][0], out[10][1], out[8][1], out["exhaustive"]


def _fewer_searches_same_words(grow, fewer: int) -> None:
    """``grow(on)`` -> (graph searches, words, words at the first sight, exhaustive nearest words) of the
    landmarks under test, with the mechanism on and off: ``fewer`` searches fewer when on, and the
    same words either way, which are the first sight's and the nearest ones."""
    searched_on, words_on, words_before, exhaustive = grow(True)
    searched_off, words_off, _, _ = grow(False)
    assert searched_off - searched_on == fewer
    assert np.array_equal(words_on, words_off)
    assert np.array_equal(words_on, words_before) and np.array_equal(words_on, exhaustive)


def test_a_feature_missed_for_one_image_is_decided_by_its_track_not_a_graph_search():
    # the 60 landmarks image 9 missed match image 8's features: hints instead of 60 graph searches
    _fewer_searches_same_words(lambda on: _grow_with_a_missed_image(gap=on), 60)



def _revisit(query: bool):
    """A database over a sliding window of landmarks (images 0-29), then a revisit of images 5-6's
    place: image 30 sees image 5's landmarks, image 31 image 6's (40 of them not in image 30).

    ``query``: the loop detector's order (query each image, then add it); without queries there is
    no previous best keyframe and so no pool. Returns (graph searches of image 31, image 31's words
    of its 40 entering landmarks, image 6's words of them, image 31's nearest words of them by
    exhaustive search).
    """
    rng = np.random.default_rng(11)
    landmarks = clustered_words(rng, 1700)
    db = BowDatabase(None, VocabConfig(idf_source="database", ann_min_words=500, ann_pca_dims=16))
    entering = np.arange(40 * 6 + 360, 40 * 6 + 400)
    out = {}
    for k in range(32):
        ids = np.arange(40 * k, 40 * k + 400) if k < 30 else np.arange(40 * (k - 25), 40 * (k - 25) + 400)
        u = unit(landmarks[ids] + 0.02 * rng.normal(size=(len(ids), 32)))
        before = db.words.index.n_searched if db.words is not None else 0
        if k == 31:
            out["exhaustive"] = exact_nearest(db.words.centres, u)[0][np.isin(ids, entering)]
        if query and len(db):
            db.query(u, top_k=3, exclude_recent_n=5)
        db.add(k, k * 10**9, u)
        out[k] = (db.words.index.n_searched - before, db.words._prev_words[np.isin(ids, entering)])
    assert db.words.index.active
    return out[31][0], out[31][1], out[6][1], out["exhaustive"]


def test_landmarks_entering_the_view_on_a_revisit_take_the_retrieved_places_words():
    # image 30's query ranks image 5 first: image 31's 40 entering landmarks are decided among the
    # words of images 4-7 instead of 40 graph searches; the same words, those of the first visit
    _fewer_searches_same_words(lambda on: _revisit(query=on), 40)


def test_binary_descriptors_search_the_graph_without_a_pool():
    # ORB words are less distinct: an aliased place's words must not decide the next query (the
    # corridor's ORB run took a false loop with them); float descriptors get the pool
    rng = np.random.default_rng(2)
    pools = {}
    for kind in ("binary", "float"):
        db = BowDatabase(None, VocabConfig(idf_source="database"))
        base = rng.integers(0, 256, (200, 32), dtype=np.uint8) if kind == "binary" else rng.normal(size=(200, 32))
        for k in range(3):  # the same place three times: the queries find the earlier images
            d = base.copy() if kind == "binary" else unit(base + 0.05 * rng.normal(size=base.shape))
            if len(db):
                db.query(d, top_k=1)
            db.add(k, k * 10**9, d)
        pools[kind] = db._pool()
    assert pools["binary"] is None and pools["float"] is not None and len(pools["float"]) > 0
