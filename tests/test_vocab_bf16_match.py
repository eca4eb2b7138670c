"""Word growth's match to the previous image from a bfloat16 or int8 product gives the float32 rule's matches."""
from __future__ import annotations

import numpy as np
import pytest

from slam_lcd.errors import ConfigError
from slam_lcd.vocab import IncrementalWords, as_unit_vectors
from slam_lcd.vocab.bf16_match import (ERROR_BOUND, int8_available, int8_error_bound, mutual_nn_unit_bf16,
                                       mutual_nn_unit_int8, to_bf16, to_int8)
from slam_lcd.vocab.words import mutual_nn_unit


needs_int8 = pytest.mark.skipif(not int8_available(), reason="this torch has no int8 CPU product (torch._int_mm)")


def rounded_match(product, a, b, ratio, max_distance):
    if product == "int8":
        return mutual_nn_unit_int8(a, b, ratio, max_distance, to_int8(a), to_int8(b))
    return mutual_nn_unit_bf16(a, b, ratio, max_distance, to_bf16(a), to_bf16(b))


PRODUCTS = ["bfloat16", pytest.param("int8", marks=needs_int8)]


def views(rng, landmarks, idx, noise):
    """Noisy unit views of ``landmarks[idx]`` (noise ~ ``noise`` in L2)."""
    x = landmarks[idx] + noise * rng.standard_normal((len(idx), landmarks.shape[1])).astype(np.float32) / 16
    return as_unit_vectors(x)


@pytest.mark.parametrize("product", PRODUCTS)
@pytest.mark.parametrize("noise", [0.1, 0.3, 0.45, 0.6, 0.8])
@pytest.mark.parametrize("ratio, max_distance", [(0.9, 0.8), (None, 0.8), (0.8, 1.0), (0.95, 0.5)])
def test_rounded_candidates_give_the_float32_matches(product, noise, ratio, max_distance):
    # consecutive images of one scene: most landmarks seen twice, at every distance around the thresholds
    rng = np.random.default_rng(int(noise * 100))
    landmarks = as_unit_vectors(rng.standard_normal((1500, 256)).astype(np.float32))
    a = views(rng, landmarks, rng.choice(1500, 700, replace=False), noise)
    b = views(rng, landmarks, rng.choice(1500, 650, replace=False), noise)
    m32, d32 = mutual_nn_unit(a, b, ratio, max_distance, return_distances=True)
    m16, d16 = rounded_match(product, a, b, ratio, max_distance)
    assert len(m32) > 0 or noise > 0.8 * max_distance
    assert np.array_equal(m16, m32)
    assert np.allclose(d16, d32, atol=1e-5)


@pytest.mark.parametrize("product", PRODUCTS)
@pytest.mark.parametrize("third", [False, True])
def test_ratio_test_near_its_bound_is_decided_on_float32_rows(product, third):
    # each query has its best match just inside the distance bound and a rival at about best / ratio:
    # the bfloat16 bounds cannot decide the ratio test, the float32 row must (and the outcome still
    # equals the float32 rule)
    rng = np.random.default_rng(5)
    n = 200
    e1, e2, e3 = np.linalg.qr(rng.standard_normal((n, 64, 3)))[0].transpose(2, 0, 1)
    d_best = rng.uniform(0.80, 0.88, n)
    d_rival = d_best / rng.uniform(0.86, 0.94, n)
    angle = lambda d: 2 * np.arcsin(d / 2)  # noqa: E731 - chord length -> angle on the unit sphere
    query = e1.astype(np.float32)
    best = (np.cos(angle(d_best))[:, None] * e1 + np.sin(angle(d_best))[:, None] * e2).astype(np.float32)
    rival = (np.cos(angle(d_rival))[:, None] * e1 + np.sin(angle(d_rival))[:, None] * e3).astype(np.float32)
    cols = [best, rival]
    if third:  # a third neighbour around the candidate threshold: sometimes a candidate, sometimes not
        e4 = np.linalg.qr(rng.standard_normal((n, 64, 4)))[0][:, :, 3]
        d_third = rng.uniform(0.92, 0.96, n)
        cols.append((np.cos(angle(d_third))[:, None] * e1 + np.sin(angle(d_third))[:, None] * e4).astype(np.float32))
    cols = np.concatenate(cols)
    m32 = mutual_nn_unit(query, cols, 0.9, 0.9)
    m16, _ = (mutual_nn_unit_int8 if product == "int8" else mutual_nn_unit_bf16)(query, cols, 0.9, 0.9)
    assert 0 < len(m32) < n  # the ratio test rejected some and kept others
    assert np.array_equal(m16, m32)


def test_error_bound_holds_for_unit_vectors():
    rng = np.random.default_rng(3)
    a = as_unit_vectors(rng.standard_normal((300, 256)).astype(np.float32))
    b = as_unit_vectors(np.concatenate([a[:100] + 0.01 * rng.standard_normal((100, 256)).astype(np.float32),
                                        rng.standard_normal((200, 256)).astype(np.float32)]))
    approx = (to_bf16(a) @ to_bf16(b).T).float().numpy()[:300, :300]
    assert np.abs(approx - a.astype(np.float64) @ b.T.astype(np.float64)).max() < ERROR_BOUND


@needs_int8
def test_int8_error_bound_holds_and_is_tight_enough():
    # the bound is rigorous for any two images; on unit rows like SuperPoint's (largest component ~0.3)
    # it stays a few hundredths, so the candidates are barely more than the bfloat16 product's
    rng = np.random.default_rng(3)
    a = as_unit_vectors(rng.standard_normal((300, 256)).astype(np.float32))
    b = as_unit_vectors(np.concatenate([a[:100] + 0.01 * rng.standard_normal((100, 256)).astype(np.float32),
                                        rng.standard_normal((200, 256)).astype(np.float32)]))
    ha, hb = to_int8(a), to_int8(b)
    approx = (ha.t.numpy()[:300].astype(np.int64) @ hb.t.numpy()[:300].astype(np.int64).T) / (ha.scale * hb.scale)
    err = np.abs(approx - a.astype(np.float64) @ b.T.astype(np.float64)).max()
    bound = int8_error_bound(ha, hb)
    assert err < bound < 0.05
    one_hot = np.zeros((4, 256), np.float32)
    one_hot[:, 0] = 1  # the largest possible component: scale 127, no rounding residual
    h = to_int8(one_hot)
    assert h.scale == 127 and h.residual_norm == 0


@pytest.mark.parametrize("product", ["float32", "bfloat16", pytest.param("int8", marks=needs_int8)])
def test_word_growth_is_the_same_with_either_product(product):
    rng = np.random.default_rng(4)
    landmarks = as_unit_vectors(rng.standard_normal((3000, 128)).astype(np.float32))
    images = [views(rng, landmarks, np.flatnonzero(rng.random(3000) < 0.15)[:400], 0.35) for _ in range(6)]
    ref = IncrementalWords(128, 0.9, 0.8, product="float32")
    got = IncrementalWords(128, 0.9, 0.8, product=product)
    assert got.product == product
    for d in images:
        assert np.array_equal(got.add_image(d), ref.add_image(d))
    assert np.array_equal(got.centres, ref.centres)


def test_unknown_product_is_a_config_error():
    with pytest.raises(ConfigError, match="match_product"):
        IncrementalWords(32, product="float16")


def test_auto_product_takes_the_fastest_the_machine_has():
    from slam_lcd.vocab.bf16_match import auto_product, bf16_fast, int8_fast

    import torch  # noqa: F401 - auto only rounds when torch is loaded already

    expected = "int8" if int8_fast() else ("bfloat16" if bf16_fast() else "float32")
    assert auto_product() == expected and IncrementalWords(32).product == expected
    if int8_available():  # no positive similarity bound at this distance: float32
        assert IncrementalWords(32, max_distance=1.5, product="int8").product == "float32"
