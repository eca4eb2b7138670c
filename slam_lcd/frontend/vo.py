"""Built-in visual odometry for logs without an odometry topic (RGB-D or rectified stereo).

Frame-to-keyframe tracking: each frame's features are matched to the current tracking
keyframe, whose features carry 3-D points (from the depth image or from stereo
disparity); PnP-RANSAC plus a motion-only refinement give the pose and its covariance
(:mod:`slam_lcd.vision.pnp`). The tracking keyframe is replaced when the overlap
drops or the camera has moved enough, so drift only grows keyframe to keyframe.

Before a frame is declared lost it is relocalised (:mod:`slam_lcd.frontend.reloc`): a
constant-velocity prediction from the last two tracked poses guides matching against the
current tracking keyframe and then against the last ``vo_reloc_keyframes`` ones, and a PnP
pose outside the gate around the prediction is rejected; a success is ``relocalised`` and
the segment goes on.

Tracking loss is explicit. A frame that can be neither tracked nor relocalised is reported
``lost`` and gets no pose. The next frame is tried again the same way (``recovered``, the
same segment); if that fails too, a new segment starts at the last good pose, its covariance
starting again from zero (the segment's own frame), and the frame is flagged
``segment_start`` so the keyframe selector and the back end see the break: the pose graph
anchors the segment on its own and only loops join it to the others
(:mod:`slam_lcd.backend.segments`). The trajectory never jumps silently.
"""
from __future__ import annotations

import logging
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError
from ..geometry import compose_covariance, inv, rotation_angle, transform_covariance
from ..types import CameraModel, Features, Trajectory
from ..vision.camera import undistort_points
from ..vision.gray import to_gray_uint8
from ..vision.pnp import solve_pnp
from .config import FrontendConfig, default_extractor
from .depth_points import points_from_depth, points_from_stereo
from .matching import match_descriptors
from .reloc import MotionPrior, guided_matches, within_gate

log = logging.getLogger(__name__)


@dataclass
class VoFrame:
    """What VO says about one input frame."""

    stamp: int
    status: str  # 'init' | 'tracked' | 'keyframe' | 'recovered' | 'relocalised' | 'segment-start' | 'lost'
    segment: int
    T_world_body: np.ndarray | None = None
    covariance: np.ndarray | None = None  # absolute (growing) pose covariance, GTSAM order, body frame
    n_matches: int = 0
    n_inliers: int = 0
    rms_px: float = float("nan")
    reason: str = ""

    @property
    def has_pose(self) -> bool:
        return self.T_world_body is not None

    @property
    def segment_start(self) -> bool:
        return self.status == "segment-start"


@dataclass
class VoResult:
    frames: list[VoFrame] = field(default_factory=list)

    def trajectory(self) -> Trajectory:
        """Frames with a pose: ``T_world_body`` with absolute covariances (GTSAM order)."""
        fr = [f for f in self.frames if f.has_pose]
        return Trajectory(stamps=np.array([f.stamp for f in fr], np.int64),
                          poses=np.array([f.T_world_body for f in fr]).reshape(-1, 4, 4),
                          covariances=np.array([f.covariance for f in fr]).reshape(-1, 6, 6),
                          frame_id="vo_world", child_frame_id="body")

    @property
    def segment_starts(self) -> np.ndarray:
        """Boolean per trajectory pose: True where a new segment starts after tracking loss."""
        return np.array([f.segment_start for f in self.frames if f.has_pose], bool)

    @property
    def n_lost(self) -> int:
        return sum(f.status == "lost" for f in self.frames)

    @property
    def n_segments(self) -> int:
        return 1 + sum(f.segment_start for f in self.frames)


@dataclass
class _TrackingKeyframe:
    features: Features
    points: np.ndarray  # (N,3) camera frame, NaN where unknown
    point_cov: np.ndarray  # (N,3,3)
    T_world_cam: np.ndarray
    covariance: np.ndarray  # absolute, body frame
    stamp: int


class _FrameToKeyframeOdometry:
    """Shared tracking logic; subclasses say how a frame's keypoints get 3-D points."""

    def __init__(self, camera: CameraModel, conf: FrontendConfig | None = None,
                 T_body_camera: np.ndarray | None = None, extractor=None):
        self.camera = camera
        self.conf = conf or FrontendConfig()
        self.T_bc = np.eye(4) if T_body_camera is None else np.asarray(T_body_camera, np.float64)
        self.T_cb = inv(self.T_bc)
        self.extractor = extractor if extractor is not None else default_extractor(self.conf)
        self.K = camera.K
        self.ref: _TrackingKeyframe | None = None
        self.segment = 0
        self.lost = False
        self.last_T_world_cam: np.ndarray | None = None
        self.last_cov: np.ndarray | None = None
        self.T_ref_cur_last = np.eye(4)
        self.frames: list[VoFrame] = []
        self.ring: deque[_TrackingKeyframe] = deque(maxlen=max(self.conf.vo_reloc_keyframes, 1))
        self.motion = MotionPrior()

    # -- subclasses ---------------------------------------------------------
    def _points(self, feats: Features, image, aux) -> tuple[np.ndarray, np.ndarray]:
        raise NotImplementedError

    # -- helpers ------------------------------------------------------------
    def _body(self, T_world_cam: np.ndarray) -> np.ndarray:
        return T_world_cam @ self.T_cb

    def _make_ref(self, feats, image, aux, T_world_cam, cov, stamp) -> int:
        pts, pcov = self._points(feats, image, aux)
        if self.ref is not None:
            self.ring.append(self.ref)
        self.ref = _TrackingKeyframe(feats, pts, pcov, T_world_cam, cov, stamp)
        self.T_ref_cur_last = np.eye(4)
        return int(np.isfinite(pts[:, 0]).sum())

    def _track(self, feats: Features, uv_all: np.ndarray, ref: _TrackingKeyframe,
               T_ref_cur_guess: np.ndarray | None = None):
        """PnP of ``feats`` (undistorted keypoints ``uv_all``) against ``ref``: ``(PnpResult | None,
        n_matches)``; with ``T_ref_cur_guess``, matching is guided by that pose."""
        c = self.conf
        # a pose the motion prior confirms (the gate) needs fewer inliers
        min_inliers = c.vo_min_inliers if T_ref_cur_guess is None else min(c.vo_min_inliers, c.vo_reloc_min_inliers)
        valid = np.flatnonzero(np.isfinite(ref.points[:, 0]))
        if len(valid) < min_inliers or len(feats) < min_inliers:
            return None, 0
        if T_ref_cur_guess is None:
            m = match_descriptors(ref.features.descriptors[valid], feats.descriptors, ratio=c.vo_match_ratio)
        else:
            m = guided_matches(ref.points[valid], ref.features.descriptors[valid], T_ref_cur_guess, self.K, uv_all,
                               feats.descriptors, c.vo_reloc_search_radius * self.camera.width)
        if len(m) < min_inliers:
            return None, len(m)
        i_ref = valid[m[:, 0]]
        uv = uv_all[m[:, 1]]
        res = solve_pnp(ref.points[i_ref], ref.point_cov[i_ref], uv, self.K,
                        reprojection_px=self.conf.vo_ransac_reprojection_px,
                        iterations=self.conf.vo_ransac_iterations, min_inliers=min_inliers,
                        pixel_sigma=self.conf.vo_pixel_sigma)
        if not res.ok or len(res.inliers) < self.conf.vo_min_inlier_ratio * len(m):
            return None, len(m)
        return res, len(m)

    def _relocalise(self, feats: Features, uv_all: np.ndarray, stamp_ns: int):
        """``(keyframe, PnpResult, n_matches)`` of a pose found by guided matching against the tracking
        keyframe, then the kept ones (newest first), within the motion prior's gate; or None."""
        c = self.conf
        T_pred = self.motion.predict(stamp_ns)
        if (c.vo_reloc_keyframes == 0 or T_pred is None or self.ref is None
                or self.motion.seconds_since_last(stamp_ns) > c.vo_reloc_max_gap_s):
            return None
        for kf in [self.ref, *reversed(self.ring)]:
            res, n_matches = self._track(feats, uv_all, kf, inv(kf.T_world_cam) @ T_pred)
            if res is not None and within_gate(T_pred, kf.T_world_cam @ res.T_ref_cur, c.vo_reloc_gate_translation,
                                               c.vo_reloc_gate_rotation_deg):
                return kf, res, n_matches
        return None

    # -- main entry ---------------------------------------------------------
    def process(self, stamp_ns: int, image: np.ndarray, aux=None, features: Features | None = None) -> VoFrame:
        """Track one frame (``aux``: depth image for RGB-D, right image for stereo)."""
        conf = self.conf
        stamp_ns = int(stamp_ns)
        gray = to_gray_uint8(image)
        feats = features if features is not None else self.extractor.extract(gray)
        uv_all = undistort_points(self.camera, feats.keypoints)

        if self.ref is None:  # very first frame: the world frame is the first body frame
            T_wc = self.T_bc.copy()
            cov = np.zeros((6, 6))
            n3d = self._make_ref(feats, gray, aux, T_wc, cov, stamp_ns)
            if n3d < conf.vo_min_inliers:
                self.ref = None
                return self._emit(VoFrame(stamp_ns, "lost", self.segment, reason=f"only {n3d} features with depth"))
            self.last_T_world_cam, self.last_cov = T_wc, cov
            self.motion.add(stamp_ns, T_wc)
            return self._emit(VoFrame(stamp_ns, "init", self.segment, self._body(T_wc), cov, len(feats), n3d))

        ref = self.ref
        res, n_matches = self._track(feats, uv_all, ref)
        relocalised = False
        if res is None:
            found = self._relocalise(feats, uv_all, stamp_ns)
            if found is not None:
                ref, res, n_matches = found
                relocalised = True
        if res is None:
            if not self.lost:
                self.lost = True
                return self._emit(VoFrame(stamp_ns, "lost", self.segment, n_matches=n_matches,
                                          reason="tracking failed"))
            # second failure in a row: start a new segment here (if this frame has 3-D structure)
            assert self.last_T_world_cam is not None and self.last_cov is not None  # set with the first reference
            T_wc = self.last_T_world_cam
            cov = np.zeros((6, 6))  # the new segment's own frame (the pose graph anchors it on its own)
            n3d = self._make_ref(feats, gray, aux, T_wc, cov, stamp_ns)
            if n3d < conf.vo_min_inliers:
                return self._emit(VoFrame(stamp_ns, "lost", self.segment, n_matches=n_matches,
                                          reason=f"tracking failed; only {n3d} features with depth"))
            self.lost = False
            self.segment += 1
            self.last_cov = cov
            self.ring.clear()  # the kept keyframes and the motion prior belong to the segment that ended
            self.motion.reset()
            self.motion.add(stamp_ns, T_wc)
            log.warning("visual odometry lost tracking; new segment %d at stamp %d", self.segment, stamp_ns)
            return self._emit(VoFrame(stamp_ns, "segment-start", self.segment, self._body(T_wc), cov,
                                      n_matches, n3d, reason="tracking lost: new segment, large-noise link"))

        recovered = self.lost
        self.lost = False
        T_ref_cur = res.T_ref_cur
        T_wc = ref.T_world_cam @ T_ref_cur
        T_refb_curb = self.T_bc @ T_ref_cur @ self.T_cb
        cov_rel = transform_covariance(res.covariance, self.T_bc)
        cov = compose_covariance(ref.covariance, T_refb_curb, cov_rel)
        self.last_T_world_cam, self.last_cov = T_wc, cov
        self.motion.add(stamp_ns, T_wc)
        self.T_ref_cur_last = T_ref_cur
        status = "relocalised" if relocalised else "recovered" if recovered else "tracked"
        n_in = len(res.inliers)
        if (relocalised or n_in < conf.vo_new_keyframe_inliers
                or np.linalg.norm(T_ref_cur[:3, 3]) > conf.vo_new_keyframe_translation
                or np.degrees(rotation_angle(T_ref_cur[:3, :3])) > conf.vo_new_keyframe_rotation_deg):
            n3d = self._make_ref(feats, gray, aux, T_wc, cov, stamp_ns)
            if n3d >= conf.vo_min_inliers:
                status = "keyframe" if status == "tracked" else status
            else:  # keep the reference tracked against: this frame has too little structure
                self.ring.pop()
                self.ref = ref
        reason = f"relocalised against the tracking keyframe at stamp {ref.stamp}" if relocalised else ""
        return self._emit(VoFrame(stamp_ns, status, self.segment, self._body(T_wc), cov, n_matches, n_in, res.rms_px,
                                  reason))

    def _emit(self, f: VoFrame) -> VoFrame:
        self.frames.append(f)
        return f

    def result(self) -> VoResult:
        return VoResult(list(self.frames))


class RgbdOdometry(_FrameToKeyframeOdometry):
    """VO from an intensity image and a registered metric depth image (float metres or uint16 mm)."""

    def process(self, stamp_ns: int, image: np.ndarray, depth: np.ndarray | None = None,
                features: Features | None = None) -> VoFrame:
        if depth is None:
            raise InputError("RGB-D odometry needs a depth image for every frame")
        return super().process(stamp_ns, image, depth, features)

    def _points(self, feats: Features, image, depth) -> tuple[np.ndarray, np.ndarray]:
        return points_from_depth(self.camera, feats, depth, self.conf)


class StereoOdometry(_FrameToKeyframeOdometry):
    """VO from a rectified stereo pair (left image drives tracking; right gives disparity).

    ``baseline`` defaults to ``camera.baseline`` (from the right CameraInfo's projection).
    """

    def __init__(self, camera: CameraModel, conf: FrontendConfig | None = None,
                 T_body_camera: np.ndarray | None = None, extractor=None, baseline: float | None = None):
        super().__init__(camera, conf, T_body_camera, extractor)
        baseline = baseline if baseline is not None else camera.baseline
        if not baseline or baseline <= 0:
            raise InputError("stereo odometry needs a positive baseline (camera.baseline or baseline=...)")
        self.baseline: float = baseline

    def process(self, stamp_ns: int, image: np.ndarray, right: np.ndarray | None = None,
                features: Features | None = None) -> VoFrame:
        if right is None:
            raise InputError("stereo odometry needs the right image for every frame")
        return super().process(stamp_ns, image, right, features)

    def _points(self, feats: Features, left, right) -> tuple[np.ndarray, np.ndarray]:
        return points_from_stereo(self.camera, self.baseline, feats, left, to_gray_uint8(right), self.extractor,
                                  self.conf)


def run_rgbd_odometry(camera, frames, conf=None, T_body_camera=None, extractor=None) -> VoResult:
    """``frames``: iterable of ``(stamp_ns, image, depth)``."""
    vo = RgbdOdometry(camera, conf, T_body_camera, extractor)
    for stamp, img, depth in frames:
        vo.process(stamp, img, depth)
    return vo.result()


def run_stereo_odometry(camera, frames, conf=None, T_body_camera=None, extractor=None,
                        baseline=None) -> VoResult:
    """``frames``: iterable of ``(stamp_ns, left, right)``."""
    vo = StereoOdometry(camera, conf, T_body_camera, extractor, baseline)
    for stamp, left, right in frames:
        vo.process(stamp, left, right)
    return vo.result()
