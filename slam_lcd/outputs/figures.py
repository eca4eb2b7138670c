"""The figures of a run: trajectories (aligned to ground truth as in the ATE) and error over time."""
from __future__ import annotations

from pathlib import Path

from ..backend.pose_graph import ACCEPTED


def write_plots(out_dir: Path, odom, corrected, gt, keyframes, kf_corrected, loop_records, ate_before, ate_after) -> None:
    """Top view (estimates aligned to ground truth as in the ATE) and ATE over time."""
    from ..eval.plots import plot_error_over_time, plot_trajectories_top

    kf = kf_corrected
    if ate_after is not None:
        odom = ate_before.alignment.apply(odom)
        corrected = ate_after.alignment.apply(corrected)
        kf = ate_after.alignment.apply(kf)
    trajs = [("odometry", odom), ("corrected", corrected)]
    if gt is not None:
        trajs = [("ground truth", gt)] + trajs
    pos = {k.id: kf.poses[i][:3, 3] for i, k in enumerate(keyframes) if i < len(kf)}
    edges = [(pos[r.query_id], pos[r.match_id]) for r in loop_records
             if r.verdict == ACCEPTED and r.query_id in pos and r.match_id in pos]
    align = ate_after.alignment.label if ate_after is not None else "no ground truth"
    plot_trajectories_top(trajs, loop_edges=edges, title=f"trajectories, accepted loops ({align})",
                          out=out_dir / "trajectory.png")
    if ate_before is not None:
        plot_error_over_time([("odometry", ate_before), ("corrected", ate_after)],
                             title=f"ATE over time ({align})", out=out_dir / "ate_over_time.png")
