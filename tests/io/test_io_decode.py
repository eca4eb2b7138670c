"""Decoders: every supported image encoding (incl. row padding and big-endian), compressed images,
camera info, poses and the covariance convention; the TF buffer on hand-made transforms."""
from __future__ import annotations

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from slam_lcd.io import message_builders as M
from slam_lcd.io.decode import (
    decode_camera_info,
    decode_compressed_image,
    decode_image,
    decode_pose,
)
from slam_lcd.io.tf import TfBuffer
from slam_lcd.io.transforms import gtsam_cov_to_ros, ros_cov_to_gtsam
from slam_lcd.types import CameraModel
from slam_lcd.vision.gray import image_to_gray

RNG = np.random.default_rng(3)
GRAY = RNG.integers(0, 256, (5, 7), dtype=np.uint8)
RGB = RNG.integers(0, 256, (5, 7, 3), dtype=np.uint8)
RGBA = RNG.integers(0, 256, (5, 7, 4), dtype=np.uint8)
U16 = RNG.integers(0, 65536, (5, 7), dtype=np.uint16)
F32 = RNG.random((5, 7), dtype=np.float32)


def _raw(enc: str, payload: np.ndarray, pad: int = 0, big: bool = False):
    """An Image message assembled by hand (not with slam-lcd's builder)."""
    h, w = payload.shape[:2]
    arr = payload.astype(payload.dtype.newbyteorder(">" if big else "<"))
    rows = arr.reshape(h, -1).view(np.uint8).reshape(h, -1)
    step = rows.shape[1] + pad
    data = np.zeros((h, step), np.uint8)
    data[:, : rows.shape[1]] = rows
    return M.Image(header=M.header(5, "c"), height=h, width=w, encoding=enc, is_bigendian=int(big), step=step,
                   data=data.reshape(-1))


@pytest.mark.parametrize("pad", [0, 3])
@pytest.mark.parametrize(
    "enc,payload,expected",
    [
        ("mono8", GRAY, GRAY),
        ("8UC1", GRAY, GRAY),
        ("mono16", U16, U16),
        ("16UC1", U16, U16),
        ("32FC1", F32, F32),
        ("rgb8", RGB, RGB),
        ("bgr8", RGB[..., ::-1], RGB),
        ("rgba8", RGBA, RGBA[..., :3]),
        ("bgra8", RGBA[..., [2, 1, 0, 3]], RGBA[..., :3]),
    ],
)
def test_image_encodings(enc, payload, expected, pad):
    img = decode_image(_raw(enc, np.ascontiguousarray(payload), pad))
    assert img.dtype == expected.dtype and img.shape == expected.shape
    np.testing.assert_array_equal(img, expected)


@pytest.mark.parametrize("enc,payload", [("mono16", U16), ("32FC1", F32)])
def test_big_endian_images(enc, payload):
    np.testing.assert_array_equal(decode_image(_raw(enc, payload, big=True)), payload)


@pytest.mark.parametrize("img", [GRAY, RGB, RGBA, U16, F32], ids=["mono8", "rgb8", "rgba8", "mono16", "32FC1"])
def test_builder_round_trip(img):
    out = decode_image(M.image_msg(img, 1, "c"))
    np.testing.assert_array_equal(out, img if img.ndim == 2 or img.shape[2] == 3 else img[..., :3])


def test_compressed_images():
    big = cv2.resize(RGB, (64, 48), interpolation=cv2.INTER_NEAREST)
    png = decode_compressed_image(M.compressed_image_msg(big, 1, "c", "png"))
    np.testing.assert_array_equal(png, big)
    gray = cv2.resize(GRAY, (64, 48), interpolation=cv2.INTER_NEAREST)
    np.testing.assert_array_equal(decode_compressed_image(M.compressed_image_msg(gray, 1, "c", "png")), gray)
    smooth = np.tile(np.linspace(0, 255, 64, dtype=np.uint8), (48, 1))
    jpg = decode_compressed_image(M.compressed_image_msg(smooth, 1, "c", "jpeg"))
    assert jpg.shape == smooth.shape and np.abs(jpg.astype(int) - smooth).max() <= 4
    # image_transport's 'compressedDepth' 16UC1: 12-byte header then PNG
    depth = (RNG.random((48, 64)) * 5000).astype(np.uint16)
    ok, buf = cv2.imencode(".png", depth)
    msg = M.CompressedImage(header=M.header(1, "c"), format="16UC1; compressedDepth png",
                            data=np.concatenate([np.zeros(12, np.uint8), buf.reshape(-1)]))
    np.testing.assert_array_equal(decode_compressed_image(msg), depth)


def test_image_to_gray():
    np.testing.assert_array_equal(image_to_gray(RGB), cv2.cvtColor(RGB, cv2.COLOR_RGB2GRAY))
    assert image_to_gray(GRAY) is GRAY
    g = image_to_gray(F32)
    assert g.dtype == np.uint8 and g.min() == 0 and g.max() == 255


def test_camera_info_round_trip_with_stereo_baseline():
    cam = CameraModel(752, 480, 458.6, 457.3, 367.2, 248.4, "equidistant", np.array([-0.28, 0.07, 0.0002, 0.00002]),
                      baseline=0.11)
    got = decode_camera_info(M.camera_info_msg(cam, 1, "cam1"))
    assert (got.width, got.height, got.fx, got.fy, got.cx, got.cy) == (752, 480, 458.6, 457.3, 367.2, 248.4)
    assert got.distortion_model == "equidistant" and got.baseline == pytest.approx(0.11)
    np.testing.assert_array_equal(got.D, cam.D)


def test_covariance_convention_matches_perturbation_sampling():
    """A ROS covariance (parent axes) converted to GTSAM body-frame tangent order predicts the spread
    of T^-1 * T_perturbed, measured by sampling ROS-style perturbations."""
    R = Rotation.from_euler("xyz", [0.3, -0.2, 1.1]).as_matrix()
    A = RNG.normal(size=(6, 6)) * 0.01
    ros = A @ A.T  # [x y z rx ry rz] in parent axes
    samples = RNG.multivariate_normal(np.zeros(6), ros, size=2000)
    xi = np.empty_like(samples)
    for k, d in enumerate(samples):
        dR = Rotation.from_rotvec(d[3:]).as_matrix() @ R  # rotation perturbed about parent axes
        xi[k, :3] = Rotation.from_matrix(R.T @ dR).as_rotvec()
        xi[k, 3:] = R.T @ d[:3]  # translation perturbation seen in the body frame
    # the conversion is linear, so it must map the samples' covariance onto the tangents' exactly
    np.testing.assert_allclose(ros_cov_to_gtsam(np.cov(samples.T).reshape(-1), R), np.cov(xi.T), atol=1e-12)
    cov = ros_cov_to_gtsam(ros.reshape(-1), R)
    np.testing.assert_allclose(gtsam_cov_to_ros(cov, R).reshape(6, 6), ros, atol=1e-15)
    assert ros_cov_to_gtsam(np.zeros(36), R) is None


def test_decode_pose_kinds():
    T = np.eye(4)
    T[:3, :3] = Rotation.from_euler("z", 0.7).as_matrix()
    T[:3, 3] = [1, 2, 3]
    for msg in (
        M.pose_stamped_msg(T, 1, "m"),
        M.odometry_msg(T, None, 1, "o", "b"),
        M.pose_with_covariance_stamped_msg(T, np.eye(6), 1, "m"),
        M.transform_stamped_msg(T, 1, "a", "b"),
    ):
        got, _ = decode_pose(msg)
        np.testing.assert_allclose(got, T, atol=1e-12)


def test_tf_buffer_chain_and_interpolation():
    buf = TfBuffer()
    T_ab = np.eye(4)
    T_ab[:3, 3] = [0, 0, 1]  # static
    buf.add(M.tf_message([(T_ab, 0, "a", "b")]), static=True)
    for s, x, yaw in [(10, 0.0, 0.0), (20, 2.0, np.pi / 2)]:
        T = np.eye(4)
        T[:3, :3] = Rotation.from_euler("z", yaw).as_matrix()
        T[0, 3] = x
        buf.add(M.tf_message([(T, s, "b", "c")]))
    got = buf.lookup("a", "c", 15)
    np.testing.assert_allclose(got[:3, 3], [1.0, 0, 1.0], atol=1e-12)
    np.testing.assert_allclose(Rotation.from_matrix(got[:3, :3]).as_euler("xyz")[2], np.pi / 4, atol=1e-12)
    np.testing.assert_allclose(buf.lookup("c", "a", 15), np.linalg.inv(got), atol=1e-12)
    np.testing.assert_array_equal(buf.stamps("a", "c"), [10, 20])
