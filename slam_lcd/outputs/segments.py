"""What a run says about its tracking-loss segments: the table, ATE per joined component, file notes.

Why: after a tracking loss the odometry restarts in a frame of its own (a new segment of the
pose graph, :mod:`slam_lcd.backend.segments`); only loops can say where it lies. A segment
that no loop joins floats: its poses are where the odometry left off, not where the camera
was. One ATE over the whole run, aligned once, would blame the correction for that; one
aligned per pose would hide it. So ATE is computed per *component* (segments joined by
loops), each aligned on its own, and the run's figure is the RMSE over all components'
errors together, with every component listed beside it (keyframes, joined or not, its own
before and after).

A pose belongs to the segment whose first keyframe is the last one at or before its stamp
(poses before the first keyframe: segment 0), so the odometry, the corrected trajectory and
the keyframes share one partition; ``segments.csv`` gives the stamp ranges.
"""
from __future__ import annotations

import csv
import io
from collections.abc import Sequence

import numpy as np

from ..errors import SlamLcdError
from ..eval import ate_with_config
from ..files.atomic import write_text
from ..types import Trajectory

SEGMENTS_FILE = "segments.csv"
_COLUMNS = ("segment", "component", "keyframes", "first_keyframe", "last_keyframe", "first_stamp_ns",
            "last_stamp_ns", "joining_loops")


def segment_of(stamps: np.ndarray, rows: Sequence[dict]) -> np.ndarray:
    """Segment index of each stamp (see the module docstring)."""
    starts = np.array([r["first_stamp_ns"] for r in rows[1:]], dtype=np.int64)
    return np.searchsorted(starts, np.asarray(stamps, np.int64), side="right")


def tum_notes(traj: Trajectory, rows: Sequence[dict]) -> dict[int, str]:
    """Comment lines for a TUM file: before the first pose of each segment after the first one."""
    if len(rows) < 2 or len(traj) == 0:
        return {}
    seg = segment_of(traj.stamps, rows)
    notes = {}
    for i in np.flatnonzero(np.diff(seg) != 0) + 1:
        r = rows[int(seg[i])]
        notes[int(i)] = (f"segment {r['segment']} (component {r['component']}): tracking was lost before this pose; "
                         + ("joined to the others by loops" if r["component"] != r["segment"] or r["joining_loops"]
                            else "no loop joins it: its poses are where the odometry left off"))
    return notes


def write_segments_csv(path, rows: Sequence[dict]) -> None:
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=_COLUMNS, lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow({k: r[k] for k in _COLUMNS})
    write_text(path, buf.getvalue())


def components_of(rows: Sequence[dict]) -> list[dict]:
    """One entry per component: its segments, keyframes and whether loops joined more than one segment."""
    comps: dict[int, dict] = {}
    for r in rows:
        c = comps.setdefault(r["component"], {"component": r["component"], "segments": [], "keyframes": 0,
                                              "joining_loops": 0})
        c["segments"].append(r["segment"])
        c["keyframes"] += r["keyframes"]
        c["joining_loops"] += r["joining_loops"]
    return [comps[k] for k in sorted(comps)]


def component_ate(gt: Trajectory, odom: Trajectory, corrected: Trajectory, rows: Sequence[dict],
                  eval_conf) -> tuple[list[dict], float | None, float | None]:
    """ATE before and after per component, each aligned on its own; and the RMSE over all their errors.

    A component too short to align (or without ground truth over it) gets ``None`` and a reason.
    """
    comps = components_of(rows)
    label = np.array([r["component"] for r in rows])
    odom_c, corr_c = label[segment_of(odom.stamps, rows)], label[segment_of(corrected.stamps, rows)]
    err_b: list[np.ndarray] = []
    err_a: list[np.ndarray] = []
    for c in comps:
        c["joined"] = len(c["segments"]) > 1
        c["ate_before_m"] = c["ate_after_m"] = None
        c["poses"] = int((corr_c == c["component"]).sum())
        try:
            before = ate_with_config(gt, _subset(odom, odom_c == c["component"]), eval_conf)
            after = ate_with_config(gt, _subset(corrected, corr_c == c["component"]), eval_conf)
        except SlamLcdError as e:
            c["not_measured"] = e.problem
            continue
        c["ate_before_m"], c["ate_after_m"] = float(before.rmse), float(after.rmse)
        err_b.append(before.errors)
        err_a.append(after.errors)
    if not err_a:
        return comps, None, None
    rms = lambda e: float(np.sqrt(np.mean(np.concatenate(e) ** 2)))  # noqa: E731
    return comps, rms(err_b), rms(err_a)


def _subset(traj: Trajectory, mask: np.ndarray) -> Trajectory:
    return Trajectory(traj.stamps[mask], traj.poses[mask],
                      None if traj.covariances is None else traj.covariances[mask],
                      frame_id=traj.frame_id, child_frame_id=traj.child_frame_id)


def segments_line(rows: Sequence[dict], comps: Sequence[dict]) -> str:
    """The summary's line: how many segments, the components loops made, how many segments stand alone."""
    joined = [c for c in comps if len(c["segments"]) > 1]
    alone = [c for c in comps if len(c["segments"]) == 1]
    parts = []
    for c in joined:
        ate = (f", ATE {c['ate_before_m']:.3f} -> {c['ate_after_m']:.3f} m" if c.get("ate_after_m") is not None
               else "")
        parts.append(f"segments {_ranges(c['segments'])} joined by {c['joining_loops'] // 2} loops "
                     f"({c['keyframes']} keyframes{ate})")
    if alone:
        parts.append(f"{len(alone)} on their own ({sum(c['keyframes'] for c in alone)} keyframes; "
                     f"segments.csv lists them)")
    return (f"segments: {len(rows)} (tracking lost {len(rows) - 1} times) in {len(comps)} components: "
            + "; ".join(parts))


def _ranges(values: Sequence[int]) -> str:
    out, start, prev = [], values[0], values[0]
    for v in list(values[1:]) + [None]:
        if v is not None and v == prev + 1:
            prev = v
            continue
        out.append(f"{start}" if start == prev else f"{start}-{prev}")
        if v is not None:
            start = prev = v
    return ",".join(out)


def segment_facts(rows: list[dict], gt: Trajectory | None, odom: Trajectory, corrected: Trajectory, eval_conf,
                  result) -> dict | None:
    """report.json's ``segments`` (None: no keyframe). With more than one component and a ground truth the
    run's ATE (``result.ate_before`` / ``ate_after``) becomes the per-component one (module docstring)."""
    if not rows:
        return None
    comps = components_of(rows)
    facts = {"count": len(rows), "components": comps, "segments": rows, "ate": "one alignment"}
    if len(comps) > 1 and gt is not None:
        comps, before, after = component_ate(gt, odom, corrected, rows, eval_conf)
        facts["components"] = comps
        if after is not None:
            result.ate_before, result.ate_after = before, after
            facts["ate"] = "per component, each aligned on its own"
            result.alignment = f"{result.alignment}, per component ({len(comps)} components aligned separately)"
    return facts
