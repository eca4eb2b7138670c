"""Shared fixtures: where the real data lives (``../shared`` or ``$SLAM_LCD_SHARED``)."""
from __future__ import annotations

import os
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent


def shared_root() -> Path | None:
    env = os.environ.get("SLAM_LCD_SHARED")
    cand = Path(env) if env else REPO.parent / "shared"
    return cand if (cand / "data").is_dir() else None


@pytest.fixture(scope="session")
def shared() -> Path:
    root = shared_root()
    if root is None:
        pytest.skip("real data folder ../shared (or $SLAM_LCD_SHARED) is absent")
    return root


@pytest.fixture(scope="session")
def shared_data(shared) -> Path:
    return shared / "data"


@pytest.fixture(scope="session")
def superpoint_weights(shared) -> Path:
    p = shared / "weights" / "superpoint_community.pth"
    if not p.is_file():
        pytest.skip(f"SuperPoint test checkpoint not found at {p}")
    return p
