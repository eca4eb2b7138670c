"""Two-view geometry on 20 real TUM fr2/desk frames against motion-capture ground truth."""
from __future__ import annotations

import numpy as np
import pytest

from slam_lcd.frontend import two_view_geometry
from slam_lcd.geometry import inv, rotation_angle, se3_exp, se3_log
from slam_lcd.types import CameraModel
from slam_lcd.vision.camera import undistort_points

TUM_FR2 = CameraModel(640, 480, 520.9, 521.0, 325.1, 249.7, "plumb_bob",
                      np.array([0.2312, -0.7849, -0.0033, -0.0001, 0.9172]))
STRIDE = 5  # frame i against frame i+5 (0.5 s apart, 8-16 cm baseline)


def _interpolate(stamps, poses, query):
    """Ground truth at image stamps: geodesic interpolation between the bracketing samples."""
    out = []
    for s in query:
        k = int(np.searchsorted(stamps, s))
        a, b = k - 1, k
        while stamps[b] == stamps[a]:
            b += 1
        w = (s - stamps[a]) / (stamps[b] - stamps[a])
        out.append(poses[a] @ se3_exp(w * se3_log(inv(poses[a]) @ poses[b])))
    return np.array(out)


@pytest.fixture(scope="module")
def tum(shared_data):
    import cv2

    from slam_lcd.features import FeaturesConfig, load_extractor
    from slam_lcd.io.trajectory_files import read_tum

    files = sorted((shared_data / "frames" / "tum_fr2_desk").glob("*.png"))
    assert len(files) == 20
    stamps = np.array([int(round(float(f.stem) * 1e9)) for f in files], np.int64)
    gt = read_tum(shared_data / "trajectories" / "fr2_desk_groundtruth.txt")
    T_world_cam = _interpolate(gt.stamps, gt.poses, stamps)
    images = [cv2.imread(str(f), cv2.IMREAD_GRAYSCALE) for f in files]
    ex = load_extractor(FeaturesConfig(kind="orb", orb_n_features=2000))
    feats = [ex.extract(im) for im in images]
    return images, feats, T_world_cam


def test_relative_rotations_within_one_degree(tum):
    images, feats, T_wc = tum
    errors = []
    for i in range(len(images) - STRIDE):
        j = i + STRIDE
        res = two_view_geometry(TUM_FR2, feats[i], feats[j], images=(images[i], images[j]))
        assert res.ok and res.well_conditioned, (i, j, res.reason, res.parallax_deg)
        T_gt = inv(T_wc[j]) @ T_wc[i]  # camera i -> camera j, like res.R
        errors.append(np.degrees(rotation_angle(res.R.T @ T_gt[:3, :3])))
        # translation direction agrees too (baselines are 8-16 cm here)
        cosang = res.t @ T_gt[:3, 3] / np.linalg.norm(T_gt[:3, 3])
        assert cosang > np.cos(np.radians(15.0)), (i, j, np.degrees(np.arccos(cosang)))
    errors = np.array(errors)
    print("two-view rotation errors (deg):", np.round(errors, 3), "max", errors.max(), "mean", errors.mean())
    assert errors.max() < 1.0


def test_distortion_matters_on_real_frames(tum):
    """Ignoring the fr2 distortion makes the estimate worse: the undistortion is really used."""
    images, feats, T_wc = tum
    plain = CameraModel(640, 480, 520.9, 521.0, 325.1, 249.7)
    e_dist, e_plain = [], []
    for i in (0, 5, 10):
        j = i + STRIDE
        T_gt = inv(T_wc[j]) @ T_wc[i]
        for cam, acc in ((TUM_FR2, e_dist), (plain, e_plain)):
            r = two_view_geometry(cam, feats[i], feats[j], images=(images[i], images[j]))
            acc.append(np.degrees(rotation_angle(r.R.T @ T_gt[:3, :3])))
    assert np.mean(e_dist) < np.mean(e_plain)


def test_undistort_round_trip():
    from slam_lcd.vision.camera import distort_points

    pts = np.array([[0.0, 0.0], [639.0, 479.0], [320.0, 240.0], [15.0, 400.0]])
    n = undistort_points(TUM_FR2, pts, normalized=True)
    assert np.abs(distort_points(TUM_FR2, n) - pts).max() < 1e-6
    fish = CameraModel(640, 480, 300, 300, 320, 240, "equidistant", np.array([0.1, -0.05, 0.01, 0.002]))
    n = undistort_points(fish, pts, normalized=True)
    assert np.abs(distort_points(fish, n) - pts).max() < 1e-6
    # pixels of the ideal pinhole: the centre stays, corners move outwards for barrel distortion
    u = undistort_points(TUM_FR2, pts)
    assert np.allclose(u[2], [320, 240], atol=1.0)
