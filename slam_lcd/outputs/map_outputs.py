"""The files a run with a map adds to its set: every session in the map frame, localisation results.

``run --map``: ``map/sessions.csv`` (one row per session: keyframes, component, loops to other
sessions, ATE in the common frame), ``map/<session>.tum`` (every session's keyframes in the
frame of its component; the first session's odometry frame is the map frame), ``map/<this
session>_full_rate.tum`` (this log at every odometry stamp in the map frame) and
``map/inter_session_loops.csv``. ``localize``: ``localized.tum`` (every odometry stamp in the map
frame), ``keyframes_localized.tum`` and ``localization.csv`` (per keyframe: localised or not, why,
the map keyframe it matched, the error against ground truth where known).
"""
from __future__ import annotations

import csv
import io
from pathlib import Path

import numpy as np

from ..backend import correct_full_rate
from ..files.atomic import write_text
from ..io.trajectory_files import write_tum
from ..map.summary import gt_alignment
from ..types import Trajectory
from .corrected_log import SessionLayer

MAP_DIR = "map"
LOCALIZATION_FILES = ("localized.tum", "keyframes_localized.tum", "localization.csv")


def _csv(rows: list[dict]) -> str:
    buf = io.StringIO()
    if rows:
        w = csv.DictWriter(buf, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    return buf.getvalue()


def session_file_stem(name: str) -> str:
    """A session name as a file name: letters, digits, - _ . kept, anything else as _ (`run --map` and `map export`)."""
    return "".join(ch if ch.isalnum() or ch in "-_." else "_" for ch in name) or "session"


def write_map_outputs(out_dir: Path, pipe, result, the_map) -> list[str]:
    """Write ``map/`` for a run that appended to ``the_map``; returns the names written."""
    folder = out_dir / MAP_DIR
    folder.mkdir(parents=True, exist_ok=True)
    summary = result.map
    rows = []
    for s in summary["sessions"]:
        rows.append({"session": s["name"], "keyframes": s["keyframes"], "component": s["component"],
                     "joined": s["joined"], "inter_session_loops": s["inter_session_loops"],
                     "ate_odometry_m": _num(s.get("ate_odometry")), "ate_map_m": _num(s.get("ate_map")),
                     "note": s.get("note", "")})
    write_text(folder / "sessions.csv", _csv(rows))
    write_text(folder / "inter_session_loops.csv", _csv(summary["inter_session_loops"]) or
               "query_id,match_id,query_session,match_session,accepted,reason\n")
    for i, name in enumerate(the_map.session_names):
        write_tum(folder / f"{session_file_stem(name)}.tum", the_map.session_trajectory(i))
    current = summary.get("current_session")
    if current is not None and pipe.keyframes:
        full, _ = current_in_map_frame(pipe, the_map, current)
        write_tum(folder / f"{session_file_stem(current)}_full_rate.tum", full)
    return [MAP_DIR + "/"]


def current_in_map_frame(pipe, the_map, current: str) -> tuple[Trajectory, Trajectory]:
    """This run's session in its component's frame: (every odometry stamp, keyframes)."""
    kf_map = the_map.session_trajectory(the_map.session_names.index(current))
    kf_odom = pipe.keyframe_odometry()
    full = correct_full_rate(pipe.odometry_trajectory(), kf_odom.stamps, kf_odom.poses, kf_map.poses)
    return full, kf_map


def session_layer(the_map, current: str, inter_session_loops: list[dict]):
    """Every session of the map for corrected.mcap, and the map's ground-truth alignment of this component.

    Returns ``(SessionLayer, alignment)``; ``alignment`` has ``R``, ``t`` (map frame to the ground
    truth's) or is None without ground truth in the map."""
    from types import SimpleNamespace

    comp = {m["name"]: int(m["component"]) for m in the_map.manifest.sessions}
    mine = comp[current]
    poses = the_map.poses()
    names, paths, joined = [], [], []
    for i, name in enumerate(the_map.session_names):
        names.append(session_file_stem(name))
        paths.append(the_map.session_trajectory(i))
        joined.append(comp[name] == mine)
    loops = [(poses[int(r["match_id"])][:3, 3], poses[int(r["query_id"])][:3, 3]) for r in inter_session_loops
             if r["accepted"] and comp[r["query_session"]] == mine and comp[r["match_session"]] == mine
             and int(r["match_id"]) in poses and int(r["query_id"]) in poses]

    al = gt_alignment(the_map, mine)
    return (SessionLayer(names, paths, joined, loops),
            SimpleNamespace(R=al[0], t=al[1]) if al is not None else None)


def write_localization_outputs(out_dir: Path, pipe, result) -> list[str]:
    rep = result.localization
    loc = rep["_loc"]
    written = []
    if len(loc.trajectory):  # nothing localised: no trajectory in the map frame, the table says why
        kf_odom = pipe.keyframe_odometry()
        full = correct_full_rate(pipe.odometry_trajectory(), kf_odom.stamps, kf_odom.poses, loc.trajectory.poses)
        write_tum(out_dir / "localized.tum", full)
        write_tum(out_dir / "keyframes_localized.tum", Trajectory(loc.trajectory.stamps, loc.trajectory.poses))
        written = list(LOCALIZATION_FILES[:2])
    rows = [{"keyframe": k.kf_id, "stamp_ns": k.stamp, "localised": k.localised, "reason": k.reason,
             "map_keyframe": "" if k.match_id is None else k.match_id, "map_session": k.match_session or "",
             "inliers": "" if k.inliers is None else k.inliers,
             "error_m": "" if getattr(k, "error_m", None) is None else round(k.error_m, 4)} for k in loc.keyframes]
    write_text(out_dir / "localization.csv", _csv(rows))
    return [*written, "localization.csv"]


def _num(x):
    return "" if x is None or not np.isfinite(x) else round(float(x), 4)


def growth_png(summary: dict) -> bytes | None:
    """The map's growth over its sessions (keyframes stored, kept, and megabytes after each), as PNG; None
    when the map does not record it (a map of an older slam-lcd)."""
    rows = [g for g in summary.get("growth", []) if g.get("keyframes") is not None]
    if not rows:
        return None
    import io as _io

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    x = np.arange(1, len(rows) + 1)
    fig, ax = plt.subplots(figsize=(6.4, 3.6), dpi=100)
    ax.plot(x, [g["keyframes"] for g in rows], "o-", label="keyframes (poses)")
    ax.plot(x, [g["kept_keyframes"] for g in rows], "s-", label="kept keyframes (matched against)")
    ax.set_xlabel("sessions in the map")
    ax.set_ylabel("keyframes")
    ax2 = ax.twinx()
    ax2.plot(x, [(g["bytes"] or 0) / 1e6 for g in rows], "^--", color="tab:red", label="MB")
    ax2.set_ylabel("MB of arrays")
    lines, labels = ax.get_legend_handles_labels()
    lines2, labels2 = ax2.get_legend_handles_labels()
    ax.legend(lines + lines2, labels + labels2, loc="upper left", fontsize=8)
    ax.set_title("map growth over sessions")
    fig.tight_layout()
    buf = _io.BytesIO()
    fig.savefig(buf, format="png")
    plt.close(fig)
    return buf.getvalue()
