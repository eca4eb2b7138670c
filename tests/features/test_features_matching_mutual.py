"""Brute-force mutual matching: the same pairs and ratios as a plain distance-matrix rule, ties included."""
import numpy as np
import pytest

from slam_lcd.features.matching import mutual_nn_match_bf, mutual_nn_match_symmetric
from slam_lcd.vision.column_best import first_in_column


def _unit(x):
    return (x / np.linalg.norm(x, axis=1, keepdims=True)).astype(np.float32)


def _coarse_pair(rng, t):
    """Descriptors on a coarse lattice (many exactly equal distances), with copies across and within images."""
    n1, n2 = rng.integers(1, 150, 2)
    q = int(rng.integers(2, 5))
    d1 = _unit(rng.integers(-q, q + 1, (n1, 6)) + 0.5)
    d2 = _unit(rng.integers(-q, q + 1, (n2, 6)) + 0.5)
    if t % 3 == 0:
        d2[: n2 // 2] = d1[rng.integers(0, n1, n2 // 2)]
    if t % 4 == 0:
        d1 = np.repeat(d1[: max(1, n1 // 3)], 3, axis=0)
    return d1, d2


def _reference(d1, d2, max_distance):
    """Mutual nearest neighbours and symmetric ratios from the distance matrix, the first index winning ties
    (squared distances formed in the matcher's order, so that exact copies round alike)."""
    a, b = d1.astype(np.float32), d2.astype(np.float32)
    sq = a @ b.T
    sq *= -2.0  # the matcher scales a instead: the same bits
    sq += np.einsum("ij,ij->i", a, a)[:, None]
    sq += np.einsum("ij,ij->i", b, b)[None, :]
    sq = np.maximum(sq, 0.0)
    dist = np.sqrt(sq.astype(np.float64))
    rows = np.arange(len(a))
    nn12, nn21 = dist.argmin(1), dist.argmin(0)
    keep = nn21[nn12] == rows
    if max_distance is not None:
        keep &= dist[rows, nn12] < max_distance
    i, j = rows[keep], nn12[keep]
    row2 = np.array([np.sort(dist[r])[1] if dist.shape[1] > 1 else np.inf for r in i])
    col2 = np.array([np.sort(dist[:, c])[1] if dist.shape[0] > 1 else np.inf for c in j])
    ratios = dist[i, j] / np.maximum(np.minimum(row2, col2), 1e-12) if len(i) else np.zeros(0)
    return np.stack([i, j], axis=1), ratios


@pytest.mark.parametrize("max_distance", [None, 0.6])
def test_symmetric_matching_equals_the_distance_matrix_rule_with_ties(max_distance):
    rng = np.random.default_rng(7)
    for t in range(120):
        d1, d2 = _coarse_pair(rng, t)
        m, _, ratios = mutual_nn_match_symmetric(d1, d2, max_distance=max_distance)
        ref_m, ref_ratios = _reference(d1, d2, max_distance)
        assert np.array_equal(m, ref_m), t
        np.testing.assert_allclose(ratios, ref_ratios, rtol=1e-5, atol=1e-6, err_msg=str(t))
        m_no, _, none = mutual_nn_match_symmetric(d1, d2, max_distance=max_distance, with_ratios=False)
        assert none is None and np.array_equal(m_no, ref_m), t


def test_one_sided_matching_keeps_only_mutual_pairs_with_ties():
    rng = np.random.default_rng(8)
    for t in range(120):
        d1, d2 = _coarse_pair(rng, t)
        ref_m, _ = _reference(d1, d2, None)
        assert np.array_equal(mutual_nn_match_bf(d1, d2), ref_m), t


def test_first_in_column_is_the_column_arg_extreme():
    rng = np.random.default_rng(9)
    for t in range(200):
        s = rng.integers(0, 4, (int(rng.integers(1, 40)), int(rng.integers(1, 40)))).astype(np.float32)
        for largest in (True, False):
            cols = s.argmax(1) if largest else s.argmin(1)
            vals = s[np.arange(len(s)), cols]
            want = (s.argmax(0) if largest else s.argmin(0))[cols] == np.arange(len(s))
            assert np.array_equal(first_in_column(s, cols, vals, largest), want), (t, largest)
