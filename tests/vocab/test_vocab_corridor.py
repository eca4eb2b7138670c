"""Acceptance of the vocabulary on the real RTAB-Map corridor frames (84 images, GT loop matrix).

Protocol: keyframes are the 84 frames in order; before frame i is added, frames with a GT
loop (44 of them, all after frame 40) query the database of frames 1..i-1, top-5, the 20
most recent frames excluded. A query counts as a top-K hit when one of its first K
candidates is a GT loop partner. Vocabularies are trained on the corridor's first 40 frames
(the paper's incremental words + DP tree, and the DBoW2-style hierarchical k-means baseline
with k^4 leaves of about the same size). Run with ``pytest -s`` to see the table.
"""
from __future__ import annotations

import time

import cv2
import numpy as np
import pytest

from slam_lcd.features import FeaturesConfig, load_extractor
from slam_lcd.vocab import BowDatabase, VocabConfig, Vocabulary, train_hkmeans, train_vocabulary

N_TRAIN = 40
EXCLUDE_RECENT = 20


@pytest.fixture(scope="module")
def corridor(shared_data):
    root = shared_data / "rtabmap_corridor"
    if not (root / "samples_GT.bmp").is_file():
        pytest.skip("corridor frames not found")
    images = [cv2.imread(str(root / f"{i}.jpg"), cv2.IMREAD_GRAYSCALE) for i in range(1, 85)]
    gt = cv2.imread(str(root / "samples_GT.bmp"), cv2.IMREAD_GRAYSCALE) == 255
    assert all(im is not None for im in images) and gt.shape == (84, 84) and gt.any(1).sum() == 44
    return images, gt


@pytest.fixture(scope="module")
def sp_desc(corridor, shared_data, superpoint_weights):
    # SuperPoint (default FeaturesConfig, shared checkpoint) on the 84 frames, extracted once per
    # test process and shared with the test_lcd_* files (tests/support/lcd_corridor_cache.py)
    from support.lcd_corridor_cache import corridor_features

    feats = corridor_features(str(shared_data / "rtabmap_corridor"), "superpoint", str(superpoint_weights))
    assert len(feats) == 84 and feats[0].descriptors.dtype == np.float32
    return [f.descriptors for f in feats]


@pytest.fixture(scope="module")
def orb_desc(corridor):
    ex = load_extractor(FeaturesConfig(kind="orb", orb_n_features=500, feature_cache=False))
    return [ex.extract(im).descriptors for im in corridor[0]]


def retrieval(vocab, descs, gt, conf=None):
    """(top-1 hits, top-5 hits) over the GT query frames; vocab None = online mode."""
    db = BowDatabase(vocab, conf or VocabConfig())
    top1 = top5 = 0
    for i, d in enumerate(descs):
        if gt[i].any():
            cands = db.query(d, top_k=5, exclude_recent_n=EXCLUDE_RECENT, query_id=i)
            hits = [bool(gt[i, c.match_id]) for c in cands]
            top1 += bool(hits) and hits[0]
            top5 += any(hits)
        db.add(i, i * 10**9, d)
    return top1, top5


def agreement(vocab, descs, limit: int = 5000) -> float:
    """Share of descriptors of the frames after training (at most ``limit``, evenly spread) for
    which greedy descent returns the exhaustive nearest word."""
    x = np.concatenate(descs[N_TRAIN:])
    x = x[np.linspace(0, len(x) - 1, min(limit, len(x))).astype(int)]
    return float((vocab.quantize(x) == vocab.quantize_exhaustive(x)).mean())


def compare(descs, gt, name, online=True):
    t0 = time.perf_counter()
    dp = train_vocabulary(descs[:N_TRAIN], VocabConfig(), features=name)
    t_dp = time.perf_counter() - t0
    k = max(2, int(round(len(dp) ** 0.25)))
    t0 = time.perf_counter()
    hk = train_hkmeans(descs[:N_TRAIN], k, 4, features=name)
    t_hk = time.perf_counter() - t0
    rows = {}
    for label, vocab, t in (("incremental+DP", dp, t_dp), (f"hkmeans k={k} L=4", hk, t_hk)):
        rows[label] = retrieval(vocab, descs, gt) + (len(vocab), vocab.depth, agreement(vocab, descs), t)
    if online:
        rows["online (no vocab)"] = retrieval(None, descs, gt) + (None, None, None, None)
    print(f"\n[vocab] corridor, {name} features, trained on frames 1-{N_TRAIN}, 44 queries, exclude 20 recent")
    print(f"[vocab] {'vocabulary':22s} {'top-1':>6s} {'top-5':>6s} {'words':>6s} {'depth':>5s} "
          f"{'greedy=exh':>10s} {'train s':>7s}")
    for label, (t1, t5, n, depth, agr, t) in rows.items():
        extra = f"{n:6d} {depth:5d} {agr:10.3f} {t:7.1f}" if n is not None else f"{'':6s} {'':5s} {'':10s} {'':7s}"
        print(f"[vocab] {label:22s} {t1:3d}/44 {t5:3d}/44 {extra}")
    return dp, hk, rows


@pytest.fixture(scope="module")
def sp_result(sp_desc, corridor):
    return compare(sp_desc, corridor[1], "superpoint")


def test_superpoint_dp_vocabulary_retrieves_at_least_as_well_as_hkmeans(sp_result):
    dp, hk, rows = sp_result
    (dp_t1, dp_t5, *_), (hk_t1, hk_t5, *_) = list(rows.values())[:2]
    assert 0.5 <= len(dp) / len(hk) <= 2.0  # baseline of similar size
    assert dp_t5 >= hk_t5
    assert dp_t5 >= 35  # a working vocabulary finds most of the corridor's revisits
    assert rows["online (no vocab)"][1] >= 30


def test_orb_vocabularies_reported(orb_desc, corridor):
    dp, hk, rows = compare(orb_desc, corridor[1], "orb", online=False)  # online ORB: brute-force words, slow
    assert dp.desc_kind == "binary" and hk.desc_kind == "binary"
    (dp_t1, dp_t5, *_), (hk_t1, hk_t5, *_) = list(rows.values())[:2]
    assert min(dp_t5, hk_t5) >= 22  # ORB works too (at least half of the queries)


def test_real_vocabulary_save_load_identical_quantisation(sp_result, sp_desc, tmp_path):
    dp, hk, _ = sp_result
    x = np.concatenate(sp_desc[N_TRAIN:])
    for vocab in (dp, hk):
        path = tmp_path / "v.npz"
        vocab.save(path)
        back = Vocabulary.load(path)
        assert np.array_equal(back.quantize(x), vocab.quantize(x))
        assert back.stats() == vocab.stats()
