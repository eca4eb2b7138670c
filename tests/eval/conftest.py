"""Fixtures of the evaluation tests: the real trajectories of the shared data folder."""
from __future__ import annotations

import pytest

from slam_lcd.io.trajectory_files import read_trajectory


@pytest.fixture(scope="session")
def tdir(shared_data):
    """The shared trajectories: KITTI 00 and TUM fr2/desk ground truth with ORB-SLAM estimates."""
    return shared_data / "trajectories"


@pytest.fixture(scope="session")
def fr2(tdir):
    """TUM fr2/desk: (ground truth, ORB-SLAM estimate) as slam-lcd trajectories."""
    return read_trajectory(tdir / "fr2_desk_groundtruth.txt"), read_trajectory(tdir / "fr2_desk_ORB.txt")
