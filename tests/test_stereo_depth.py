"""Stereo depth for the loop poses (slam_lcd.sensors.stereo_depth): a rendered pair, rectified and raw,
gives the depth the renderer drew, and only when it is read."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from slam_lcd.geometry import make_T
from slam_lcd.sensors.rectify import stereo_rectifier
from slam_lcd.sensors.stereo_depth import StereoDepth, StereoDepthMap, StereoFrames
from slam_lcd.sim import rig
from slam_lcd.sim.render import render
from slam_lcd.sim.trajectory import make_path, path_trajectory, START_NS
from slam_lcd.sim.world import build_world
from slam_lcd.types import CameraModel

W, H = 320, 240


@pytest.fixture(scope="module")
def view():
    world = build_world(0)
    path = make_path("laps", laps=1.0, seed=0)
    T_wb = path_trajectory(path, np.array([START_NS + 3_000_000_000], np.int64)).poses[0]
    return world, T_wb @ rig.T_body_camera()


def _rel_error(z, truth):
    ok = np.isfinite(z) & (truth > 0.3) & (truth < 8.0)
    return ok.mean(), np.median(np.abs(z[ok] - truth[ok]) / truth[ok])


def test_rectified_pair_gives_the_rendered_depth(view):
    world, T_wc = view
    cam = rig.demo_camera(W, H)
    left, truth = render(world, cam, T_wc)
    right, _ = render(world, cam, T_wc @ rig.T_left_right(), with_depth=False)
    z = np.asarray(StereoDepth(StereoDepthMap(cam, rig.STEREO_BASELINE), left, right))
    coverage, err = _rel_error(z, truth)
    assert coverage > 0.5 and err < 0.03, (coverage, err)


def test_raw_pair_gives_the_raw_cameras_depth(view):
    """Both cameras turned and distorted (as EuRoC's): rectified, matched, mapped back to raw cam0 pixels."""
    world, T_wc = view
    cam = rig.demo_camera(W, H)
    R0 = cv2.Rodrigues(np.radians([0.0, 2.0, 0.0]))[0]
    R1 = cv2.Rodrigues(np.radians([-1.5, 0.0, 0.0]))[0]
    D = np.array([-0.05, 0.01, 0.001, -0.0005])
    T_c0 = T_wc @ make_T(R0, np.zeros(3))  # raw cam0 in the world
    T_c1 = T_wc @ rig.T_left_right() @ make_T(R1, np.zeros(3))
    u, v = np.meshgrid(np.arange(W, dtype=np.float64), np.arange(H, dtype=np.float64))
    grid = np.stack([u.ravel(), v.ravel()], 1).reshape(-1, 1, 2)
    m = cv2.undistortPoints(grid, cam.K, D, P=cam.K).reshape(H, W, 2).astype(np.float32)
    raw = []
    for T in (T_c0, T_c1):
        img, dep = render(world, cam, T)
        raw.append((cv2.remap(img, m[..., 0], m[..., 1], cv2.INTER_LINEAR),
                    cv2.remap(dep, m[..., 0], m[..., 1], cv2.INTER_NEAREST)))
    raw_cam = CameraModel(width=W, height=H, fx=cam.fx, fy=cam.fy, cx=cam.cx, cy=cam.cy, D=list(D),
                          distortion_model="plumb_bob")
    T_c1_c0 = np.linalg.inv(T_c1) @ T_c0
    rect = stereo_rectifier(raw_cam, raw_cam, T_c1_c0)
    z = np.asarray(StereoDepth(StereoDepthMap(raw_cam, rectifier=rect), raw[0][0], raw[1][0]))
    coverage, err = _rel_error(z, raw[0][1])
    assert coverage > 0.4 and err < 0.03, (coverage, err)
    # without the rectifier the same pair is matched along the wrong rows: far worse
    z_bad = np.asarray(StereoDepth(StereoDepthMap(raw_cam, rig.STEREO_BASELINE), raw[0][0], raw[1][0]))
    assert _rel_error(z_bad, raw[0][1])[1] > 2 * err


def test_depth_is_computed_when_read_and_pairs_wait_for_their_partner(monkeypatch):
    cam = rig.demo_camera(64, 48)
    calls = []
    monkeypatch.setattr(StereoDepthMap, "depth", lambda self, l, r: calls.append(1) or np.ones((48, 64), np.float32))
    frames = StereoFrames("/right", camera=cam, baseline=0.1)
    img = np.zeros((48, 64), np.uint8)
    assert frames.add_left(100, img) == []  # waits for its right image
    (s, _, d), = frames.add_right(100, img)
    assert s == 100 and isinstance(d, StereoDepth) and not calls
    assert np.asarray(d).shape == (48, 64) and np.asarray(d).shape == (48, 64) and len(calls) == 1  # once
    assert frames.add_left(200, img) == []
    (s, _, d), = frames.add_right(300_000_000, img)  # a right image far later: the left one has no partner
    assert s == 200 and d is None and frames.unpaired == 1
    frames.add_left(300_000_000, img)
    assert frames.flush() == [] and frames.unpaired == 1
