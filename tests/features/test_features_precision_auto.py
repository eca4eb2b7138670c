"""``features.precision: auto``: bfloat16 only where the device computes it natively, float32 (the reference,
byte for byte) elsewhere."""
from __future__ import annotations

import numpy as np
import pytest
import torch

import slam_lcd.features.superpoint_extractor as spx
from slam_lcd.features import FeaturesConfig
from slam_lcd.features.superpoint import SuperPoint
from slam_lcd.features.superpoint_extractor import SuperPointExtractor, resolve_precision


def _extractor(precision: str) -> SuperPointExtractor:
    torch.manual_seed(0)
    conf = FeaturesConfig(kind="superpoint", precision=precision, max_keypoints=300)
    return SuperPointExtractor(conf, device="cpu", model=SuperPoint(SuperPointExtractor.model_conf(conf)))


def _image() -> np.ndarray:
    rng = np.random.default_rng(1)
    img = (rng.random((120, 160)) * 255).astype(np.uint8)
    return np.kron(img, np.ones((2, 2), np.uint8))  # 240x320, blocky: corners to detect


def test_auto_is_float32_byte_for_byte_where_bfloat16_is_not_native(monkeypatch):
    monkeypatch.setattr(spx, "bfloat16_is_native", lambda device: False)
    auto, f32 = _extractor("auto"), _extractor("float32")
    assert auto.precision == "float32" and auto.identity() == f32.identity()  # the same feature cache
    a, b = auto.extract(_image()), f32.extract(_image())
    assert a.keypoints.tobytes() == b.keypoints.tobytes() and a.descriptors.tobytes() == b.descriptors.tobytes()


def test_auto_is_bfloat16_where_the_device_computes_it(monkeypatch):
    monkeypatch.setattr(spx, "bfloat16_is_native", lambda device: True)
    ex = _extractor("auto")
    assert ex.precision == "bfloat16" and ex.identity()["backbone_precision"] == "bfloat16"
    assert resolve_precision("float32", torch.device("cpu")) == "float32"  # one setting away


def test_the_default_is_auto():
    assert FeaturesConfig().precision == "auto"


@pytest.mark.parametrize("setting", ["float32", "bfloat16"])
def test_explicit_settings_are_kept(setting):
    assert resolve_precision(setting, torch.device("cpu")) == setting
