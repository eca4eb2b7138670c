"""``mutual_nn_match_bf`` without OpenCV's matcher objects, against the loop over them it replaced."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from slam_lcd.features.matching import mutual_nn_match, mutual_nn_match_bf


def _bf_reference(d1, d2, ratio=None, max_distance=None, *, ratio_floor=1e-12, max_inclusive=False):
    """The reference: cv2.BFMatcher knnMatch + match and a Python loop over the DMatch objects."""
    if len(d1) == 0 or len(d2) == 0:
        return np.zeros((0, 2), np.int64)
    binary = d1.dtype == np.uint8
    a = np.ascontiguousarray(d1 if binary else d1.astype(np.float32))
    b = np.ascontiguousarray(d2 if binary else d2.astype(np.float32))
    bf = cv2.BFMatcher(cv2.NORM_HAMMING if binary else cv2.NORM_L2, crossCheck=False)
    k = 2 if (ratio is not None and len(b) > 1) else 1
    fwd = bf.knnMatch(a, b, k=k)
    nn21 = np.full(len(b), -1, np.int64)
    for m in bf.match(b, a):
        nn21[m.queryIdx] = m.trainIdx
    out = []
    for row in fwd:
        best = row[0]
        if nn21[best.trainIdx] != best.queryIdx:
            continue
        if k == 2 and len(row) > 1 and not best.distance < ratio * max(row[1].distance, ratio_floor):
            continue
        if max_distance is not None and not (best.distance <= max_distance if max_inclusive
                                             else best.distance < max_distance):
            continue
        out.append((best.queryIdx, best.trainIdx))
    return np.asarray(out, dtype=np.int64).reshape(-1, 2)


RULES = [dict(ratio=0.9, max_distance=64.0), dict(ratio=0.85, max_distance=64.0, ratio_floor=0.0, max_inclusive=True),
         dict(ratio=None, max_distance=None)]


def test_orb_identical_including_ties():
    """Hamming distances are integers, so ties are frequent: the first index must win as in OpenCV."""
    rng = np.random.default_rng(0)
    for trial in range(20):
        n1, n2 = rng.integers(1, 400, 2)
        d1 = rng.integers(0, 256, (n1, 32), dtype=np.uint8)
        d2 = np.vstack([d1[rng.choice(n1, min(n1, n2 // 2))], rng.integers(0, 256, (n2 - min(n1, n2 // 2), 32),
                                                                          dtype=np.uint8)])
        d2[rng.random(d2.shape) < 0.05] ^= 1  # near copies
        if trial % 2:
            d2 = np.vstack([d2, d2[:10]])  # exact duplicates: tied nearest neighbours
        for rule in RULES:
            assert np.array_equal(mutual_nn_match_bf(d1, d2, **rule), _bf_reference(d1, d2, **rule))


@pytest.fixture(scope="module")
def corridor(shared_data, superpoint_weights):
    from support.lcd_corridor_cache import corridor_features

    folder = str(shared_data / "rtabmap_corridor")
    return (corridor_features(folder, "superpoint", str(superpoint_weights)),
            corridor_features(folder, "orb", None))


def test_real_descriptors_same_matches(corridor):
    sp, orb = corridor
    pairs = [(q, q - 40) for q in range(40, 84, 4)] + [(q, q - 20) for q in range(20, 84, 9)]
    for q, m in pairs:
        for rule in (dict(ratio=0.9, max_distance=0.8), dict(ratio=None, max_distance=None)):
            got, dist = mutual_nn_match_bf(sp[q].descriptors, sp[m].descriptors, return_distances=True, **rule)
            assert np.array_equal(got, _bf_reference(sp[q].descriptors, sp[m].descriptors, **rule))
            assert np.array_equal(got, mutual_nn_match(sp[q].descriptors, sp[m].descriptors, **rule))
            exact = np.linalg.norm(sp[q].descriptors[got[:, 0]].astype(np.float64)
                                   - sp[m].descriptors[got[:, 1]].astype(np.float64), axis=1)
            assert np.allclose(dist, exact, atol=1e-5)
        rule = dict(ratio=0.9, max_distance=64.0)
        assert np.array_equal(mutual_nn_match_bf(orb[q].descriptors, orb[m].descriptors, **rule),
                              _bf_reference(orb[q].descriptors, orb[m].descriptors, **rule))


def test_empty_and_single_row():
    e = np.zeros((0, 32), np.uint8)
    one = np.ones((1, 32), np.uint8)
    assert mutual_nn_match_bf(e, one, ratio=0.9).shape == (0, 2)
    m, d = mutual_nn_match_bf(one, one, ratio=0.9, return_distances=True)
    assert m.tolist() == [[0, 0]] and d.tolist() == [0.0]
