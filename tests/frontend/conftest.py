"""The rendered demo log the front-end tests share: 60 frames at 320x240 with depth and stereo."""
from __future__ import annotations

import numpy as np
import pytest

from slam_lcd.types import Trajectory

W, H = 320, 240
N_FRAMES = 60  # 6 s of driving along the first corridor


@pytest.fixture(scope="session")
def demo_log(tmp_path_factory):
    """A seeded demo-world MCAP with depth and stereo (slam_lcd.sim), written once per test run."""
    from slam_lcd.sim.demo_log import make_demo_log

    out = tmp_path_factory.mktemp("frontend") / "demo_stereo_depth.mcap"
    make_demo_log(out, "mcap", frames=N_FRAMES, seed=0, stereo=True, depth=True, width=W, height=H)
    return out


@pytest.fixture(scope="session")
def demo(demo_log):
    """Frames, camera, mounting and ground truth read back from the log with slam_lcd.io."""
    from slam_lcd.io import open_log, read_trajectory_from_log
    from slam_lcd.io.decode import decode_camera_info, decode_image
    from slam_lcd.io.tf import TfBuffer

    imgs, depths, rights = {}, {}, {}
    cam = None
    with open_log(demo_log) as r:
        topics = ["/camera/image_raw", "/camera/depth", "/camera/right/image_raw", "/camera/right/camera_info"]
        for m in r.messages(topics):
            if m.topic == "/camera/right/camera_info":
                cam = cam or decode_camera_info(m.msg)
                continue
            by_topic = {"/camera/image_raw": imgs, "/camera/depth": depths, "/camera/right/image_raw": rights}
            by_topic[m.topic][m.stamp] = decode_image(m.msg)
    stamps = np.array(sorted(imgs), np.int64)
    T_bc = TfBuffer.from_log(demo_log).lookup("base_link", "camera_optical_frame", int(stamps[0]))
    gt_all = read_trajectory_from_log(demo_log, "/ground_truth/pose")
    index = {int(s): i for i, s in enumerate(gt_all.stamps)}
    gt = Trajectory(stamps=stamps, poses=np.array([gt_all.poses[index[int(s)]] for s in stamps]))
    frames = [(imgs[s], depths[s], rights[s]) for s in stamps]
    return gt, cam, T_bc, frames
