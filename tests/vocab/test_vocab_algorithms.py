"""Vocabulary algorithms on controlled descriptor sets (fast; the real-data checks are in test_vocab_corridor)."""
from __future__ import annotations

import numpy as np
import pytest

from slam_lcd.errors import InputError, VocabularyError
from slam_lcd.vocab import (
    BowDatabase,
    BowVector,
    IncrementalWords,
    VocabConfig,
    Vocabulary,
    as_unit_vectors,
    bow_similarity,
    train_hkmeans,
    train_vocabulary,
)
from slam_lcd.vocab.tree import VocabTree


def unit(x):
    x = np.asarray(x, np.float32)
    return x / np.linalg.norm(x, axis=1, keepdims=True)


def track_sequence(rng, n_images=12, per_image=60, keep=40, dim=64, noise=0.05):
    """Images whose features are noisy views of landmarks; each image keeps `keep` landmarks of the previous."""
    landmarks, images, ids = [], [], []
    cur = list(range(per_image))
    landmarks = list(unit(rng.normal(size=(per_image, dim))))
    for i in range(n_images):
        if i:
            kept = list(rng.choice(cur, keep, replace=False))
            new = list(range(len(landmarks), len(landmarks) + per_image - keep))
            landmarks += list(unit(rng.normal(size=(len(new), dim))))
            cur = kept + new
        lm = np.array([landmarks[j] for j in cur])
        images.append(unit(lm + noise * rng.normal(size=lm.shape)))
        ids.append(np.array(cur))
    return images, ids, len(landmarks)


def test_incremental_words_follow_feature_tracks():
    rng = np.random.default_rng(1)
    images, ids, n_landmarks = track_sequence(rng)
    words = IncrementalWords(64, ratio=0.9, max_distance=0.8)
    assigned = [words.add_image(d) for d in images]
    # one word per landmark track: matched features joined their match's word, the others founded new ones
    assert words.n_words == n_landmarks
    lm_to_word = {}
    for lm, w in zip(np.concatenate(ids), np.concatenate(assigned), strict=True):
        assert lm_to_word.setdefault(lm, w) == w
    assert len(set(lm_to_word.values())) == n_landmarks
    # per-word counts = how often the landmark was seen; centres are unit running means
    seen = np.bincount(np.concatenate(ids))
    assert np.array_equal(words.counts[[lm_to_word[k] for k in range(n_landmarks)]], seen)
    assert np.allclose(np.linalg.norm(words.centres, axis=1), 1.0, atol=1e-5)
    first = [w for lm, w in lm_to_word.items() if seen[lm] > 3][0]
    members = np.concatenate([d[a == first] for d, a in zip(images, assigned, strict=True)])
    assert np.allclose(words.centres[first], unit(members.mean(0, keepdims=True))[0], atol=1e-5)


def test_ratio_test_keeps_ambiguous_features_apart():
    rng = np.random.default_rng(2)
    base = unit(rng.normal(size=(1, 32)))
    twins = unit(np.repeat(base, 2, 0) + 0.01 * rng.normal(size=(2, 32)))
    words = IncrementalWords(32, ratio=0.8, max_distance=0.8)
    words.add_image(twins)
    w = words.add_image(unit(base))
    assert w[0] == 2  # both old features are equally close: no match, a new word


def clustered(rng, n_clusters=240, per=10, dim=32, noise=0.03):
    """Words with a real hierarchy (8 groups of 6 groups of 5 words) and noisy points around each word."""
    top = unit(rng.normal(size=(8, dim)))
    mid = unit(np.repeat(top, 6, 0) + 0.35 * rng.normal(size=(48, dim)))
    centres = unit(np.repeat(mid, n_clusters // 48, 0) + 0.12 * rng.normal(size=(n_clusters, dim)))
    pts = unit(np.repeat(centres, per, 0) + noise * rng.normal(size=(n_clusters * per, dim)))
    return centres, pts


@pytest.mark.parametrize("tree", ["dp", "hkmeans"])
def test_greedy_descent_equals_exhaustive_on_separated_words(tree):
    rng = np.random.default_rng(3)
    centres, pts = clustered(rng)
    if tree == "dp":
        vocab = train_vocabulary([centres], VocabConfig())
        assert len(vocab) == len(centres) and vocab.depth >= 2
    else:
        vocab = train_hkmeans(centres, k=8, L=3)
    q = vocab.quantize(pts)
    ex = vocab.quantize_exhaustive(pts)
    assert (q == ex).mean() > 0.9
    # where greedy descent misses the nearest word, it still lands on a near one
    words = vocab.tree.words
    sim_greedy = (pts * words[q]).sum(1)
    sim_exh = (pts * words[ex]).sum(1)
    assert sim_greedy.mean() > 0.9 and sim_exh.mean() > 0.95


def test_dp_tree_infers_branching_and_has_single_root():
    rng = np.random.default_rng(4)
    centres, _ = clustered(rng, n_clusters=480, per=1)
    vocab = train_vocabulary([centres], VocabConfig(dp_block_size=128, dp_truncation=32, max_branching=24))
    br = vocab.tree.branching()
    assert len(br[0]) == 1  # single root
    assert all(b.max() <= 24 and b.min() >= 1 for b in br)
    # the branching was inferred: not one fixed k everywhere
    assert len(set(np.concatenate(br[1:]).tolist())) > 2
    assert sum(len(b) for b in br[1:]) + 1 < 480  # inner nodes fewer than words
    assert vocab.meta["tree"] == "dp"


def test_tree_rejects_broken_structure():
    c = unit(np.eye(4))
    with pytest.raises(ValueError):
        VocabTree([c[:2], c], [np.zeros(2), np.array([0, 0, 0, 0])])  # node 1 of level 1 has no child


@pytest.mark.parametrize("binary", [False, True])
def test_save_load_gives_identical_quantisation(tmp_path, binary):
    rng = np.random.default_rng(5)
    if binary:
        sets = [rng.integers(0, 256, size=(80, 32), dtype=np.uint8) for _ in range(6)]
    else:
        sets = [unit(rng.normal(size=(80, 64))) for _ in range(6)]
    test = np.concatenate(sets)
    for vocab in (train_vocabulary(sets, VocabConfig(dp_block_size=64, dp_truncation=16)), train_hkmeans(sets, 6, 3)):
        path = tmp_path / f"v_{vocab.meta['tree']}.npz"
        vocab.save(path)
        back = Vocabulary.load(path)
        assert len(back) == len(vocab) and back.depth == vocab.depth
        assert np.array_equal(back.quantize(test), vocab.quantize(test))
        assert np.array_equal(back.idf, vocab.idf) and back.meta == vocab.meta


def test_bad_vocabulary_files_give_one_line_errors(tmp_path):
    rng = np.random.default_rng(6)
    vocab = train_hkmeans([unit(rng.normal(size=(100, 16)))], 4, 2)
    good = tmp_path / "good.npz"
    vocab.save(good)
    data = good.read_bytes()
    (tmp_path / "trunc.npz").write_bytes(data[: len(data) // 2])
    (tmp_path / "text.npz").write_text("hello")
    np.savez(tmp_path / "other.npz", a=np.zeros(3))
    for name in ("trunc.npz", "text.npz", "other.npz", "missing.npz"):
        with pytest.raises(VocabularyError) as e:
            Vocabulary.load(tmp_path / name)
        assert "\n" not in str(e.value) and name in str(e.value)
    with pytest.raises(InputError):
        vocab.quantize(np.zeros((3, 17), np.float32))  # wrong dimension


def test_orb_bits_map_to_unit_vectors_preserving_hamming_order():
    rng = np.random.default_rng(7)
    a = rng.integers(0, 256, size=(50, 32), dtype=np.uint8)
    u = as_unit_vectors(a)
    assert u.shape == (50, 256) and np.allclose(np.linalg.norm(u, axis=1), 1)
    ham = np.unpackbits(a[:, None, :] ^ a[None, :, :], axis=2).sum(2)
    d2 = ((u[:, None, :] - u[None, :, :]) ** 2).sum(2)
    assert np.allclose(d2, ham / 64.0, atol=1e-5)


def random_vocab(rng, n_words=300, dim=16):
    return train_hkmeans([unit(rng.normal(size=(40, dim))) for _ in range(30)], 7, 3)


@pytest.mark.parametrize("idf_source", ["vocabulary", "database"])
def test_inverted_index_scores_equal_direct_l1_formula(idf_source):
    rng = np.random.default_rng(8)
    vocab = random_vocab(rng)
    db = BowDatabase(vocab, VocabConfig(idf_source=idf_source))
    descs = [unit(rng.normal(size=(int(rng.integers(5, 60)), 16))) for _ in range(25)]
    for i, d in enumerate(descs):
        db.add(100 + i, i * 10**9, d)
    q = db.transform(descs[3] + 0.0)
    s = db.scores(q)
    idf = db.idf()
    direct = [bow_similarity(q, db.bow(100 + i), idf) for i in range(len(descs))]
    assert np.allclose(s, direct, atol=1e-9)
    assert s[3] == pytest.approx(1.0)
    assert np.all((s >= 0) & (s <= 1 + 1e-9))


def test_query_window_top_k_and_alpha():
    rng = np.random.default_rng(9)
    vocab = random_vocab(rng)
    db = BowDatabase(vocab, VocabConfig())
    descs = [unit(rng.normal(size=(50, 16))) for _ in range(20)]
    for i, d in enumerate(descs):
        db.add(i, i * 10**9, d)
    q = unit(descs[5] + 0.02 * rng.normal(size=descs[5].shape))
    top = db.query(q, top_k=3)
    assert top[0].match_id == 5 and len(top) == 3
    assert top[0].bow_score >= top[1].bow_score >= top[2].bow_score
    # frames within 15 s of the newest (stamp 19 s) are excluded: 5 is out, the best remaining is older than 4 s
    assert all(c.match_id < 5 for c in db.query(q, top_k=3, exclude_recent_s=15.0))
    assert all(c.match_id < 12 for c in db.query(q, top_k=20, exclude_recent_n=8))
    assert [c.match_id for c in db.query(descs[19], top_k=20, query_id=19)].count(19) == 0
    # alpha: scores divided by the score against the previous keyframe
    raw = db.scores(db.transform(q))
    alpha = db.query(q, top_k=1, normalise_by_previous=True)
    assert alpha[0].bow_score == pytest.approx(raw[5] / raw[19])
    far = BowVector(np.array([0]), np.array([1.0]))
    assert db.query(far, top_k=3, normalise_by_previous=True, exclude_recent_n=0) == [] or raw[19] > 0


def test_online_mode_grows_words_and_finds_revisit():
    rng = np.random.default_rng(10)
    images, _, _ = track_sequence(rng, n_images=15, per_image=60, keep=30, dim=64, noise=0.05)
    db = BowDatabase(None, VocabConfig(idf_source="database", online_word_radius=0.7))
    sizes = []
    for i, d in enumerate(images):
        db.add(i, i * 10**9, d)
        sizes.append(db.n_words)
    assert sizes == sorted(sizes) and sizes[-1] > sizes[0]
    # scores stay consistent with the direct formula after words and keyframes were added
    idf = db.idf()
    for k in (0, 7, 14):
        assert np.allclose(db.scores(db.bow(k)), [bow_similarity(db.bow(k), db.bow(j), idf) for j in range(15)])
    # revisit: a noisy re-observation of image 2 retrieves image 2
    revisit = unit(images[2] + 0.05 * rng.normal(size=images[2].shape))
    bow = db.add(15, 15 * 10**9, revisit)
    assert db.n_words == sizes[-1]  # nothing new: every feature fell within an existing word
    top = db.query(bow, top_k=1, exclude_recent_n=1)
    assert top[0].match_id == 2


def test_a_buffer_refilled_in_place_is_converted_again():
    """The database converts a keyframe's descriptors once for its transform and its add (same
    array); a caller that refills the same buffer for the next keyframe must get the new content's
    words."""
    rng = np.random.default_rng(12)
    images, _, _ = track_sequence(rng, n_images=6, per_image=40, keep=20, dim=32, noise=0.05)
    db = BowDatabase(None, VocabConfig(idf_source="database", online_word_radius=0.7))
    for i, d in enumerate(images[:4]):
        db.add(i, i * 10**9, d)
    buf = np.ascontiguousarray(images[4], dtype=np.float32)
    first = db.transform(buf)
    buf[:] = images[5]
    again = db.transform(buf)
    fresh = db.transform(np.array(images[5], dtype=np.float32))
    assert np.array_equal(again.words, fresh.words) and np.array_equal(again.counts, fresh.counts)
    assert not np.array_equal(first.words, again.words)


def test_database_rejects_inconsistent_input():
    rng = np.random.default_rng(11)
    db = BowDatabase(random_vocab(rng), VocabConfig())
    db.add(0, 5, unit(rng.normal(size=(10, 16))))
    with pytest.raises(InputError):
        db.add(0, 6, unit(rng.normal(size=(10, 16))))
    with pytest.raises(InputError):
        db.add(1, 4, unit(rng.normal(size=(10, 16))))
    with pytest.raises(InputError):
        db.add(2, 7, rng.integers(0, 256, size=(10, 32), dtype=np.uint8))


def test_nearest_by_dot_in_blocks_equals_one_product(monkeypatch):
    """Vocabulary training's nearest-centre steps are formed in row blocks (bounded memory) with the
    same answers as one product."""
    import slam_lcd.vocab.descriptors as D

    rng = np.random.default_rng(0)
    x = rng.normal(size=(500, 16)).astype(np.float32)
    c = rng.normal(size=(70, 16)).astype(np.float32)
    whole = (x @ c.T).argmax(axis=1)
    monkeypatch.setattr(D, "_PRODUCT_BLOCK_FLOATS", 70 * 33)  # 33 rows per block
    assert np.array_equal(D.nearest_by_dot(x, c), whole)
    assert D.nearest_by_dot(x[:0], c).shape == (0,)
