"""Configuration section `frontend` (owned by :mod:`slam_lcd.frontend`)."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Literal


@dataclass
class FrontendConfig:
    # --- keyframe selection (a new keyframe when ANY threshold is reached) ---
    kf_min_translation: float = 0.5  # metres travelled since the last keyframe
    kf_min_rotation_deg: float = 15.0  # degrees turned since the last keyframe
    kf_max_interval_s: float = 5.0  # seconds since the last keyframe (<= 0 disables)
    kf_min_interval_s: float = 0.0  # never two keyframes closer than this in time (rate cap)
    # image overlap: keyframe when fewer than this fraction of the last keyframe's features is matched
    # (<= 0 disables; ORB on adjacent demo frames gives ~0.35)
    kf_min_overlap: float = 0.15
    # bound for overlap matching (None: SuperPoint 0.9, ORB 64 bits)
    kf_overlap_max_descriptor_distance: float | None = None
    # --- odometry covariance (GTSAM order [rx ry rz tx ty tz], body frame) ---
    # meaning of the cov given to push(): pose covariance, covariance of the motion since the previous push,
    # or ignore it and use the motion model
    odom_covariance: Literal["absolute", "relative", "model"] = "absolute"
    # motion model: translation sigma per metre travelled (used when no covariance is given)
    odom_trans_sigma_per_m: float = 0.02
    odom_rot_sigma_per_rad: float = 0.02  # motion model: rotation sigma (rad) per radian turned
    odom_min_sigma_trans: float = 0.002  # floor on each translation sigma of a relative motion (m)
    odom_min_sigma_rot_deg: float = 0.05  # floor on each rotation sigma of a relative motion (deg)
    # --- camera mounting ---
    # 16 row-major numbers (or 7: x y z qx qy qz qw); None: from /tf_static, else identity
    T_body_camera: list[float] | None = None
    body_frame: str = "base_link"  # body frame name for the /tf_static lookup
    camera_frame: str | None = None  # camera frame name (None: the CameraInfo header frame_id)
    # --- visual odometry (used only when the log has no odometry) ---
    vo_features: Literal["orb", "superpoint"] = "orb"  # feature kind for tracking
    vo_max_features: int = 1000  # ORB features per frame
    vo_match_ratio: float = 0.85  # Lowe ratio for descriptor matching (frame to keyframe)
    vo_ransac_reprojection_px: float = 2.0  # PnP-RANSAC inlier threshold (pixels)
    vo_ransac_iterations: int = 200  # PnP-RANSAC iterations
    vo_min_inliers: int = 25  # fewer inliers than this: tracking lost
    vo_min_inlier_ratio: float = 0.2  # fewer inliers / matches than this: tracking lost
    vo_new_keyframe_inliers: int = 120  # switch tracking keyframe when inliers fall below this
    vo_new_keyframe_translation: float = 0.3  # ... or when the camera moved this far from it (m)
    vo_new_keyframe_rotation_deg: float = 10.0  # ... or turned this much (deg)
    vo_max_depth: float = 20.0  # ignore depths beyond this (m)
    vo_min_depth: float = 0.1  # ignore depths below this (m)
    vo_pixel_sigma: float = 1.0  # assumed keypoint noise (px) before inflation by residual RMS
    vo_depth_sigma_per_m2: float = 0.002  # RGB-D depth noise sigma = this * depth^2 (m), structured-light-like
    vo_disparity_sigma_px: float = 0.5  # stereo disparity noise (px)
    vo_lost_sigma_trans: float = 10.0  # translation sigma (m) of the large-noise link after tracking loss
    vo_lost_sigma_rot_deg: float = 90.0  # rotation sigma (deg) of the large-noise link after tracking loss
    stereo_max_row_diff_px: float = 1.5  # rectified stereo: match only within this many rows
    stereo_min_disparity_px: float = 1.0  # smallest usable disparity (px)
    stereo_max_disparity_px: float = 200.0  # largest disparity searched (px)
    # --- monocular landmarks from the odometry baseline ---
    tri_min_parallax_deg: float = 2.0  # triangulated points need at least this ray angle
    tri_max_reprojection_px: float = 2.0  # and reproject within this in every view used
    tri_max_neighbours: int = 2  # neighbour keyframes used per keyframe


def default_extractor(conf: FrontendConfig):
    """The tracking feature extractor named by ``conf.vo_features`` (slam_lcd.features)."""
    from ..features import FeaturesConfig, load_extractor

    if conf.vo_features == "orb":
        return load_extractor(FeaturesConfig(kind="orb", orb_n_features=conf.vo_max_features))
    return load_extractor(FeaturesConfig(kind="superpoint", max_keypoints=conf.vo_max_features))
