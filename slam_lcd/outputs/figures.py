"""The figures of a run: trajectories (aligned to ground truth as in the ATE) and error over time."""
from __future__ import annotations

from pathlib import Path

from ..backend.pose_graph import ACCEPTED


def write_plots(out_dir: Path, odom, corrected, gt, keyframes, kf_corrected, loop_records, ate_before, ate_after,
                mode: str = "auto") -> None:
    """``trajectory.png`` (``mode``: xy / xz / yz / xyz / auto) and, with ground truth, ``ate_over_time.png``.

    The estimates are drawn aligned to ground truth as in the ATE (the alignment is in the
    title); the corrected trajectory is coloured by its ATE error; loops the back end
    accepted are solid, those it rejected dashed.
    """
    from ..eval.plots import plot_error_over_time, plot_run_trajectories  # lazy: matplotlib (see run.runner)

    kf = kf_corrected
    errors = None
    if ate_after is not None:
        odom = ate_before.alignment.apply(odom)
        kf = ate_after.alignment.apply(kf)
        if ate_after.est_aligned is not None:  # the matched, aligned poses: one error each
            corrected, errors = ate_after.est_aligned, ate_after.errors
        else:
            corrected = ate_after.alignment.apply(corrected)
    pos = {k.id: kf.poses[i][:3, 3] for i, k in enumerate(keyframes) if i < len(kf)}

    def edges(accepted: bool):
        return [(pos[r.query_id], pos[r.match_id]) for r in loop_records
                if (r.verdict == ACCEPTED) == accepted and r.query_id in pos and r.match_id in pos]

    align = ate_after.alignment.label if ate_after is not None else "no ground truth"
    plot_run_trajectories(ground_truth=gt, odometry=odom, corrected=corrected, corrected_errors=errors,
                          accepted_edges=edges(True), rejected_edges=edges(False), mode=mode,
                          title=f"trajectories and loops ({align})", out=out_dir / "trajectory.png")
    if ate_before is not None:
        plot_error_over_time([("odometry", ate_before), ("corrected", ate_after)],
                             title=f"ATE over time ({align})", out=out_dir / "ate_over_time.png")
