"""Visual odometry relocalisation (guided matching from a constant-velocity prior, the kept
keyframes, the gate) and the depth-discontinuity test the RGB-D points pass."""
from __future__ import annotations

import dataclasses

import numpy as np

import slam_lcd.frontend.vo as vo_module
from slam_lcd.frontend import FrontendConfig, RgbdOdometry, points_from_depth
from slam_lcd.frontend.reloc import MotionPrior, within_gate
from slam_lcd.geometry import inv, make_T, se3_exp
from slam_lcd.sim.kinect import KINECT_V1, depth_mm
from slam_lcd.types import CameraModel, Features

K_BAD = 30  # the frame tracked against a keyframe it cannot match


def _run_with_unmatchable_keyframe(demo, conf: FrontendConfig, n_after: int = 3) -> RgbdOdometry:
    """Frames up to ``K_BAD - 1`` as recorded; then the tracking keyframe's descriptors are those of
    a frame 2.5 s further on (a keyframe the next frames cannot match, as one taken through a glitch
    would be); then ``n_after`` frames from ``K_BAD``."""
    gt, cam, T_bc, frames = demo
    vo = RgbdOdometry(cam, conf, T_bc)
    for k in range(K_BAD):
        vo.process(int(gt.stamps[k]), frames[k][0], frames[k][1])
    assert vo.ref is not None
    other = vo.extractor.extract(frames[K_BAD + 25][0])
    n = min(len(other), len(vo.ref.features))
    feats = dataclasses.replace(vo.ref.features, descriptors=other.descriptors[:n], keypoints=other.keypoints[:n],
                                scores=other.scores[:n])
    vo.ref = dataclasses.replace(vo.ref, features=feats, points=vo.ref.points[:n], point_cov=vo.ref.point_cov[:n])
    for k in range(K_BAD, K_BAD + n_after):
        vo.process(int(gt.stamps[k]), frames[k][0], frames[k][1])
    return vo


def _motion_error(vo: RgbdOdometry, gt, k: int) -> float:
    """Translation error (m) of the VO's motion from the last frame before ``K_BAD`` to frame ``k``."""
    i = K_BAD - 1
    est = inv(vo.frames[i].T_world_body) @ vo.frames[k].T_world_body
    ref = inv(gt.poses[i]) @ gt.poses[k]
    return float(np.linalg.norm((inv(ref) @ est)[:3, 3]))


def test_relocalises_against_an_earlier_keyframe(demo):
    gt = demo[0]
    vo = _run_with_unmatchable_keyframe(demo, FrontendConfig())
    f = vo.frames[K_BAD]
    assert f.status == "relocalised", (f.status, f.reason)
    # found through one of the kept keyframes, not the (unmatchable) tracking keyframe
    used = int(f.reason.rsplit(" ", 1)[1])
    assert used < int(gt.stamps[K_BAD - 1]) and used in {kf.stamp for kf in vo.ring}
    assert _motion_error(vo, gt, K_BAD) < 0.04  # the chain through an older keyframe: a few cm
    res = vo.result()
    assert res.n_segments == 1 and res.n_lost == 0
    assert [g.status for g in vo.frames[K_BAD + 1:]] in (["tracked", "tracked"], ["tracked", "keyframe"],
                                                          ["keyframe", "tracked"], ["keyframe", "keyframe"])
    assert _motion_error(vo, gt, K_BAD + 2) < 0.08

    # without relocalisation the same frames are a tracking loss and a new segment
    plain = _run_with_unmatchable_keyframe(demo, FrontendConfig(vo_reloc_keyframes=0))
    assert [g.status for g in plain.frames[K_BAD:K_BAD + 2]] == ["lost", "segment-start"]
    assert plain.result().n_segments == 2


def test_gate_rejects_a_pnp_pose_far_from_the_prediction(demo, monkeypatch):
    """A relocalisation PnP that lands 0.5 m off the constant-velocity prediction is refused: the
    frame is lost (and the next one, refused the same way, starts a new segment)."""
    true_solve = vo_module.solve_pnp

    def displaced(*args, **kwargs):
        res = true_solve(*args, **kwargs)
        if kwargs["min_inliers"] < FrontendConfig().vo_min_inliers:  # only relocalisation asks for fewer
            res = dataclasses.replace(res, T_ref_cur=res.T_ref_cur @ make_T(np.eye(3), np.array([0.5, 0.0, 0.0])))
        return res

    monkeypatch.setattr(vo_module, "solve_pnp", displaced)
    vo = _run_with_unmatchable_keyframe(demo, FrontendConfig(), n_after=2)
    assert [g.status for g in vo.frames[K_BAD:]] == ["lost", "segment-start"]
    # a gate wide enough for the displacement lets the same wrong pose through
    wide = _run_with_unmatchable_keyframe(demo, FrontendConfig(vo_reloc_gate_translation=1.0), n_after=1)
    assert wide.frames[K_BAD].status == "relocalised" and _motion_error(wide, demo[0], K_BAD) > 0.4


def test_motion_prior_extrapolates_constant_velocity():
    mp = MotionPrior()
    assert mp.predict(0) is None
    step = se3_exp(np.array([0.0, 0.02, 0.0, 0.1, 0.0, 0.3]))
    T0 = make_T(np.eye(3), np.array([1.0, 2.0, 3.0]))
    mp.add(1_000_000_000, T0)
    assert np.allclose(mp.predict(1_100_000_000), T0)  # one pose: no velocity yet
    mp.add(1_100_000_000, T0 @ step)
    assert np.allclose(mp.predict(1_300_000_000), T0 @ step @ step @ step, atol=1e-9)
    assert mp.seconds_since_last(1_600_000_000) == 0.5
    assert within_gate(T0, T0 @ se3_exp(np.array([0, 0, 0.05, 0.2, 0, 0])), 0.3, 10.0)
    assert not within_gate(T0, T0 @ se3_exp(np.array([0, 0, 0, 0.4, 0, 0])), 0.3, 10.0)
    assert not within_gate(T0, T0 @ se3_exp(np.array([0, 0, np.radians(15), 0, 0, 0])), 0.3, 10.0)


def _wall_depth(width: int, height: int, seed: int = 0):
    """Camera (90 deg field of view) looking along a corridor; its left wall (x = -1 m) measured by
    the Kinect v1 model (noise, disparity steps, 0.5-4.5 m), beyond it nothing; uint16 mm."""
    f = width / 2.0
    cam = CameraModel(width=width, height=height, fx=f, fy=f, cx=width / 2.0, cy=height / 2.0)
    x = (np.arange(width) - cam.cx) / f
    z = np.where(x < -0.2, -1.0 / np.minimum(x, -1e-9), np.inf)  # the wall: z * x = -1
    z = np.repeat(z[None, :], height, axis=0)
    return cam, depth_mm(KINECT_V1.measure(z, np.random.default_rng(seed)))


def _features(uv: np.ndarray, width: int, height: int) -> Features:
    n = len(uv)
    return Features(uv.astype(np.float32), np.ones(n, np.float32), np.zeros((n, 32), np.uint8), (width, height), "orb")


def test_depth_on_a_slanted_wall_is_kept_at_every_resolution():
    """The left wall of a corridor, seen at a grazing angle, is one plane: keypoints on it keep their
    depth at 320x240 as at 640x480 (a 3x3 spread test in metres dropped most of them at 320x240,
    where a pixel spans twice the angle), and the points lie on the wall."""
    for width, height in ((320, 240), (640, 480)):
        cam, depth = _wall_depth(width, height)
        d = depth.astype(np.float64) * 1e-3
        v, u = np.mgrid[10:height - 10:7, 2:width // 2 - 2:3]
        uv = np.column_stack([u.ravel(), v.ravel()]).astype(np.float64)
        readable = np.all([d[np.clip(uv[:, 1].astype(int) + dy, 0, height - 1),
                             np.clip(uv[:, 0].astype(int) + dx, 0, width - 1)] > 0
                           for dy in (-1, 0, 1) for dx in (-1, 0, 1)], axis=0)
        assert readable.sum() > 200
        pts, _ = points_from_depth(cam, _features(uv[readable], width, height), depth)
        kept = np.isfinite(pts[:, 0])
        assert kept.mean() > 0.95, (width, kept.mean())
        assert np.all(np.abs(pts[kept, 0] + 1.0) < 0.1 * pts[kept, 2])  # on the wall x = -1 m (depth noise)


def test_depth_step_is_still_a_discontinuity():
    """Keypoints beside a depth step (2 m in front of 3 m) get no depth; those two pixels away do."""
    w, h = 320, 240
    cam = CameraModel(width=w, height=h, fx=160.0, fy=160.0, cx=160.0, cy=120.0)
    z = np.full((h, w), 3.0)
    z[:, :150] = 2.0
    depth = depth_mm(z)
    uv = np.array([[149.0, 100.0], [149.0, 120.0], [150.0, 60.0], [150.0, 80.0], [147.0, 100.0], [152.0, 100.0]])
    pts, _ = points_from_depth(cam, _features(uv, w, h), depth)
    assert np.isnan(pts[:4, 0]).all() and np.isfinite(pts[4:, 0]).all()
    assert np.allclose(pts[4:, 2], [2.0, 3.0])
