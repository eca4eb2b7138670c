import numpy as np

from slam_lcd.features.matching import descriptor_distances, mutual_nn_match


def test_mutual_nn_float_identity_under_permutation():
    rng = np.random.default_rng(0)
    d = rng.normal(size=(50, 256)).astype(np.float32)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    perm = rng.permutation(50)
    m = mutual_nn_match(d, d[perm] + 0.01 * rng.normal(size=(50, 256)).astype(np.float32), ratio=0.9)
    assert len(m) == 50
    assert np.all(perm[m[:, 1]] == m[:, 0])


def test_hamming_distance_matches_bit_count():
    a = np.array([[0b10110000, 0]], dtype=np.uint8)
    b = np.array([[0b00010000, 255]], dtype=np.uint8)
    assert descriptor_distances(a, b)[0, 0] == 2 + 8


def test_empty_inputs():
    assert mutual_nn_match(np.zeros((0, 8), np.float32), np.ones((3, 8), np.float32)).shape == (0, 2)
