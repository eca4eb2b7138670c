"""Built-in visual odometry on the rendered demo world (RGB-D and stereo), tracking loss,
and monocular landmarks from the odometry baseline."""
from __future__ import annotations

import numpy as np
import pytest

from slam_lcd.frontend import FrontendConfig, KeyframeSelector, RgbdOdometry, StereoOdometry, triangulate_landmarks
from slam_lcd.geometry import inv
from slam_lcd.types import Keyframe

W, H = 320, 240


def _ate(est, ref):
    pe, pr = est[:, :3, 3], ref[:, :3, 3]
    me, mr = pe.mean(0), pr.mean(0)
    U, _, Vt = np.linalg.svd((pr - mr).T @ (pe - me))
    S = np.diag([1, 1, np.sign(np.linalg.det(U @ Vt))])
    R = U @ S @ Vt
    e = (pe - me) @ R.T + mr - pr
    return float(np.sqrt(np.mean(np.sum(e * e, 1))))


@pytest.mark.parametrize("mode", ["rgbd", "stereo"])
def test_vo_accuracy_on_demo_world(demo, mode):
    gt, cam, T_bc, frames = demo
    vo = RgbdOdometry(cam, FrontendConfig(), T_bc) if mode == "rgbd" else StereoOdometry(cam, FrontendConfig(), T_bc)
    for s, (img, depth, right) in zip(gt.stamps, frames, strict=True):
        vo.process(int(s), img, depth if mode == "rgbd" else right)
    res = vo.result()
    traj = res.trajectory()
    assert len(traj) == len(gt) and res.n_lost == 0 and res.n_segments == 1
    ate = _ate(traj.poses, gt.poses)
    L = gt.path_length()
    assert ate < 0.03 * L, (ate, L)
    # VO's world frame is the first body frame: relative motion over the run matches GT within 3%
    d_est = (inv(traj.poses[0]) @ traj.poses[-1])[:3, 3]
    d_gt = (inv(gt.poses[0]) @ gt.poses[-1])[:3, 3]
    assert np.linalg.norm(d_est - d_gt) < 0.03 * L
    # covariances grow along the run and are positive definite
    c = traj.covariances
    assert np.all(np.linalg.eigvalsh(c[-1]) > 0)
    assert np.trace(c[-1][3:, 3:]) > np.trace(c[10][3:, 3:]) > 0
    # and are not absurdly over- or under-confident: end error within 5 sigma, sigma < 10x error + 5 cm
    sig = np.sqrt(np.trace(c[-1][3:, 3:]))
    err = np.linalg.norm(d_est - d_gt)
    assert err < 5 * sig + 0.01 and sig < 10 * err + 0.05, (err, sig)


def test_vo_from_log_matches_direct_run(demo_log, demo):
    """visual_odometry_from_log reads camera, mounting and frames itself and gives the same poses."""
    from slam_lcd.sensors.log_vo import visual_odometry_from_log

    gt, cam, T_bc, frames = demo
    out = visual_odometry_from_log(demo_log, depth_topic="/camera/depth", max_frames=20)
    assert out.mode == "rgbd" and np.allclose(out.T_body_camera, T_bc)
    vo = RgbdOdometry(cam, FrontendConfig(), T_bc)
    for s, (img, depth, _) in list(zip(gt.stamps, frames, strict=True))[:20]:
        vo.process(int(s), img, depth)
    a, b = out.result.trajectory(), vo.result().trajectory()
    assert len(a) == 20 and np.allclose(a.poses, b.poses)


def test_blank_frames_start_a_new_segment_without_a_jump(demo):
    gt, cam, T_bc, frames = demo
    blank = set(range(25, 40))  # 1.5 s of black frames (camera covered)
    vo = RgbdOdometry(cam, FrontendConfig(), T_bc)
    sel = KeyframeSelector(FrontendConfig(kf_min_translation=1.0), cam, T_bc)
    statuses = []
    for k, (s, (img, depth, _)) in enumerate(zip(gt.stamps, frames, strict=True)):
        if k in blank:
            img = np.zeros_like(img)
        f = vo.process(int(s), img, depth)
        statuses.append(f.status)
        if f.has_pose:
            sel.push(f.stamp, f.T_world_body, f.covariance, img, segment_start=f.segment_start)
    assert all(statuses[k] == "lost" for k in blank)
    res = vo.result()
    assert res.n_segments == 2
    k0 = statuses.index("segment-start")
    assert k0 == max(blank) + 1  # first usable frame after the gap
    before = vo.frames[min(blank) - 1]
    after = vo.frames[k0]
    # no silent jump: the new segment starts where the old one ended ...
    assert np.allclose(after.T_world_body, before.T_world_body)
    # ... its uncertainty starting again in its own frame, and the keyframe selector opens a segment there
    # (the pose graph anchors it on its own: slam_lcd.backend.segments)
    assert np.allclose(after.covariance, 0.0)
    assert "segment-break" in sel.reasons
    kf = sel.keyframes[sel.reasons.index("segment-break")]
    assert kf.segment_start and sum(k.segment_start for k in sel.keyframes) == 1
    # and tracking continues afterwards
    assert statuses[-1] in ("tracked", "keyframe")


def test_short_gap_recovers_in_the_same_segment(demo):
    gt, cam, T_bc, frames = demo
    vo = RgbdOdometry(cam, FrontendConfig(), T_bc)
    for k, (s, (img, depth, _)) in enumerate(zip(gt.stamps[:40], frames[:40], strict=True)):
        vo.process(int(s), np.zeros_like(img) if k == 20 else img, depth)
    res = vo.result()
    assert res.frames[20].status == "lost" and res.frames[21].status == "recovered"
    assert res.n_segments == 1


def test_monocular_landmarks_from_odometry_baseline(demo):
    """Triangulated points agree with the rendered depth (used only as the check)."""
    from slam_lcd.features import FeaturesConfig, load_extractor

    gt, cam, T_bc, frames = demo
    ex = load_extractor(FeaturesConfig(kind="orb", orb_n_features=1000))

    def kf(i):
        return Keyframe(id=i, stamp=int(gt.stamps[i]), T_world_body=gt.poses[i], image=frames[i][0], camera=cam,
                        T_body_camera=T_bc, features=ex.extract(frames[i][0]))

    k, nbs = kf(20), [kf(10), kf(30)]
    L = triangulate_landmarks(k, nbs)
    assert L.shape == (len(k.features), 3) and k.landmarks is L
    ok = np.isfinite(L[:, 0])
    assert ok.sum() >= 30, ok.sum()
    u = np.round(k.features.keypoints[ok]).astype(int)
    # keypoints sit on corners, often on a depth edge: compare with the closest depth in a 5x5 window
    D = frames[20][1]
    win = np.stack([D[np.clip(u[:, 1] + dy, 0, H - 1), np.clip(u[:, 0] + dx, 0, W - 1)]
                    for dy in range(-2, 3) for dx in range(-2, 3)], axis=1)
    k_best = np.argmin(np.abs(win - L[ok, 2:3]), axis=1)
    z_true = win[np.arange(len(win)), k_best]
    rel = np.abs(L[ok, 2] - z_true) / z_true
    print("landmarks", ok.sum(), "median rel depth error", np.median(rel))
    assert np.median(rel) < 0.04, np.median(rel)
    assert np.mean(rel < 0.15) > 0.8
    # without a baseline (same pose) nothing can be triangulated
    same = kf(20)
    assert np.isnan(triangulate_landmarks(k, [same])).all()


def test_keyframes_from_image_overlap(demo):
    """With the odometry thresholds out of the way, keyframes come from the tracked-feature fraction."""
    from slam_lcd.features import FeaturesConfig, load_extractor

    gt, cam, T_bc, frames = demo
    ex = load_extractor(FeaturesConfig(kind="orb", orb_n_features=800))
    feats = [ex.extract(f[0]) for f in frames]
    counts = {}
    for thr in (0.1, 0.2):
        conf = FrontendConfig(kf_min_translation=1e9, kf_min_rotation_deg=1e9, kf_max_interval_s=0, kf_min_overlap=thr)
        sel = KeyframeSelector(conf, cam, T_bc)
        for s, T, f in zip(gt.stamps, gt.poses, feats, strict=True):
            was = sel.push(int(s), T, None, None, f)
            if len(sel.keyframes) > 1:
                # the decision agrees with the overlap measured against the keyframe before it
                assert bool(was) == (sel.last_overlap < thr)
        assert set(sel.reasons[1:]) <= {"overlap"}
        counts[thr] = len(sel.keyframes)
    assert 2 <= counts[0.1] < counts[0.2] < len(frames) // 2, counts


def test_landmarks_from_depth_and_stereo_agree(demo):
    """RGB-D and stereo keyframes get their landmarks from their own sensor; both agree."""
    from slam_lcd.features import FeaturesConfig, load_extractor
    from slam_lcd.frontend import landmarks_from_sensor

    gt, cam, T_bc, frames = demo
    ex = load_extractor(FeaturesConfig(kind="orb", orb_n_features=1000))
    img, depth, right = frames[5]
    f = ex.extract(img)
    k_rgbd = Keyframe(id=0, stamp=int(gt.stamps[5]), T_world_body=gt.poses[5], image=img, camera=cam,
                      T_body_camera=T_bc, depth=depth, features=f)
    k_st = Keyframe(id=0, stamp=int(gt.stamps[5]), T_world_body=gt.poses[5], image=img, camera=cam,
                    T_body_camera=T_bc, right_image=right, features=f)
    a = landmarks_from_sensor(k_rgbd)
    b = landmarks_from_sensor(k_st, extractor=ex)
    both = np.isfinite(a[:, 0]) & np.isfinite(b[:, 0])
    assert np.isfinite(a[:, 0]).sum() > 0.5 * len(f) and both.sum() > 0.2 * len(f)
    # compare in disparity (what stereo measures): f b / z
    fb = cam.fx * cam.baseline
    err_px = np.abs(fb / a[both, 2] - fb / b[both, 2])
    assert np.median(err_px) < 0.3 and np.mean(err_px < 1.0) > 0.85, (np.median(err_px), np.mean(err_px < 1.0))
