"""Keyframe selection from odometry and image overlap.

A frame becomes a keyframe when the body moved or turned enough since the last keyframe,
when too much time passed, or when too few of the last keyframe's features are still
tracked in it (the image content changed). Between keyframes the odometry covariance is
accumulated in GTSAM's Pose3 convention, so each keyframe carries the covariance of the
motion since the previous keyframe: exactly what a between factor needs. Where the log gives
no covariance the motion model stands in for it, and the keyframe says so
(``Keyframe.covariance_source``): the map's PCM then uses its own per-metre allowance.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError, UnsortedStampsError
from ..geometry import compose_covariance, inv, relative_covariance, rotation_angle
from ..types import CameraModel, Features, Keyframe, Trajectory
from .config import FrontendConfig
from .matching import DEFAULT_MAX_DISTANCE, geometric_inliers, match_descriptors


@dataclass
class _Pending:
    """The most recent pushed frame (kept so it can be promoted on a segment break)."""

    stamp: int
    T: np.ndarray
    cov_since_kf: np.ndarray
    image: np.ndarray | None
    features: Features | None
    depth: np.ndarray | None
    right_image: np.ndarray | None
    is_keyframe: bool
    colour: np.ndarray | None = None
    source: str = "given"  # of cov_since_kf: "given" by the log or "model"


def motion_model_covariance(distance: float, angle: float, conf: FrontendConfig) -> np.ndarray:
    """Covariance of a motion between keyframes when the odometry gives none (GTSAM order, no floor).

    A random walk: the variance grows linearly with the ``distance`` travelled (m) and the
    ``angle`` turned (rad), so a step's covariance does not depend on how many odometry samples
    make it up (a sigma proportional to each sample's length, composed, would shrink as the rate
    rises). The map's per-metre allowance (:func:`slam_lcd.map.pcm.step_covariances`) is the same
    formula with the same default figures.
    """
    v_r = conf.odom_rot_sigma_per_sqrt_m ** 2 * distance + conf.odom_rot_sigma_per_sqrt_rad ** 2 * abs(angle)
    v_t = conf.odom_trans_sigma_per_sqrt_m ** 2 * distance
    return np.diag([v_r] * 3 + [v_t] * 3)


def covariance_floor(conf: FrontendConfig) -> np.ndarray:
    r = np.radians(conf.odom_min_sigma_rot_deg)
    return np.array([r * r] * 3 + [conf.odom_min_sigma_trans**2] * 3)


def _usable(cov) -> np.ndarray | None:
    if cov is None:
        return None
    c = np.asarray(cov, dtype=np.float64).reshape(6, 6)
    if not np.all(np.isfinite(c)) or np.trace(c) <= 0.0:
        return None  # many drivers publish all-zero covariances: treat as "not given"
    return c


class KeyframeSelector:
    """Feed it every odometry sample (and, optionally, the frame's image/features).

    ``push`` returns the keyframes that frame made (none, itself, or on an odometry break
    also the frame before it); the keyframes are in ``self.keyframes``
    (``slam_lcd.types.Keyframe``), each with
    ``covariance_since_last`` (6x6, GTSAM ``[rx ry rz tx ty tz]``, body frame of the keyframe),
    and ``self.reasons[i]`` says why keyframe i was taken.

    ``cov`` passed to ``push`` is read according to ``conf.odom_covariance``: ``absolute``
    (the pose's covariance, growing with time, GTSAM order: the motion covariance is the
    difference to the last keyframe's), ``relative`` (covariance of the motion since the
    previous push) or ``model`` (ignored; the motion model is used). Missing or all-zero
    covariances fall back to the motion model; each keyframe's ``covariance_source`` says which
    (``"given"`` or ``"model"``).

    ``keep_images=False`` (a consumer such as the pipeline takes the keyframes ``push``
    returns): ``self.keyframes`` holds light copies (stamp, pose, covariance, and the newest
    one's features, all the overlap test needs), so images do not pile up here.
    """

    def __init__(self, conf: FrontendConfig | None = None, camera: CameraModel | None = None,
                 T_body_camera: np.ndarray | None = None, *, keep_images: bool = True):
        self.conf = conf or FrontendConfig()
        self.camera = camera
        self.T_body_camera = np.eye(4) if T_body_camera is None else np.asarray(T_body_camera, np.float64)
        self.keyframes: list[Keyframe] = []
        self.keep_images = keep_images
        self.reasons: list[str] = []
        self._last: _Pending | None = None
        self._kf_abs_cov: np.ndarray | None = None  # absolute covariance at the last keyframe (absolute mode)
        self._model_since_kf = np.zeros((6, 6))  # relative mode: the given covariances composed since the keyframe
        self._path_since_kf = 0.0  # metres travelled since the last keyframe (sum over the samples)
        self._all_given = True  # relative mode: every sample since the last keyframe gave a covariance
        self.last_overlap: float | None = None

    # ------------------------------------------------------------------ helpers
    @property
    def last_keyframe(self) -> Keyframe | None:
        return self.keyframes[-1] if self.keyframes else None

    def overlap(self, features: Features | None) -> float | None:
        """Fraction of the last keyframe's features matched (geometrically consistent) in ``features``."""
        kf = self.last_keyframe
        if kf is None or kf.features is None or features is None or len(kf.features) == 0:
            return None
        if len(features) == 0:
            return 0.0
        dmax = self.conf.kf_overlap_max_descriptor_distance
        if dmax is None:
            dmax = DEFAULT_MAX_DISTANCE["uint8" if features.descriptors.dtype == np.uint8 else "float"]
        m = match_descriptors(kf.features.descriptors, features.descriptors, ratio=0.9, max_distance=dmax)
        if len(m) >= 12:
            ok = geometric_inliers(kf.features.keypoints[m[:, 0]], features.keypoints[m[:, 1]], 3.0)
            n = int(ok.sum())
        else:
            n = len(m)
        return n / len(kf.features)

    def _make_keyframe(self, p: _Pending, cov_since: np.ndarray | None, reason: str) -> Keyframe:
        kf = Keyframe(id=len(self.keyframes), stamp=int(p.stamp), T_world_body=p.T.copy(), image=p.image,
                      camera=self.camera, T_body_camera=self.T_body_camera.copy(), depth=p.depth,
                      right_image=p.right_image, covariance_since_last=cov_since, features=p.features,
                      colour=p.colour, segment_start=reason == "segment-break", covariance_source=p.source)
        if self.keep_images:
            self.keyframes.append(kf)
        else:  # only the newest keyframe is compared with: older ones need no features
            if self.keyframes:
                self.keyframes[-1].features = None
            self.keyframes.append(Keyframe(id=kf.id, stamp=kf.stamp, T_world_body=kf.T_world_body, features=kf.features,
                                           covariance_since_last=kf.covariance_since_last,
                                           segment_start=kf.segment_start,
                                           covariance_source=kf.covariance_source))
        self.reasons.append(reason)
        p.is_keyframe = True
        return kf

    # ------------------------------------------------------------------ main entry
    def push(self, stamp_ns: int, T_world_body: np.ndarray, cov: np.ndarray | None = None,
             image: np.ndarray | None = None, features: Features | None = None, *,
             depth: np.ndarray | None = None, right_image: np.ndarray | None = None,
             segment_start: bool = False, segment_cov: np.ndarray | None = None,
             colour: np.ndarray | None = None) -> list[Keyframe]:
        """Offer one frame; the keyframes it made (empty when it made none).

        ``segment_start=True`` marks a break in the odometry (visual tracking lost): the
        previous frame is promoted to a keyframe if it was not one, and this frame becomes a
        keyframe whose ``covariance_since_last`` is ``segment_cov`` (a large-noise link)
        instead of the accumulated odometry covariance. ``colour``: the frame's colour image,
        carried to the keyframe for the map cloud only.
        """
        conf = self.conf
        stamp_ns = int(stamp_ns)
        T = np.asarray(T_world_body, dtype=np.float64).reshape(4, 4)
        if not np.all(np.isfinite(T)):
            raise InputError(f"pose at stamp {stamp_ns} has non-finite values")
        given = None if conf.odom_covariance == "model" else _usable(cov)
        floor = covariance_floor(conf)

        prev = self._last
        if prev is None:
            p = _Pending(stamp_ns, T, np.zeros((6, 6)), image, features, depth, right_image, False, colour)
            self._last = p
            self._kf_abs_cov = given if conf.odom_covariance == "absolute" else None
            made = [self._make_keyframe(p, None, "first")]
            self._restart()
            return made
        if stamp_ns < prev.stamp:
            raise UnsortedStampsError(f"stamp {stamp_ns} is earlier than the previous one ({prev.stamp})")

        kf = self.last_keyframe
        assert kf is not None  # the first pose (prev is None above) made one
        T_prev_cur = inv(prev.T) @ T
        T_kf_cur = inv(kf.T_world_body) @ T
        # --- covariance of the motion since the last keyframe: as the log gave it, else the motion model
        self._path_since_kf += float(np.linalg.norm(T_prev_cur[:3, 3]))
        if conf.odom_covariance == "relative":
            self._all_given &= given is not None
            if given is not None:
                self._model_since_kf = compose_covariance(self._model_since_kf, T_prev_cur, given)
        if conf.odom_covariance == "absolute" and given is not None and self._kf_abs_cov is not None:
            cov_since, source = relative_covariance(kf.T_world_body, self._kf_abs_cov, T, given, floor), "given"
        elif conf.odom_covariance == "relative" and self._all_given:
            cov_since, source = self._model_since_kf + np.diag(floor), "given"
        else:
            model = motion_model_covariance(self._path_since_kf, rotation_angle(T_kf_cur[:3, :3]), conf)
            cov_since, source = model + np.diag(floor), "model"

        cur = _Pending(stamp_ns, T, cov_since, image, features, depth, right_image, False, colour, source)

        if segment_start:
            made = [self._make_keyframe(prev, prev.cov_since_kf, "before-break")] if not prev.is_keyframe else []
            if segment_cov is None:
                s_t, s_r = conf.vo_lost_sigma_trans, np.radians(conf.vo_lost_sigma_rot_deg)
                segment_cov = np.diag([s_r**2] * 3 + [s_t**2] * 3)
            self._last = cur
            cur.source = "given"  # the break's link is meant as it is (the back end reads none: a new segment)
            made.append(self._make_keyframe(cur, np.asarray(segment_cov, np.float64), "segment-break"))
            self._kf_abs_cov = given if conf.odom_covariance == "absolute" else None
            self._restart()
            return made

        self._last = cur
        dt = (stamp_ns - kf.stamp) * 1e-9
        if dt < conf.kf_min_interval_s:
            return []
        reason = None
        if np.linalg.norm(T_kf_cur[:3, 3]) >= conf.kf_min_translation:
            reason = "translation"
        elif np.degrees(rotation_angle(T_kf_cur[:3, :3])) >= conf.kf_min_rotation_deg:
            reason = "rotation"
        elif conf.kf_max_interval_s > 0 and dt >= conf.kf_max_interval_s:
            reason = "time"
        elif conf.kf_min_overlap > 0 and features is not None:
            ov = self.overlap(features)
            self.last_overlap = ov
            if ov is not None and ov < conf.kf_min_overlap:
                reason = "overlap"
        if reason is None:
            return []
        made = [self._make_keyframe(cur, cov_since, reason)]
        self._kf_abs_cov = given if conf.odom_covariance == "absolute" else None
        self._restart()
        return made

    def _restart(self) -> None:
        """A keyframe was made: the motion since the last keyframe starts again."""
        self._model_since_kf = np.zeros((6, 6))
        self._path_since_kf = 0.0
        self._all_given = True


def select_keyframes(trajectory: Trajectory, conf: FrontendConfig | None = None,
                     segment_starts=None) -> list[int]:
    """Indices of ``trajectory`` that become keyframes (odometry thresholds only).

    ``trajectory.covariances`` (if present) are read per ``conf.odom_covariance``;
    ``segment_starts`` (indices or a boolean array) marks odometry breaks.
    """
    sel = KeyframeSelector(conf)
    flags = list(keyframes_from_trajectory_iter(trajectory, sel, segment_starts))
    idx = {i for i, f in enumerate(flags) if f}
    # frames promoted on a segment break are found by their stamp (they precede the break)
    stamps = trajectory.stamps
    for kf in sel.keyframes:
        j = int(np.searchsorted(stamps, kf.stamp, side="right")) - 1
        idx.add(j)
    return sorted(idx)


def keyframes_from_trajectory(trajectory: Trajectory, conf: FrontendConfig | None = None,
                              segment_starts=None, camera: CameraModel | None = None,
                              T_body_camera: np.ndarray | None = None) -> list[Keyframe]:
    """Keyframes (without images) selected from an odometry trajectory."""
    sel = KeyframeSelector(conf, camera=camera, T_body_camera=T_body_camera)
    for _ in keyframes_from_trajectory_iter(trajectory, sel, segment_starts):
        pass
    return sel.keyframes


def keyframes_from_trajectory_iter(trajectory: Trajectory, sel: KeyframeSelector, segment_starts=None):
    n = len(trajectory)
    starts = np.zeros(n, bool)
    if segment_starts is not None:
        s = np.asarray(segment_starts)
        if s.dtype == bool:
            starts[: len(s)] = s[:n]
        else:
            starts[s.astype(int)] = True
    covs = trajectory.covariances
    for i in range(n):
        cov = None if covs is None else covs[i]
        yield sel.push(int(trajectory.stamps[i]), trajectory.poses[i], cov, segment_start=bool(starts[i] and i > 0))
