"""The demo world in the dataset layouts (``make-demo-log --layout``) read end to end by its preset.

Per layout one tiny log (60 frames, 320x240: the VO tracks from that size on, TUM's RGB-D
VO with its Kinect depth errors too since its discontinuity test works in inverse depth) run with
``--config <preset>`` and no topic flag (ORB features keep each run at seconds): the topics
the preset names are found, the calibration file is read (EuRoC), the ground truth is read
from the layout's message (PointStamped, TF chain), the built-in VO is the odometry and
its ATE is small; stereo layouts give the loop detector each keyframe's pair (SGBM once per
keyframe, never for the frames between).
"""
from __future__ import annotations

import logging

import numpy as np
import pytest

from slam_lcd.config import load_config
from slam_lcd.io import open_log
from slam_lcd.run import OutputOptions, Sources, run_log
from slam_lcd.sim import make_demo_log

FRAMES, W, H = 60, 320, 240

EXPECTED = {  # layout: (preset, image topic, ground-truth topic, right topic, depth topic, gt message type)
    "euroc": ("euroc", "/cam0/image_raw", "/leica/position", "/cam1/image_raw", None, "geometry_msgs/msg/PointStamped"),
    "tum": ("tum-rgbd", "/camera/rgb/image_color", "/tf", None, "/camera/depth_registered/image_raw",
            "tf2_msgs/msg/TFMessage"),
    "kitti": ("kitti", "/kitti/camera_gray_left/image_raw", "/tf", "/kitti/camera_gray_right/image_raw", None,
              "tf2_msgs/msg/TFMessage"),
}


@pytest.fixture(scope="module")
def layout_logs(tmp_path_factory):
    root = tmp_path_factory.mktemp("layouts")
    return {name: make_demo_log(root / f"{name}.mcap", "mcap", frames=FRAMES, width=W, height=H, layout=name,
                                workers=0) for name in EXPECTED}


@pytest.mark.parametrize("layout", list(EXPECTED))
def test_layout_is_read_by_its_preset(layout, layout_logs, tmp_path, monkeypatch, caplog):
    preset, image, gt, right, depth, gt_type = EXPECTED[layout]
    info = layout_logs[layout]
    with open_log(info.path) as r:  # the layout as the dataset has it: no odometry, the ground-truth type
        types = {t: i.msgtype for t, i in r.topics.items()}
    assert "nav_msgs/msg/Odometry" not in types.values() and types[gt] == gt_type
    assert (layout == "euroc") == ("sensor_msgs/msg/CameraInfo" not in types.values())
    import slam_lcd.lcd.geometry as lcd_geometry

    calls = []
    real_sgbm = lcd_geometry.dense_disparity
    monkeypatch.setattr(lcd_geometry, "dense_disparity", lambda left, right: calls.append(1) or real_sgbm(left, right))
    cfg = load_config(preset, ["features.kind=orb", "features.feature_cache=false", "run.plots=false",
                               "run.loop_pictures=false"])
    calib = [info.calibration_path] if layout == "euroc" else None
    with caplog.at_level(logging.WARNING, logger="slam_lcd"):
        res = run_log(info.path, tmp_path / "out", cfg, sources=Sources(calib=calib),
                      output=OutputOptions(progress=False, write_mcap=False))
    assert res.topics["image"] == image and res.topics.get("gt") == gt
    assert res.topics.get("right") == right and res.topics.get("depth") == depth and not res.topics.get("odom")
    assert res.n_frames == FRAMES and res.n_keyframes >= 3
    assert res.ate_before is not None and np.isfinite(res.ate_before)
    assert res.ate_before < 0.03 * info.path_length_m, (res.ate_before, info.path_length_m)
    if layout == "tum":  # the layout's depth is the Kinect's, with no-reading pixels
        assert info.depth_model is not None and "Kinect v1" in info.summary()
    if layout == "euroc":
        assert info.calibration_path.name == "camchain-euroc.yaml"
        assert "position-only" in res.alignment
        assert any("not a rectified pair: the stereo VO rectifies them" in m.getMessage() for m in caplog.records)
    if right is not None:  # SGBM once per keyframe, never for the frames between
        assert len(calls) == res.n_keyframes, (len(calls), res.n_keyframes)
    else:
        assert not calls
