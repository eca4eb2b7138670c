"""Configuration section `frontend` (owned by :mod:`slam_lcd.frontend`)."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from ..value_range import ANY, ranged


@dataclass
class FrontendConfig:
    # --- keyframe selection (a new keyframe when ANY threshold is reached) ---
    kf_min_translation: float = ranged(0.5, "[0, inf)")  # metres travelled since the last keyframe
    kf_min_rotation_deg: float = ranged(15.0, "[0, 360]")  # degrees turned since the last keyframe
    kf_max_interval_s: float = ranged(5.0, ANY)  # seconds since the last keyframe (<= 0 disables)
    kf_min_interval_s: float = ranged(0.0, "[0, inf)")  # never two keyframes closer than this in time (rate cap)
    # image overlap: keyframe when fewer than this fraction of the last keyframe's features is matched
    # (<= 0 disables; ORB on adjacent demo frames gives ~0.35)
    kf_min_overlap: float = ranged(0.15, "(-inf, 1]")
    # bound for overlap matching (None: SuperPoint 0.9, ORB 64 bits)
    kf_overlap_max_descriptor_distance: float | None = ranged(None, "(0, 256]")
    # --- odometry covariance (GTSAM order [rx ry rz tx ty tz], body frame) ---
    # meaning of the cov given to push(): pose covariance, covariance of the motion since the previous push,
    # or ignore it and use the motion model
    odom_covariance: Literal["absolute", "relative", "model"] = "absolute"
    # motion model (used where the log gives no covariance): a random walk, variance growing linearly with
    # the distance travelled and the angle turned, whatever the odometry rate (docs/frontend.md, calibration);
    # the same figures as the map's per-metre allowance (map.pcm_sigma_*), so the loop gate and PCM agree
    odom_trans_sigma_per_sqrt_m: float = ranged(0.05, "[0, inf)")  # translation sigma (m) per sqrt(m) travelled
    odom_rot_sigma_per_sqrt_m: float = ranged(0.02, "[0, inf)")  # rotation sigma (rad) per sqrt(m) travelled
    odom_rot_sigma_per_sqrt_rad: float = ranged(0.05, "[0, inf)")  # rotation sigma (rad) per sqrt(rad) turned
    odom_min_sigma_trans: float = ranged(0.002, "(0, inf)")  # floor on each translation sigma of a relative motion (m)
    odom_min_sigma_rot_deg: float = ranged(0.05, "(0, inf)")  # floor on each rotation sigma of a relative motion (deg)
    # --- camera mounting ---
    # 16 row-major numbers (or 7: x y z qx qy qz qw); None: from /tf_static, else identity
    T_body_camera: list[float] | None = None
    body_frame: str = "base_link"  # body frame name for the /tf_static lookup
    camera_frame: str | None = None  # camera frame name (None: the CameraInfo header frame_id)
    # --- visual odometry (used only when the log has no odometry) ---
    vo_features: Literal["orb", "superpoint"] = "orb"  # feature kind for tracking
    vo_max_features: int = ranged(1000, "[1, inf)")  # ORB features per frame
    vo_orb_fast_threshold: int = ranged(20, "[0, 255]")  # ORB's FAST threshold for tracking
    # a frame with fewer corners than this fraction of vo_max_features is detected again with the fallback
    # FAST threshold (dim, low-contrast and small images)
    vo_orb_fallback_below: float = ranged(0.5, "[0, 1]")
    vo_orb_fallback_fast_threshold: int = ranged(7, "[0, 255]")
    vo_match_ratio: float = ranged(0.85, "(0, 1]")  # Lowe ratio for descriptor matching (frame to keyframe)
    vo_ransac_reprojection_px: float = ranged(2.0, "(0, inf)")  # PnP-RANSAC inlier threshold (pixels)
    vo_ransac_iterations: int = ranged(200, "[1, inf)")  # PnP-RANSAC iterations
    vo_min_inliers: int = ranged(25, "[4, inf)")  # fewer inliers than this: tracking lost
    vo_min_inlier_ratio: float = ranged(0.2, "[0, 1]")  # fewer inliers / matches than this: tracking lost
    vo_new_keyframe_inliers: int = ranged(120, "[0, inf)")  # switch tracking keyframe when inliers fall below this
    vo_new_keyframe_translation: float = ranged(0.3, "[0, inf)")  # ... or when the camera moved this far from it (m)
    vo_new_keyframe_rotation_deg: float = ranged(10.0, "[0, 360]")  # ... or turned this much (deg)
    vo_max_depth: float = ranged(20.0, "(0, inf)")  # ignore depths beyond this (m)
    vo_min_depth: float = ranged(0.1, "[0, inf)", below="vo_max_depth")  # ignore depths below this (m)
    vo_pixel_sigma: float = ranged(1.0, "(0, inf)")  # assumed keypoint noise (px) before inflation by residual RMS
    # RGB-D depth noise sigma = this * depth^2 (m), structured-light-like
    vo_depth_sigma_per_m2: float = ranged(0.002, "[0, inf)")
    vo_disparity_sigma_px: float = ranged(0.5, "(0, inf)")  # stereo disparity noise (px)
    # translation sigma (m) of the large-noise link after tracking loss
    vo_lost_sigma_trans: float = ranged(10.0, "(0, inf)")
    # rotation sigma (deg) of the large-noise link after tracking loss
    vo_lost_sigma_rot_deg: float = ranged(90.0, "(0, inf)")
    # relocalisation before a loss: the last tracking keyframes kept and tried again (0: off)
    vo_reloc_keyframes: int = ranged(5, "[0, inf)")
    vo_reloc_max_gap_s: float = ranged(1.0, "[0, inf)")  # ... only this long after the last tracked pose (s)
    # guided matching: search radius around a point's predicted projection, as a fraction of the image width
    vo_reloc_search_radius: float = ranged(0.06, "(0, 1]")
    # a relocalised pose farther than this from the constant-velocity prediction is rejected (m, deg)
    vo_reloc_gate_translation: float = ranged(0.3, "(0, inf)")
    vo_reloc_gate_rotation_deg: float = ranged(10.0, "(0, 180]")
    vo_reloc_min_inliers: int = ranged(12, "[4, inf)")  # inliers a relocalised pose needs (gated by the prior)
    stereo_max_row_diff_px: float = ranged(1.5, "[0, inf)")  # rectified stereo: match only within this many rows
    # smallest usable disparity (px)
    stereo_min_disparity_px: float = ranged(1.0, "(0, inf)", below="stereo_max_disparity_px")
    stereo_max_disparity_px: float = ranged(200.0, "(0, inf)")  # largest disparity searched (px)
    # --- monocular landmarks from the odometry baseline ---
    tri_min_parallax_deg: float = ranged(2.0, "[0, 180)")  # triangulated points need at least this ray angle
    tri_max_reprojection_px: float = ranged(2.0, "(0, inf)")  # and reproject within this in every view used
    tri_max_neighbours: int = ranged(2, "[0, inf)")  # neighbour keyframes used per keyframe


def default_extractor(conf: FrontendConfig):
    """The tracking feature extractor named by ``conf.vo_features`` (slam_lcd.features)."""
    from ..features import FeaturesConfig, load_extractor

    if conf.vo_features == "orb":
        from .tracking_orb import TrackingOrbExtractor

        return TrackingOrbExtractor(FeaturesConfig(kind="orb", orb_n_features=conf.vo_max_features,
                                                   orb_fast_threshold=conf.vo_orb_fast_threshold),
                                    conf.vo_orb_fallback_fast_threshold, conf.vo_orb_fallback_below)
    return load_extractor(FeaturesConfig(kind="superpoint", max_keypoints=conf.vo_max_features))
