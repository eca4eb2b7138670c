"""Configuration section `backend` (owned by :mod:`slam_lcd.backend`).

Sigmas are standard deviations: rotations in radians, translations in metres. Every
covariance/information matrix of the back end is in GTSAM Pose3 tangent order
``[rx ry rz tx ty tz]``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

from ..value_range import ranged


@dataclass
class BackendConfig:
    # Prior that anchors the first keyframe (gauge freedom of the pose graph).
    prior_sigma_rot: float = ranged(1e-4, "(0, inf)")
    prior_sigma_trans: float = ranged(1e-4, "(0, inf)")
    # Weak prior on the first keyframe of each segment after a tracking loss (slam_lcd.backend.segments):
    # fixes the segment's gauge without pulling a joined segment (a loop's information is 1e4-1e6 x larger);
    # 10 m / 1 rad keeps iSAM2's Cholesky factorisation well conditioned (100 m / 3 rad does not).
    segment_prior_sigma_rot: float = ranged(1.0, "(0, inf)")
    segment_prior_sigma_trans: float = ranged(10.0, "(0, inf)")
    # Two segments no accepted loop connects are joined by at least this many mutually consistent loops.
    segment_join_min_loops: int = ranged(2, "[1, inf)")
    # Odometry noise used when a keyframe comes without a 6x6 covariance (per keyframe step).
    odom_sigma_rot: float = ranged(0.01, "(0, inf)")
    odom_sigma_trans: float = ranged(0.05, "(0, inf)")
    # Use the covariance handed to add_keyframe (false: always the sigmas above).
    use_odometry_covariance: bool = True
    # Loop noise used when a closure's information matrix is missing or not positive definite.
    loop_sigma_rot: float = ranged(0.02, "(0, inf)")
    loop_sigma_trans: float = ranged(0.2, "(0, inf)")
    # Robust kernel on loop factors (odometry and prior stay Gaussian).
    loop_kernel: Literal["none", "huber", "cauchy", "dcs", "geman_mcclure"] = "cauchy"
    # Kernel width on the whitened error (Huber k, Cauchy k, DCS phi, Geman-McClure c).
    loop_kernel_width: float = ranged(3.0, "(0, inf)")
    # iSAM2: relinearise a variable whose update exceeds this (tangent norm) ...
    isam2_relinearize_threshold: float = ranged(0.1, "[0, inf)")
    # ... checking every this many updates.
    isam2_relinearize_skip: int = ranged(1, "[1, inf)")
    # iSAM2 factorisation of the linear system.
    isam2_factorization: Literal["cholesky", "qr"] = "cholesky"
    # Extra iSAM2 update() calls after a loop is added or removed (lets big corrections converge).
    isam2_extra_updates_per_loop: int = ranged(1, "[0, inf)")
    # Outlier handling: 'none' accepts every loop as given (kernel only); 'gate' runs the
    # consistency checks on each new loop; 'gate+gnc' adds the batch GNC (TLS) re-check;
    # 'gnc' accepts every loop into iSAM2 and relies on the GNC re-check alone.
    outlier_rejection: Literal["none", "gate", "gate+gnc", "gnc"] = "gate+gnc"
    # Consistency gate: chi-square test of the loop against the current estimate (with the
    # odometry chain covariance) and PCM-style pairwise tests, at this probability (6 dof).
    gate_chi2_probability: float = ranged(0.999, "(0, 1)")
    # Pairwise (PCM) tests against earlier loops whose keyframes lie within this many
    # keyframes of the new loop's ends (0 disables them).
    gate_pairwise_window: int = ranged(50, "[0, inf)")
    # A loop failing the first test is accepted (with its supporters) when at least this many
    # nearby earlier loops are pairwise consistent with it (0: never).
    gate_min_support: int = ranged(2, "[0, inf)")
    # ... but only while its chi2 against the estimate is at most this multiple of the gate
    # threshold (and likewise for each supporting loop): a cluster of loops into an aliased
    # place (same texture elsewhere) is mutually consistent, and only its gross disagreement
    # with odometry gives it away. True loops under biased odometry score a few times the
    # threshold; aliases that shift the map by metres / tens of degrees score far more.
    gate_rescue_max_factor: float = ranged(8.0, "[1, inf)")
    # A new loop is rejected when it is inconsistent with more than this fraction of the
    # earlier accepted loops it was checked against pairwise.
    gate_pairwise_max_inconsistent: float = ranged(0.5, "[0, 1]")
    # Batch GNC (TLS) re-check after every this many new loops (0: only in finalize()).
    gnc_every_n_loops: int = ranged(50, "[0, inf)")
    # ... and at least this fraction of the loops offered so far (0: every gnc_every_n_loops). A
    # re-check costs O(keyframes + loops); spacing re-checks in proportion to the loops keeps
    # its cost per keyframe constant on hour-long runs (docs/backend.md).
    gnc_every_fraction: float = ranged(0.25, "[0, inf)")
    # GNC also reconsiders loops the pairwise test rejected (may restore them as inliers).
    gnc_includes_gated: bool = False
    # GNC inlier threshold as a chi-square probability per loop factor (6 dof).
    gnc_inlier_probability: float = ranged(0.99, "(0, 1)")
    # GNC iterations (outer, mu schedule) limit.
    gnc_max_iterations: int = ranged(100, "[1, inf)")
    # Weight below which GNC declares a loop an outlier.
    gnc_outlier_weight: float = ranged(0.5, "[0, 1]")
    # finalize(): 'lm' solves the written graph (prior, odometry, accepted loops; Gaussian) by
    # batch Levenberg-Marquardt from iSAM2's estimate, so every output sits at its optimum;
    # 'none' keeps iSAM2's last estimate.
    final_solver: Literal["lm", "none"] = "lm"


def gnc_due(loops_since: int, loops_held: int, conf: BackendConfig) -> bool:
    """Whether the batch GNC re-check is due after ``loops_since`` new gated loops (``loops_held`` offered in all)."""
    n = conf.gnc_every_n_loops
    if n <= 0:
        return False
    return loops_since >= max(n, math.ceil(conf.gnc_every_fraction * (loops_held - loops_since)))
