"""``features.resize_max``: extraction on a smaller copy, keypoints in the full image's pixels.

Unset, every output is bit for bit the network's own result on the full image (the same
feature-cache key, the same pipeline result); set, the keypoints land on the full-resolution
pixels of what they mark.
"""
from __future__ import annotations

import numpy as np
import pytest
import torch

from slam_lcd.config import load_config, preset_names
from slam_lcd.errors import ConfigError
from slam_lcd.features import FeatureCache, FeaturesConfig, load_extractor
from slam_lcd.features.resize import downscale, resized_shape, to_full_resolution
from slam_lcd.vision.gray import to_gray_float

from support.module_files import random_extractor


def textured(h=120, w=160, seed=0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    img = np.zeros((h, w), np.uint8)
    for _ in range(40):
        x0, y0 = rng.integers(0, w - 10), rng.integers(0, h - 10)
        img[y0 : y0 + rng.integers(5, 30), x0 : x0 + rng.integers(5, 30)] = rng.integers(0, 256)
    return img


def test_longest_side_at_most_n_aspect_kept_never_enlarged():
    assert resized_shape(480, 640, 320) == (240, 320)
    assert resized_shape(376, 1241, 400) == (121, 400)  # KITTI: 0.3223 x
    assert resized_shape(384, 512, 400) == (300, 400)
    assert resized_shape(240, 320, 320) == (240, 320) and resized_shape(240, 320, 640) == (240, 320)
    assert resized_shape(480, 640, None) == (480, 640)
    img = np.zeros((10, 20), np.uint8)
    assert downscale(img, 20) is img and downscale(img, None) is img


def test_area_interpolation_averages_blocks():
    img = np.arange(16, dtype=np.float32).reshape(4, 4)
    small = downscale(img, 2)
    assert small.shape == (2, 2)
    np.testing.assert_allclose(small, [[img[:2, :2].mean(), img[:2, 2:].mean()],
                                       [img[2:, :2].mean(), img[2:, 2:].mean()]])


def test_keypoints_map_pixel_centre_to_pixel_centre():
    kp = np.array([[0, 0], [159, 119], [10, 20]], np.float32)
    full = to_full_resolution(kp, (160, 120), (320, 240))
    # small pixel 0 was averaged from full pixels 0 and 1: its centre is 0.5
    np.testing.assert_allclose(full, [[0.5, 0.5], [318.5, 238.5], [20.5, 40.5]])
    assert to_full_resolution(kp, (160, 120), (160, 120)) is kp  # no arithmetic when nothing was resized


def test_unset_is_bit_identical_to_the_network_on_the_full_image():
    img = textured()
    ex = random_extractor()
    f = ex.extract(img)
    # the model itself on the full-resolution tensor, channels-last as the extractor feeds it
    x = torch.from_numpy(to_gray_float(img)[None, None]).contiguous(memory_format=torch.channels_last)
    with torch.inference_mode():
        ref = ex.model({"image": x})
    assert len(f.keypoints) > 20
    assert np.array_equal(f.keypoints, ref["keypoints"][0].numpy())
    assert np.array_equal(f.descriptors, ref["descriptors"][0].numpy())
    assert np.array_equal(f.scores, ref["keypoint_scores"][0].numpy())
    # an image that already fits: the same bits, only the cache key names the knob
    g = random_extractor(resize_max=160).extract(img)
    assert np.array_equal(f.keypoints, g.keypoints) and np.array_equal(f.descriptors, g.descriptors)
    # batched against single extraction: test_features_superpoint (float rounding may differ by batch size)


def test_feature_cache_is_keyed_on_resize_max(tmp_path):
    plain, small = random_extractor(), random_extractor(resize_max=80)
    assert "resize_max" not in plain.identity()  # unset: existing caches keep their key
    assert small.identity()["resize_max"] == 80
    assert FeatureCache(plain, tmp_path).base != FeatureCache(small, tmp_path).base
    orb = load_extractor(FeaturesConfig(kind="orb"))
    orb_small = load_extractor(FeaturesConfig(kind="orb", resize_max=80))
    assert "resize_max" not in orb.identity() and orb.fingerprint != orb_small.fingerprint


def test_resized_features_are_reported_at_full_resolution():
    img = textured(240, 320)
    for ex in (random_extractor(resize_max=160), load_extractor(FeaturesConfig(kind="orb", resize_max=160))):
        f = ex.extract(img)
        assert f.image_size == (320, 240) and len(f.keypoints) > 10
        assert f.keypoints.dtype == np.float32
        assert f.keypoints[:, 0].max() < 320 and f.keypoints[:, 1].max() < 240 and f.keypoints.min() >= 0
        # the network saw 160 x 120: keypoints lie on the centres of 2 x 2 blocks
        if ex.kind == "superpoint":
            assert np.allclose((f.keypoints - 0.5) % 2, 0)
            # another aspect: its own batch of one, so the first image's bits are the single call's
            b = ex.extract_batch([img, textured(400, 640)])
            assert np.array_equal(b[0].keypoints, f.keypoints) and b[1].image_size == (640, 400)


def test_resize_max_is_validated():
    assert load_config("default", ["features.resize_max=320"]).features.resize_max == 320
    assert load_config("default", ["features.resize_max=null"]).features.resize_max is None
    for bad in ("10", "-1", "0.5", "big"):
        with pytest.raises(ConfigError, match="resize_max"):
            load_config("default", [f"features.resize_max={bad}"])


def test_fast_and_accurate_presets_ship_and_load():
    assert {"default", "fast", "accurate"} <= set(preset_names())
    fast, accurate, default = load_config("fast"), load_config("accurate"), load_config("default")
    assert fast.features.kind == accurate.features.kind == "superpoint"
    assert fast.features.resize_max is not None and accurate.features.resize_max is None
    # they change features only: the rest of a run is the default's
    for section in ("frontend", "lcd", "backend", "vocab"):
        assert getattr(fast, section) == getattr(default, section) == getattr(accurate, section)


def _corners_image() -> tuple[np.ndarray, np.ndarray]:
    """640 x 480: bright rectangles on a dark ground; the outer corners' pixel positions."""
    img = np.full((480, 640), 40, np.uint8)
    corners = []
    for x0, y0, x1, y1 in ((100, 80, 260, 200), (360, 260, 560, 420), (120, 300, 220, 400), (400, 60, 520, 160)):
        img[y0:y1, x0:x1] = 220
        corners += [(x0, y0), (x1 - 1, y0), (x0, y1 - 1), (x1 - 1, y1 - 1)]
    return img, np.array(corners, np.float32)


def test_a_corner_lands_on_the_same_full_resolution_pixel(superpoint_weights):
    """Each rectangle corner is found near its pixel at full resolution and on a resized copy (a pixel of
    the copy is ``scale`` full pixels wide: +-1 pixel of it is the detector's own spread); the offsets
    average out to under half a pixel, which a mapping off by half a pixel of the copy would not."""
    img, corners = _corners_image()
    for resize_max in (None, 320, 480):
        ex = load_extractor(FeaturesConfig(feature_cache=False, resize_max=resize_max), weights=superpoint_weights,
                            device="cpu")
        f = ex.extract(img)
        assert f.image_size == (640, 480)
        d = f.keypoints[None] - corners[:, None]
        off = d[np.arange(len(corners)), np.linalg.norm(d, axis=2).argmin(axis=1)]
        scale = 640 / (resize_max or 640)
        assert np.all(np.abs(off) <= 0.5 + scale), (resize_max, off)
        assert np.all(np.abs(off.mean(axis=0)) < 0.5), (resize_max, off.mean(axis=0))


def test_unset_gives_the_same_pipeline_result(tmp_path, superpoint_weights):
    """A short run (a little more than a lap at 160x120, so loops close) with the knob unset and with a
    resize_max the images already fit: the same keyframes, loops and corrected trajectory, bit for bit."""
    from slam_lcd.run import OutputOptions, run_log
    from slam_lcd.sim import make_demo_log

    log = tmp_path / "tiny.mcap"
    make_demo_log(log, "mcap", frames=470, seed=1, depth=True, width=160, height=120)
    outs = {}
    for label, sets in (("unset", []), ("fits", ["features.resize_max=160"])):
        cfg = load_config("default", ["features.feature_cache=false", f"features.weights={superpoint_weights}",
                                      "run.plots=false", "run.write_mcap=false", "run.loop_pictures=false", *sets])
        res = run_log(log, tmp_path / label, cfg, output=OutputOptions(progress=False))
        outs[label] = res
    a, b = outs["unset"], outs["fits"]
    assert a.n_keyframes > 50 and a.loops_accepted > 0
    assert (a.n_keyframes, a.loops_proposed, a.loops_accepted, a.ate_after) == \
        (b.n_keyframes, b.loops_proposed, b.loops_accepted, b.ate_after)
    for name in ("corrected.tum", "loops.csv"):
        assert (tmp_path / "unset" / name).read_bytes() == (tmp_path / "fits" / name).read_bytes(), name
