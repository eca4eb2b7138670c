"""Configuration section `lcd` (owned by :mod:`slam_lcd.lcd`)."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from ..value_range import ranged


@dataclass
class LcdConfig:
    # --- candidate retrieval (Bag of Words) ---
    top_k: int = ranged(5, "[1, inf)")  # BoW candidates verified per query keyframe
    min_bow_score: float = ranged(0.0, "[0, inf)")  # candidates scoring below this are not verified at all
    exclude_recent_n: int = ranged(20, "[0, inf)")  # skip the last N keyframes (they look alike without being loops)
    exclude_recent_s: float = ranged(0.0, "[0, inf)")  # skip keyframes newer than this many seconds before the query
    verify: Literal["none", "ransac", "graph", "graph+ransac"] = "graph+ransac"  # verification chain
    pose: bool = True  # estimate a metric T_match_query for accepted loops (needs camera + depth/stereo/landmarks)
    require_pose: bool = True  # reject a verified loop when no metric pose can be estimated (when pose=True)
    # islands (DBoW2 / iBoW-LCD): the top-K and their temporal neighbours among the best
    # ``island_pool`` BoW candidates, grouped by keyframe position (members <= ``island_gap`` apart),
    # ranked by the sum of their members' scores and verified island by island: the best member,
    # then the next best when it fails, at most ``island_tries`` per island (docs/lcd_pose.md)
    islands: bool = False
    island_gap: int = ranged(2, "[0, inf)")  # keyframe positions between neighbouring members of one island
    # BoW candidates grouped into islands (the top-K among them seed the islands)
    island_pool: int = ranged(20, "[1, inf)")
    island_tries: int = ranged(2, "[1, inf)")  # members of one island verified at most (best BoW score first)

    # --- matching ---
    # one-to-one (mutual nearest neighbour) matches; the ratio test is symmetric (distinct in both images)
    # ratio test for the RANSAC-only chain (None: off; 0.9 measured lower: docs/lcd_pose.md)
    match_ratio: float | None = ranged(None, "(0, 1]")
    # ratio test for the graph chains: off, the graph rejects the outliers (paper III-E)
    graph_match_ratio: float | None = ranged(None, "(0, 1]")
    # max L2 distance between SuperPoint descriptors (None: off)
    match_max_distance_sp: float | None = ranged(0.8, "(0, 2]")  # SuperPoint descriptors are unit vectors
    # max Hamming distance between ORB descriptors (None: off)
    match_max_distance_orb: float | None = ranged(64.0, "(0, 256]")  # Hamming distance of 256 bits
    # 'all': every top-K candidate is verified and the one with the most verified
    # correspondences wins. 'first_accepted': candidates are verified in BoW order until one is
    # accepted (the rest are recorded as skipped). 'auto' (default): 'first_accepted' when the
    # chain has two independent checks (graph+ransac) or is RANSAC alone, 'all' for graph-only
    # and BoW-only chains. On the corridor, graph+ransac and ransac accept the same loops either
    # way (0 false) with half the graph verifications; graph-only stopping early accepts one
    # false loop that 'all' rejects (docs/lcd.md). Evaluation (run_all_checks) always verifies all.
    verify_until: Literal["auto", "all", "first_accepted"] = "auto"
    # budget: at most this many one-to-one matches go to graph/RANSAC/pose (0: all)
    verify_max_matches: int = ranged(400, "0 or [3, inf)")
    # budget picks the best by distance round-robin over an NxN grid of the query image (0: globally best)
    verify_spread_cells: int = ranged(4, "[0, 64]")

    # --- what is kept of past keyframes ---
    # SuperPoint descriptors kept (and matched) in this precision
    descriptor_dtype: Literal["float16", "float32"] = "float16"
    # past descriptors in an anonymous temp file ($TMPDIR; ~12 kB/keyframe resident) or in RAM
    descriptor_storage: Literal["memory", "disk"] = "disk"

    # --- graph verification (paper III-E) ---
    # fewer one-to-one matches than this: reject before building a graph
    graph_min_matches: int = ranged(20, "[3, inf)")
    graph_min_nodes: int = ranged(20, "[3, inf)")  # nodes that must survive the pruning
    graph_min_node_ratio: float = ranged(0.3, "[0, 1]")  # surviving nodes / matches must reach this
    # structural agreement of the surviving graphs (0..1) must reach this
    graph_min_score: float = ranged(0.8, "[0, 1]")
    # drop triangles with an edge longer than this x median edge (non-convex hull)
    graph_max_edge_factor: float = ranged(3.0, "(0, inf)")
    graph_node_threshold: float = ranged(0.2, "[0, inf)")  # a node whose violation score exceeds this is removed
    # at most this fraction of the violating nodes is removed per iteration
    graph_remove_fraction: float = ranged(0.2, "(0, 1]")
    graph_max_iterations: int = ranged(50, "[0, inf)")  # cap on pruning rounds
    # merge matched points closer than this (duplicates break triangulation)
    graph_min_separation_px: float = ranged(2.0, "[0, inf)")
    # >0: a node's neighbourhood test is the overlap of its k nearest matched neighbours in both images
    # (0: Delaunay neighbour Jaccard)
    graph_knn: int = ranged(8, "[0, inf)")
    # stop pruning once the node ratio can no longer be reached (same decisions, less work)
    graph_early_exit: bool = True

    # --- geometric verification (essential matrix) ---
    ransac_threshold_px: float = ranged(2.0, "(0, inf)")  # Sampson/epipolar RANSAC threshold in pixels
    ransac_confidence: float = ranged(0.999, "(0, 1)")  # RANSAC confidence
    ransac_min_inliers: int = ranged(20, "[5, inf)")  # essential-matrix inliers required (five-point essential matrix)
    ransac_min_inlier_ratio: float = ranged(0.3, "[0, 1]")  # inliers / matches required
    # focal = factor * image width when a keyframe has no camera model
    default_focal_factor: float = ranged(0.9, "(0, inf)")

    # --- metric relative pose ---
    pnp_threshold_px: float = ranged(3.0, "(0, inf)")  # PnP-RANSAC reprojection threshold in pixels
    # PnP inliers required for a metric pose (ORB-SLAM accepts a loop at 40 matched points after Sim3
    # refinement; on the demo every true loop had >= 46, every false one <= 45)
    pnp_min_inliers: int = ranged(40, "[4, inf)")
    pnp_max_rms_px: float = ranged(2.0, "(0, inf)")  # reject a pose whose refined reprojection RMS exceeds this
    # fewer PnP inliers than pnp_min_inliers are accepted down to this many when the pose is tight:
    # the inliers are at least pnp_tight_min_share of the matched 3-D points and the pose's 1-sigma
    # (from its information matrix: sqrt of the trace of each covariance block) is within both bounds
    # (0: off; measured on every demo-world candidate pair: docs/lcd_pose.md)
    # with the odometry check below (without it, two false loops on the 10-lap log)
    pnp_min_inliers_tight: int = ranged(15, "0 or [6, inf)")
    pnp_tight_min_share: float = ranged(0.8, "[0, 1]")
    pnp_tight_max_sigma_m: float = ranged(0.04, "(0, inf)")
    pnp_tight_max_sigma_deg: float = ranged(0.6, "(0, inf)")
    # a tight-rule pose must also agree with the odometry between the two keyframes within the drift
    # the odometry may have accumulated over the distance travelled between them:
    # floor + max_drift x path (m), floor + deg_per_m x path (deg) (lcd/odometry_check.py)
    odometry_max_drift: float = ranged(0.1, "[0, inf)")
    odometry_max_drift_deg_per_m: float = ranged(1.0, "[0, inf)")
    odometry_drift_floor_m: float = ranged(0.5, "[0, inf)")
    odometry_drift_floor_deg: float = ranged(5.0, "[0, 180]")
    min_depth_m: float = ranged(0.1, "[0, inf)", below="max_depth_m")  # depth values outside [min, max] are unknown
    max_depth_m: float = ranged(20.0, "(0, inf)")
    pixel_sigma_px: float = ranged(1.0, "(0, inf)")  # floor of the pixel noise used for the pose information matrix

    # --- a loop that continues the previous keyframe's loop (iBoW-LCD's priority island) ---
    # a candidate whose match lies within consistent_window keyframes of the match of the previous
    # keyframe's loop (one accepted at the full thresholds) and that fails only on a count
    # (too few matches, nodes or RANSAC inliers) is verified again with graph_min_matches,
    # graph_min_nodes and ransac_min_inliers lowered to consistent_min_matches (0: off; the
    # ratios, the structural score and the pose step keep their thresholds; docs/lcd_pose.md)
    consistent_min_matches: int = ranged(12, "0 or [5, inf)")  # 0: off; five-point essential matrix
    consistent_window: int = ranged(2, "[0, inf)")

    # --- temporal consistency (DBoW2-style) ---
    temporal_k: int = ranged(0, "[0, inf)")  # accept only after k consecutive consistent detections (0: off)
    temporal_window: int = ranged(3, "[0, inf)")  # two detections are consistent if their match ids differ by <= this


def stops_at_first_accepted(conf: LcdConfig) -> bool:
    """Whether verification of a keyframe's candidates stops at the first accepted one (``verify_until``)."""
    if conf.verify_until == "auto":
        return conf.verify in ("graph+ransac", "ransac")
    return conf.verify_until == "first_accepted"
