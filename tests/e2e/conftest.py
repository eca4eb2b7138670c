"""Fixtures of the end-to-end tests: one SuperPoint extractor and demo-world keyframes for the plugin examples."""
from __future__ import annotations

import pytest


@pytest.fixture(scope="session")
def superpoint_cpu(superpoint_weights):
    """One SuperPoint extractor on the CPU for the plugin tests (feature cache on)."""
    from slam_lcd.features import FeaturesConfig, load_extractor

    return load_extractor(FeaturesConfig(kind="superpoint"), weights=superpoint_weights, device="cpu")


@pytest.fixture(scope="session")
def demo_keyframes_rgbd(superpoint_cpu):
    """2 laps of demo-world RGB-D keyframes at 1 Hz, 320x240, with features and exact ground truth."""
    from slam_lcd.sim.keyframes import demo_keyframes

    return demo_keyframes(superpoint_cpu, sensor="rgbd")
