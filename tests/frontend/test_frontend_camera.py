"""Camera model from CameraInfo and camera mounting from the real /tf_static of a ROS 2 MCAP."""
from __future__ import annotations

import numpy as np
import pytest

from slam_lcd.errors import ConfigError, MessageEncodingError
from slam_lcd.frontend import FrontendConfig
from slam_lcd.geometry import pose_from_list
from slam_lcd.sensors.messages import camera_from_camera_info
from slam_lcd.sensors.mounting import camera_mounting
from slam_lcd.types import CameraModel
from slam_lcd.vision.camera import undistort_points


def _info(model: str, D):
    from slam_lcd.io.message_builders import camera_info_msg

    cam = CameraModel(640, 480, 520.9, 521.0, 325.1, 249.7, model, np.asarray(D, float))
    return camera_info_msg(cam, 1_000_000_000, "camera_optical_frame")


@pytest.mark.parametrize("model,D", [
    ("plumb_bob", [0.2312, -0.7849, -0.0033, -0.0001, 0.9172]),
    ("rational_polynomial", [0.1, -0.2, 0.001, 0.002, 0.05, 0.01, -0.02, 0.003]),
    ("equidistant", [0.1, -0.05, 0.01, 0.002]),
])
def test_camera_from_camera_info_models(model, D):
    cam = camera_from_camera_info(_info(model, D))
    assert (cam.width, cam.height) == (640, 480)
    assert cam.distortion_model == model
    assert np.allclose(cam.D, D)
    # a distorted corner is moved by the model, and undistortion inverts the projection
    from slam_lcd.vision.camera import distort_points

    n = undistort_points(cam, [[5.0, 5.0]], normalized=True)
    assert np.abs(distort_points(cam, n) - [[5.0, 5.0]]).max() < 1e-5
    assert np.abs(undistort_points(cam, [[5.0, 5.0]]) - [[5.0, 5.0]]).max() > 1.0


def test_zero_distortion_is_pinhole_and_unknown_model_is_rejected():
    cam = camera_from_camera_info(_info("plumb_bob", [0, 0, 0, 0, 0]))
    assert cam.distortion_model == "none"
    assert np.allclose(undistort_points(cam, [[10.0, 20.0]]), [[10.0, 20.0]])
    with pytest.raises(MessageEncodingError):
        camera_from_camera_info(_info("mei_unified", [0.1, 0.2, 0.0, 0.0, 0.0]))


def test_camera_mounting_from_real_tf_static(shared_data):
    from slam_lcd.io.tf import TfBuffer

    tf = TfBuffer.from_log(shared_data / "bags" / "nav2_turtlebot.mcap")
    conf = FrontendConfig(body_frame="base_link")
    T = camera_mounting(conf, tf, "oakd_rgb_camera_optical_frame")
    # chain base_link -> shell_link (z 0.0942) -> oakd_camera_bracket (-0.118, 0, 0.05257)
    # -> oakd_link (0.0584, 0, 0.09676) -> oakd_rgb_camera_frame -> optical frame (rotation only)
    assert np.allclose(T[:3, 3], [-0.118 + 0.0584, 0.0, 0.0942 + 0.05257 + 0.09676], atol=1e-6)
    # optical frame: camera z looks along body x, camera x along -body y, camera y along -body z
    assert np.allclose(T[:3, 2], [1, 0, 0], atol=1e-6)
    assert np.allclose(T[:3, 0], [0, -1, 0], atol=1e-6)
    assert np.allclose(T[:3, 1], [0, 0, -1], atol=1e-6)


def test_camera_mounting_from_config_wins():
    conf = FrontendConfig(T_body_camera=[0.1, 0.2, 0.3, 0.0, 0.0, 0.0, 1.0])
    T = camera_mounting(conf, None, "cam")
    assert np.allclose(T[:3, 3], [0.1, 0.2, 0.3]) and np.allclose(T[:3, :3], np.eye(3))
    assert np.allclose(camera_mounting(FrontendConfig(), None, None), np.eye(4))
    with pytest.raises(ConfigError):
        pose_from_list([1, 2, 3])
