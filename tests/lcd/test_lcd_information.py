"""Loop information model (lcd/information.py): NEES ~ chi2(6) when the noise is what the model says."""
from __future__ import annotations

import numpy as np
import pytest

from slam_lcd.geometry import inv, se3_exp, se3_log
from slam_lcd.lcd.config import LcdConfig
from slam_lcd.lcd.information import InformationModel, coverage, loop_information
from slam_lcd.types import CameraModel
from slam_lcd.vision.pnp import refine_pose_reprojection

CAM = CameraModel(640, 480, 457.0, 457.0, 319.5, 239.5)
STEREO = CameraModel(640, 480, 457.0, 457.0, 319.5, 239.5, baseline=0.12)
MODEL = InformationModel()


def _sigma_z(z, source):
    if source == "stereo":
        return np.maximum(z**2 * MODEL.disparity_sigma_px / (STEREO.fx * STEREO.baseline), MODEL.depth_floor_m)
    return np.maximum(MODEL.depth_rel * z, MODEL.depth_floor_m)


def _trial(rng, n=150, sigma_kp=0.7, box=(1.0, 1.0), source="rgbd"):
    """A PnP loop with the model's noise: match points with depth + keypoint noise, noisy query
    observations. Returns (true T_cm_cq, refined T_cm_cq, inlier points, inlier observations)."""
    T_true = se3_exp(np.r_[rng.normal(0, 0.05, 3), rng.normal(0, 0.3, 3)])
    u, v = rng.uniform(0, box[0], n) * CAM.width, rng.uniform(0, box[1], n) * CAM.height
    z = rng.uniform(1.5, 6.0, n)
    X = np.c_[(u - CAM.cx) / CAM.fx * z, (v - CAM.cy) / CAM.fy * z, z]  # true points, match camera
    um, vm = u + rng.normal(0, sigma_kp, n), v + rng.normal(0, sigma_kp, n)
    zm = z + rng.normal(0, 1, n) * _sigma_z(z, source)
    Xm = np.c_[(um - CAM.cx) / CAM.fx * zm, (vm - CAM.cy) / CAM.fy * zm, zm]
    T_qm = inv(T_true)
    P = X @ T_qm[:3, :3].T + T_qm[:3, 3]
    xq = P[:, :2] / P[:, 2:3] + rng.normal(0, sigma_kp / CAM.fx, (n, 2))
    T0 = T_true @ se3_exp(rng.normal(0, 1e-3, 6))
    T, _, _, keep = refine_pose_reprojection(T0, Xm, xq, CAM.fx, np.arange(n), 10.0, LcdConfig().pixel_sigma_px)
    return T_true, T, Xm[keep], xq[keep]


def _nees(trial, model=MODEL, source="rgbd"):
    T_true, T, Xm, xq = trial
    cam = STEREO if source == "stereo" else CAM
    info = loop_information(T, Xm, xq, CAM.fx, source, cam, cam, model=model, min_pixel_sigma=0.1)
    e = se3_log(inv(T_true) @ T)
    return float(e @ info @ e)


@pytest.mark.parametrize("source", ["rgbd", "stereo"])
def test_nees_follows_chi2_when_the_noise_matches_the_model(source):
    rng = np.random.default_rng(0)
    trials = [_trial(rng, source=source) for _ in range(300)]
    ne = np.array([_nees(t, source=source) for t in trials])
    # chi2(6) scaled by the few-inlier inflation 1 / (1 + 10 / 150): median 5.0, mean 5.6
    print(f"\nsynthetic NEES median {np.median(ne):.2f}, mean {ne.mean():.2f}, > 16.81: {np.mean(ne > 16.81):.1%}")
    # stereo: depth noise of 0.1-0.3 m at 4-6 m is far from linear in the reprojection; a tail remains
    assert 4.0 <= np.median(ne) <= 6.5
    assert 4.6 <= ne.mean() <= (7.0 if source == "rgbd" else 9.0)
    assert np.mean(ne > 16.81) <= (0.02 if source == "rgbd" else 0.05)


def test_few_and_clustered_inliers_inflate_the_covariance():
    rng = np.random.default_rng(2)
    state = rng.bit_generator.state
    spread = _trial(rng, n=150, box=(1.0, 1.0))
    rng.bit_generator.state = state
    cluster = _trial(rng, n=150, box=(0.2, 0.2))

    def cov_trace(t):
        _, T, Xm, xq = t
        return np.trace(np.linalg.inv(loop_information(T, Xm, xq, CAM.fx, "rgbd", CAM, CAM)))

    assert cov_trace(cluster) > 2.5 * cov_trace(spread)  # inflation 2.5 on top of the weaker geometry
    few = _trial(np.random.default_rng(3), n=20)
    _, T, Xm, xq = few
    i_few = loop_information(T, Xm, xq, CAM.fx, "rgbd", CAM, CAM)
    i_raw = loop_information(T, Xm, xq, CAM.fx, "rgbd", CAM, CAM, model=InformationModel(few_inliers_ref=0.0))
    assert np.allclose(i_few * (1 + 10.0 / len(Xm)), i_raw)
    xn = np.c_[rng.uniform(-0.7, 0.7, 500), rng.uniform(-0.52, 0.52, 500)]
    assert coverage(xn, CAM) > 0.9 and coverage(0.2 * xn, CAM) < 0.05
