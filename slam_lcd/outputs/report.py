"""``report.json``, ``report.md`` and the two figures of a run (top view, ATE over time)."""
from __future__ import annotations

import json
from pathlib import Path

from ..atomic import write_text
from ..backend.pose_graph import ACCEPTED
from .result import RunResult


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


def _ate_dict(a) -> dict:
    return {k: float(getattr(a, k)) for k in ("rmse", "mean", "median", "max") if hasattr(a, k)} | {"pairs": int(len(a.errors))}


def write_report(out_dir: Path, result: RunResult, ate_before, ate_after) -> None:
    rep = {
        "frames": result.n_frames, "keyframes": result.n_keyframes,
        "loops": {"candidates": result.loops_proposed, "verified": result.loops_verified,
                  "accepted": result.loops_accepted, "rejected_by_backend": result.loops_rejected_backend,
                  "false_accepted": result.false_loops_accepted},
        "ate": None if ate_before is None else {
            "alignment": result.alignment,
            "before": _ate_dict(ate_before), "after": _ate_dict(ate_after),
            "ratio_after_before": (ate_after.rmse / ate_before.rmse) if ate_before.rmse else None,
        },
        "interrupted": result.interrupted,
        "wall_s": round(result.wall_s, 3), "log_duration_s": round(result.log_duration_s, 3),
        "stages": result.stages, "outputs": result.outputs,
    }
    write_text(out_dir / "report.json", json.dumps(rep, indent=2))
    md = ["# slam-lcd run report", ""] + [f"- {line}" for line in result.summary_lines()]
    md += ["", "## Time per stage", "", "| stage | seconds | calls |", "|---|---|---|"]
    md += [f"| {k} | {v['seconds']:.2f} | {v['calls']} |" for k, v in result.stages.items()]
    md += ["", "## Outputs", ""] + [f"- `{o}`" for o in result.outputs]
    write_text(out_dir / "report.md", "\n".join(md) + "\n")
