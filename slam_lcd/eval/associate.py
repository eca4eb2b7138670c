"""Time association of two trajectories (nearest stamp within ``t_max_diff``, evo's rule).

For every pose of the trajectory with fewer poses, the pose of the other one whose stamp
is nearest is taken, if it is at most ``t_max_diff`` away; on a tie the earlier pose wins.
The arithmetic is evo's, to the bit: stamps are float seconds (an integer-nanosecond stamp
becomes ``sec + nsec / 1e9``, the double evo parses from the same text), ``t_offset`` is
added to the longer trajectory's stamps (subtracted when that is the reference), and the
differences are float64. Why not exact nanoseconds: two stamps 1.65 ms either side of
another are a tie in decimal but not in float64, and evo breaks such ties by rounding; doing
the same keeps ``slam-lcd ate`` equal to evo to the last digit (a different pose in one
pair moves a Sim(3) scale by ~4e-8 on TUM fr2/desk).
"""
from __future__ import annotations

import numpy as np

from ..types import Trajectory
from .errors import AssociationError


def seconds_to_ns(seconds: float) -> int:
    return int(round(float(seconds) * 1e9))


def ns_to_seconds(stamps_ns: np.ndarray) -> np.ndarray:
    """Float seconds of integer-nanosecond stamps: ``sec + nsec / 1e9`` (what ``float('sec.nsec')`` gives)."""
    st = np.asarray(stamps_ns, dtype=np.int64)
    return (st // 1_000_000_000).astype(np.float64) + (st % 1_000_000_000) / 1e9


def nearest_indices(
    stamps_short: np.ndarray, stamps_long: np.ndarray, max_diff: float
) -> tuple[np.ndarray, np.ndarray]:
    """Indices ``(i_short, i_long)`` of float-second stamps matched nearest-first within ``max_diff`` (evo's
    ``matching_time_indices``, vectorised).

    ``stamps_long`` must be sorted (non-decreasing). Several short stamps may pick the
    same long stamp, as in evo.
    """
    short = np.asarray(stamps_short, dtype=np.float64)
    long_ = np.asarray(stamps_long, dtype=np.float64)
    if len(short) == 0 or len(long_) == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    inside = (short >= long_[0] - max_diff) & (short <= long_[-1] + max_diff)
    upper = np.minimum(np.searchsorted(long_, short, side="right"), len(long_) - 1)
    d_upper = long_[upper] - short
    d_lower = np.where(upper > 0, short - long_[np.maximum(upper - 1, 0)], np.inf)
    take_upper = (d_upper <= max_diff) & (d_upper < d_lower)
    take_lower = ~take_upper & (d_lower <= max_diff) & (d_lower <= d_upper)
    ok = inside & (take_upper | take_lower)
    best = np.where(take_upper, upper, upper - 1)
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
    max_diff = float(t_max_diff)
    if not max_diff >= 0:
        raise AssociationError(f"t_max_diff must be >= 0, got {t_max_diff}")
    offset = float(t_offset)
    ref_s, est_s = ns_to_seconds(ref.stamps), ns_to_seconds(est.stamps)
    if len(est) > len(ref):  # evo: the longer one is searched, shifted by the offset
        i_ref, i_est = nearest_indices(ref_s, est_s + offset, max_diff)
    else:
        i_est, i_ref = nearest_indices(est_s, ref_s - offset, max_diff)
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
