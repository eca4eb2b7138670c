"""ORB baseline behind the extractor interface, and the on-disk feature cache."""
from __future__ import annotations

import numpy as np
import pytest
import torch

from slam_lcd.features import (
    FeatureCache,
    FeaturesConfig,
    OrbExtractor,
    SuperPoint,
    SuperPointExtractor,
    load_extractor,
)
from slam_lcd.features.cache import log_key
from slam_lcd.features.matching import mutual_nn_match

from support.paths import REPO


def texture(h=240, w=320, seed=0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    img = np.full((h, w), 128, np.uint8)
    for _ in range(60):
        x0, y0 = rng.integers(0, w - 20), rng.integers(0, h - 20)
        img[y0 : y0 + rng.integers(8, 40), x0 : x0 + rng.integers(8, 40)] = rng.integers(0, 256)
    return img


def random_superpoint(seed=0, **changes) -> SuperPointExtractor:
    conf = FeaturesConfig(max_keypoints=200, **changes)
    torch.manual_seed(seed)
    return SuperPointExtractor(conf, device="cpu", model=SuperPoint(SuperPointExtractor.model_conf(conf)))


def test_orb_interface_and_binary_descriptors():
    ex = load_extractor(FeaturesConfig(kind="orb", orb_n_features=300))
    assert isinstance(ex, OrbExtractor) and ex.descriptor_dtype == np.uint8
    img = texture()
    f = ex.extract(img)
    assert f.kind == "orb" and f.image_size == (320, 240)
    assert 20 < len(f) <= 300
    assert f.descriptors.dtype == np.uint8 and f.descriptors.shape == (len(f), 32)
    assert f.keypoints.dtype == np.float32 and np.all(np.diff(f.scores) <= 0)
    # RGB and float input give the same result as uint8 gray
    rgb = np.repeat(img[:, :, None], 3, axis=2)
    np.testing.assert_array_equal(ex.extract(rgb).keypoints, f.keypoints)
    np.testing.assert_array_equal(ex.extract(img.astype(np.float32) / 255).keypoints, f.keypoints)
    # a shifted copy matches itself with the known shift (Hamming mutual NN)
    g = ex.extract(np.roll(img, (5, 7), axis=(0, 1)))
    m = mutual_nn_match(f.descriptors, g.descriptors)
    err = np.linalg.norm(f.keypoints[m[:, 0]] + [7, 5] - g.keypoints[m[:, 1]], axis=1)
    assert (err < 2).mean() > 0.8


def test_orb_on_blank_image_gives_empty_features():
    f = load_extractor(FeaturesConfig(kind="orb")).extract(np.zeros((100, 120), np.uint8))
    assert len(f) == 0 and f.descriptors.shape == (0, 32) and f.descriptors.dtype == np.uint8


def test_cache_roundtrip_hits_and_keys(tmp_path):
    log = tmp_path / "run.mcap"
    log.write_bytes(b"fake log bytes")
    ex = random_superpoint()
    cache = FeatureCache(ex, tmp_path / "cache")
    img = texture()
    f1 = cache.extract(log, "/camera/image_raw", 1_000, img)
    f2 = cache.extract(log, "/camera/image_raw", 1_000, img)
    assert (cache.misses, cache.hits) == (1, 1)
    np.testing.assert_array_equal(f1.keypoints, f2.keypoints)
    np.testing.assert_array_equal(f1.descriptors, f2.descriptors)
    assert f2.image_size == f1.image_size and f2.kind == "superpoint"
    p = cache.path(log, "/camera/image_raw", 1_000)
    assert p.suffix == ".npz" and p.is_file()
    with np.load(p, allow_pickle=False) as z:  # plain arrays only
        assert set(z.files) == {"keypoints", "scores", "descriptors", "image_size", "kind"}
    # other topic / stamp / config / log content -> other key
    assert cache.path(log, "/other", 1_000) != p
    assert cache.path(log, "/camera/image_raw", 1_001) != p
    other = FeatureCache(random_superpoint(nms_radius=3), tmp_path / "cache")
    assert other.path(log, "/camera/image_raw", 1_000) != p
    assert FeatureCache(random_superpoint(seed=1), tmp_path / "cache").path(log, "/camera/image_raw", 1_000) != p
    k0 = log_key(log)
    log.write_bytes(b"a different, longer recording")
    assert log_key(log) != k0


def test_cache_batch_only_computes_misses_and_survives_corruption(tmp_path):
    log = tmp_path / "bagdir"
    log.mkdir()
    (log / "metadata.yaml").write_text("x")
    ex = load_extractor(FeaturesConfig(kind="orb", orb_n_features=200))
    cache = FeatureCache(ex, tmp_path / "cache")
    imgs = [texture(seed=s) for s in range(3)]
    cache.extract_batch(log, "/cam", [1, 2], imgs[:2])
    out = cache.extract_batch(log, "/cam", [1, 2, 3], imgs)
    assert (cache.misses, cache.hits) == (3, 2)
    assert out[2].descriptors.dtype == np.uint8
    # a truncated entry is a miss, recomputed and rewritten
    p = cache.path(log, "/cam", 2)
    p.write_bytes(p.read_bytes()[:20])
    f = cache.extract(log, "/cam", 2, imgs[1])
    np.testing.assert_array_equal(f.keypoints, ex.extract(imgs[1]).keypoints)
    assert cache.get(log, "/cam", 2) is not None


@pytest.mark.parametrize("kind", ["orb", "superpoint"])
def test_fingerprint_ignores_device_but_not_settings(kind):
    if kind == "orb":
        a = load_extractor(FeaturesConfig(kind="orb"))
        b = load_extractor(FeaturesConfig(kind="orb", orb_n_features=123))
    else:
        a = random_superpoint()
        b = random_superpoint(descriptor_sampling="bicubic")
    assert a.fingerprint != b.fingerprint
    fresh = load_extractor(FeaturesConfig(kind="orb")) if kind == "orb" else random_superpoint()
    assert a.fingerprint == fresh.fingerprint


def test_an_orb_run_does_not_import_torch(tmp_path):
    """ORB through the runner (the offline fallback, the baseline, a batch of ORB logs) leaves torch
    unimported: a fresh process each time would pay its ~3 s import for nothing."""
    import os
    import subprocess
    import sys

    from slam_lcd.sim import make_demo_log

    log = tmp_path / "d.mcap"
    make_demo_log(log, "mcap", frames=20, width=160, height=120)
    code = ("import sys; from pathlib import Path; from slam_lcd.config import load_config; "
            "from slam_lcd.run import OutputOptions, run_log; "
            "cfg = load_config('default', ['features.kind=orb', 'features.feature_cache=false', 'run.plots=false']); "
            f"r = run_log(Path({str(log)!r}), Path({str(tmp_path / 'out')!r}), "
            "cfg, output=OutputOptions(progress=False)); "
            "print(r.n_keyframes, 'torch' in sys.modules)")
    repo = REPO
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                         env={**os.environ, "PYTHONPATH": str(repo)})
    n_keyframes, torch_loaded = out.stdout.split()[-2:]
    assert int(n_keyframes) > 0 and torch_loaded == "False", out.stdout
