"""The valid range of every numeric configuration key, checked with a one-line error.

Why a table here rather than in each stage's dataclass: the ranges are read together (by
:func:`slam_lcd.config.validate_config` and by the test that every numeric key has one),
and a stage can add a key without touching its neighbours' files. Notation: ``[a, b]``
closed, ``(a, b)`` open, ``inf`` unbounded; alternatives joined by ``or`` (``-1 or [1, inf)``).
``None`` is allowed exactly where the type says ``| None``. NaN is never in range, and
infinity only where a bound says ``inf]``. Pairs that must be ordered are in ``ORDERED``.
"""
from __future__ import annotations

import math

ANY = "(-inf, inf)"

RANGES: dict[str, str] = {
    # io
    "io.jpeg_quality": "[0, 100]",
    "io.tf_extrapolation_s": "[0, inf)",
    "io.rosbag1_chunk_cache_mb": "[1, inf)",
    # sensors
    "sensors.depth_unit_m": "(0, inf)",
    # frontend: keyframe selection
    "frontend.kf_min_translation": "[0, inf)",
    "frontend.kf_min_rotation_deg": "[0, 360]",
    "frontend.kf_max_interval_s": ANY,  # <= 0 disables
    "frontend.kf_min_interval_s": "[0, inf)",
    "frontend.kf_min_overlap": "(-inf, 1]",  # <= 0 disables
    "frontend.kf_overlap_max_descriptor_distance": "(0, 256]",
    # frontend: odometry covariance
    "frontend.odom_trans_sigma_per_m": "[0, inf)",
    "frontend.odom_rot_sigma_per_rad": "[0, inf)",
    "frontend.odom_min_sigma_trans": "(0, inf)",
    "frontend.odom_min_sigma_rot_deg": "(0, inf)",
    # frontend: visual odometry
    "frontend.vo_max_features": "[1, inf)",
    "frontend.vo_match_ratio": "(0, 1]",
    "frontend.vo_ransac_reprojection_px": "(0, inf)",
    "frontend.vo_ransac_iterations": "[1, inf)",
    "frontend.vo_min_inliers": "[4, inf)",
    "frontend.vo_min_inlier_ratio": "[0, 1]",
    "frontend.vo_new_keyframe_inliers": "[0, inf)",
    "frontend.vo_new_keyframe_translation": "[0, inf)",
    "frontend.vo_new_keyframe_rotation_deg": "[0, 360]",
    "frontend.vo_max_depth": "(0, inf)",
    "frontend.vo_min_depth": "[0, inf)",
    "frontend.vo_pixel_sigma": "(0, inf)",
    "frontend.vo_depth_sigma_per_m2": "[0, inf)",
    "frontend.vo_disparity_sigma_px": "(0, inf)",
    "frontend.vo_lost_sigma_trans": "(0, inf)",
    "frontend.vo_lost_sigma_rot_deg": "(0, inf)",
    "frontend.stereo_max_row_diff_px": "[0, inf)",
    "frontend.stereo_min_disparity_px": "(0, inf)",
    "frontend.stereo_max_disparity_px": "(0, inf)",
    "frontend.tri_min_parallax_deg": "[0, 180)",
    "frontend.tri_max_reprojection_px": "(0, inf)",
    "frontend.tri_max_neighbours": "[0, inf)",
    # features
    "features.nms_radius": "[0, inf)",
    "features.keypoint_threshold": "[0, 1)",
    "features.remove_borders": "[0, inf)",
    "features.max_keypoints": "-1 or [1, inf)",
    "features.resize_max": "[32, inf)",  # below that SuperPoint's 8-pixel cells and borders leave little image
    "features.batch_size": "[1, inf)",
    "features.orb_n_features": "[1, inf)",
    "features.orb_scale_factor": "(1, inf)",
    "features.orb_n_levels": "[1, inf)",
    "features.orb_fast_threshold": "[0, 255]",
    # vocab
    "vocab.match_ratio": "(0, 1]",
    "vocab.match_max_distance": "(0, 2]",  # on unit vectors
    "vocab.dp_pca_dims": "[0, inf)",
    "vocab.dp_block_size": "[2, inf)",
    "vocab.dp_truncation": "[1, inf)",
    "vocab.dp_concentration": "(0, inf)",
    "vocab.dp_max_iter": "[1, inf)",
    "vocab.dp_refine_iters": "[0, inf)",
    "vocab.max_branching": "[2, inf)",
    "vocab.hk_branching": "[2, inf)",
    "vocab.hk_depth": "[1, inf)",
    "vocab.seed": "[0, inf)",
    "vocab.min_previous_score": "[0, 1]",
    "vocab.online_word_radius": "(0, 2]",  # on unit vectors
    "vocab.ann_min_words": "[1, inf)",
    "vocab.ann_pca_dims": "[1, 4096]",
    "vocab.ann_hnsw_m": "[2, 256]",
    "vocab.ann_ef_search": "[1, inf)",
    "vocab.ann_ef_construction": "[1, inf)",
    "vocab.ann_candidates": "[1, inf)",
    "vocab.ann_fresh_images": "[0, inf)",
    "vocab.ann_hint_images": "[0, inf)",
    "vocab.ann_hint_max_distance": "(0, 2]",
    "vocab.ann_rebuild_growth": "0 or [1, inf)",  # 0: never
    # lcd
    "lcd.top_k": "[1, inf)",
    "lcd.island_gap": "[0, inf)",
    "lcd.island_pool": "[1, inf)",
    "lcd.island_tries": "[1, inf)",
    "lcd.verify_max_matches": "0 or [3, inf)",  # 0: no budget
    "lcd.verify_spread_cells": "[0, 64]",  # 0: globally best
    "lcd.min_bow_score": "[0, inf)",
    "lcd.exclude_recent_n": "[0, inf)",
    "lcd.exclude_recent_s": "[0, inf)",
    "lcd.match_ratio": "(0, 1]",
    "lcd.graph_match_ratio": "(0, 1]",
    "lcd.match_max_distance_sp": "(0, 2]",  # SuperPoint descriptors are unit vectors
    "lcd.match_max_distance_orb": "(0, 256]",  # Hamming distance of 256 bits
    "lcd.graph_min_matches": "[3, inf)",
    "lcd.graph_min_nodes": "[3, inf)",
    "lcd.graph_min_node_ratio": "[0, 1]",
    "lcd.graph_min_score": "[0, 1]",
    "lcd.graph_max_edge_factor": "(0, inf)",
    "lcd.graph_node_threshold": "[0, inf)",
    "lcd.graph_remove_fraction": "(0, 1]",
    "lcd.graph_max_iterations": "[0, inf)",
    "lcd.graph_min_separation_px": "[0, inf)",
    "lcd.graph_knn": "[0, inf)",
    "lcd.ransac_threshold_px": "(0, inf)",
    "lcd.ransac_confidence": "(0, 1)",
    "lcd.ransac_min_inliers": "[5, inf)",  # five-point essential matrix
    "lcd.ransac_min_inlier_ratio": "[0, 1]",
    "lcd.default_focal_factor": "(0, inf)",
    "lcd.pnp_threshold_px": "(0, inf)",
    "lcd.pnp_min_inliers": "[4, inf)",
    "lcd.pnp_max_rms_px": "(0, inf)",
    "lcd.pnp_min_inliers_tight": "0 or [6, inf)",  # 0: off
    "lcd.pnp_tight_min_share": "[0, 1]",
    "lcd.pnp_tight_max_sigma_m": "(0, inf)",
    "lcd.pnp_tight_max_sigma_deg": "(0, inf)",
    "lcd.odometry_max_drift": "[0, inf)",
    "lcd.odometry_max_drift_deg_per_m": "[0, inf)",
    "lcd.odometry_drift_floor_m": "[0, inf)",
    "lcd.odometry_drift_floor_deg": "[0, 180]",
    "lcd.min_depth_m": "[0, inf)",
    "lcd.max_depth_m": "(0, inf)",
    "lcd.pixel_sigma_px": "(0, inf)",
    "lcd.consistent_min_matches": "0 or [5, inf)",  # 0: off; five-point essential matrix
    "lcd.consistent_window": "[0, inf)",
    "lcd.temporal_k": "[0, inf)",
    "lcd.temporal_window": "[0, inf)",
    # backend
    "backend.prior_sigma_rot": "(0, inf)",
    "backend.prior_sigma_trans": "(0, inf)",
    "backend.odom_sigma_rot": "(0, inf)",
    "backend.odom_sigma_trans": "(0, inf)",
    "backend.loop_sigma_rot": "(0, inf)",
    "backend.loop_sigma_trans": "(0, inf)",
    "backend.loop_kernel_width": "(0, inf)",
    "backend.isam2_relinearize_threshold": "[0, inf)",
    "backend.isam2_relinearize_skip": "[1, inf)",
    "backend.isam2_extra_updates_per_loop": "[0, inf)",
    "backend.gate_chi2_probability": "(0, 1)",
    "backend.gate_pairwise_window": "[0, inf)",
    "backend.gate_min_support": "[0, inf)",
    "backend.gate_rescue_max_factor": "[1, inf)",
    "backend.gate_pairwise_max_inconsistent": "[0, 1]",
    "backend.gnc_every_n_loops": "[0, inf)",
    "backend.gnc_every_fraction": "[0, inf)",
    "backend.gnc_inlier_probability": "(0, 1)",
    "backend.gnc_max_iterations": "[1, inf)",
    "backend.gnc_outlier_weight": "[0, 1]",
    # eval
    "eval.t_max_diff": "[0, inf)",
    "eval.t_offset": ANY,
    "eval.n_to_align": "[3, inf)",  # Umeyama needs three points
    "eval.rpe_delta": "(0, inf)",
    # run
    "run.loop_true_max_distance": "(0, inf)",
    "run.extract_ahead": "[0, 64]",
    "run.lcd_threads": "[0, 64]",
    "run.extract_workers": "[0, 64]",
    "run.read_ahead": "[0, 4096]",
    # batch
    "batch.cpus_per_task": "(0, inf)",
    "batch.gpus_per_task": "[0, inf)",
    "batch.max_retries": "[0, inf)",
    # map (multi-session)
    "map.min_join_loops": "[1, inf)",
    "map.pcm_probability": "(0, 1)",
    "map.pcm_sigma_trans_per_m": "[0, inf)",
    "map.pcm_sigma_rot_per_m": "[0, inf)",
    "map.pcm_clique_budget": "[1, inf)",
    "map.min_join_span_m": "[0, inf)",
    "map.join_ambiguity_ratio": "(0, inf)",
    "map.link_probability": "(0, 1)",
    "map.localize_max_disagreement_m": "(0, inf)",
    "map.localize_max_disagreement_deg": "(0, 180]",
    "map.localize_min_place_separation_m": "[0, inf)",
    "map.localize_min_group_ratio": "[1, inf)",
    "map.lock_timeout_s": "[0, inf)",
    "map.place_radius_m": "(0, inf)",
    "map.place_angle_deg": "(0, 180]",
    "map.place_compare": "[1, inf)",
    "map.redundant_match_ratio": "(0, 1]",
    "map.appearance_share": "[0, 1]",
    "map.max_variants": "[1, inf)",
    "run.loop_pictures_rejected": "[0, inf)",
    # map_cloud (the map as a point cloud)
    "map_cloud.voxel_m": "[0.001, inf)",
    "map_cloud.min_depth_m": "[0, inf)",
    "map_cloud.max_depth_m": "(0, inf)",
    "map_cloud.pixel_step": "[1, 64]",
    "map_cloud.min_keyframes_per_voxel": "[1, 1000]",
    "map_cloud.stereo_match_step": "[1, 16]",
    "map_cloud.stereo_max_jump_px": "[0, inf)",
    "map_cloud.queue_keyframes": "[0, 256]",
    "map_cloud.metric_radius_m": "(0, inf)",
    "map_cloud.metric_points": "[1, inf)",
    "map_cloud.metric_min_neighbours": "[4, inf)",
    "map_cloud.metric_min_std_voxels": "[0, 10]",
    "map_cloud.top_view_px": "[100, 8000]",
}

# (smaller, larger): the first must be below the second
ORDERED = [
    ("frontend.vo_min_depth", "frontend.vo_max_depth"),
    ("frontend.stereo_min_disparity_px", "frontend.stereo_max_disparity_px"),
    ("lcd.min_depth_m", "lcd.max_depth_m"),
    ("map_cloud.min_depth_m", "map_cloud.max_depth_m"),
]


def _alternatives(spec: str):
    out = []
    for part in spec.split(" or "):
        part = part.strip()
        if part[0] in "[(":
            lo, hi = (float(x) for x in part[1:-1].split(","))
            out.append((lo, hi, part[0] == "[", part[-1] == "]"))
        else:
            v = float(part)
            out.append((v, v, True, True))
    return out


def in_range(value, spec: str) -> bool:
    v = float(value)
    if math.isnan(v):
        return False
    for lo, hi, lo_in, hi_in in _alternatives(spec):
        if (v > lo or (lo_in and v == lo)) and (v < hi or (hi_in and v == hi)):
            return True
    return False


def describe(spec: str) -> str:
    return " or ".join(("in " + p.strip()) if p.strip()[0] in "[(" else p.strip() for p in spec.split(" or "))
