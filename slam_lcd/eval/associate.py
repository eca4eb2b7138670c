"""Time association of two trajectories (nearest stamp within ``t_max_diff``, evo's rule).

For every pose of the trajectory with fewer poses, the pose of the other one whose stamp
(shifted by ``t_offset`` for the estimate) is nearest is taken, if it is at most
``t_max_diff`` away; on a tie the earlier pose wins. Working on integer nanoseconds keeps
the comparison exact, so a pair exactly ``t_max_diff`` apart is matched reproducibly.
"""
from __future__ import annotations

import numpy as np

from ..types import Trajectory
from .errors import AssociationError


def seconds_to_ns(seconds: float) -> int:
    return int(round(float(seconds) * 1e9))


def nearest_indices(stamps_short: np.ndarray, stamps_long: np.ndarray, max_diff_ns: int) -> tuple[np.ndarray, np.ndarray]:
    """Indices ``(i_short, i_long)`` of stamps matched nearest-first within ``max_diff_ns``.

    ``stamps_long`` must be sorted (non-decreasing). Several short stamps may pick the
    same long stamp, as in evo.
    """
    short = np.asarray(stamps_short, dtype=np.int64)
    long_ = np.asarray(stamps_long, dtype=np.int64)
    if len(short) == 0 or len(long_) == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    upper = np.clip(np.searchsorted(long_, short, side="right"), 0, len(long_) - 1)
    lower = np.clip(upper - 1, 0, len(long_) - 1)
    d_upper = np.abs(long_[upper] - short)
    d_lower = np.abs(short - long_[lower])
    take_upper = d_upper < d_lower
    best = np.where(take_upper, upper, lower)
    diff = np.where(take_upper, d_upper, d_lower)
    ok = diff <= max_diff_ns
    return np.flatnonzero(ok).astype(np.int64), best[ok].astype(np.int64)


def subset(traj: Trajectory, idx: np.ndarray) -> Trajectory:
    """The poses of ``traj`` at ``idx`` (covariances kept when present)."""
    cov = traj.covariances[idx] if traj.covariances is not None else None
    return Trajectory(
        stamps=traj.stamps[idx],
        poses=traj.poses[idx],
        covariances=cov,
        frame_id=traj.frame_id,
        child_frame_id=traj.child_frame_id,
    )


def associate_indices(
    ref: Trajectory, est: Trajectory, t_max_diff: float = 0.01, t_offset: float = 0.0
) -> tuple[np.ndarray, np.ndarray]:
    """Matched index arrays ``(i_ref, i_est)``; ``t_offset`` (s) is added to the estimate's stamps."""
    max_diff_ns = seconds_to_ns(t_max_diff)
    if max_diff_ns < 0:
        raise AssociationError(f"t_max_diff must be >= 0, got {t_max_diff}")
    offset_ns = seconds_to_ns(t_offset)
    est_stamps = est.stamps + offset_ns
    if len(est) > len(ref):
        i_ref, i_est = nearest_indices(ref.stamps, est_stamps, max_diff_ns)
    else:
        i_est, i_ref = nearest_indices(est_stamps, ref.stamps, max_diff_ns)
    return i_ref, i_est


def associate(
    ref: Trajectory, est: Trajectory, t_max_diff: float = 0.01, t_offset: float = 0.0
) -> tuple[Trajectory, Trajectory]:
    """``(ref_sub, est_sub)``: equally long trajectories of poses matched in time.

    Raises :class:`AssociationError` when nothing matches, naming both time ranges.
    """
    i_ref, i_est = associate_indices(ref, est, t_max_diff, t_offset)
    if len(i_ref) == 0:
        def rng(t: Trajectory) -> str:
            return f"[{t.stamps[0] * 1e-9:.3f}, {t.stamps[-1] * 1e-9:.3f}] s" if len(t) else "(empty)"

        raise AssociationError(
            f"no matching stamps between reference {rng(ref)} and estimate {rng(est)} "
            f"with t_max_diff {t_max_diff} s and t_offset {t_offset} s"
        )
    return subset(ref, i_ref), subset(est, i_est)
