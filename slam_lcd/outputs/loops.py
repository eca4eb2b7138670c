"""``loops.csv``: every loop candidate with the back end's verdict, judged against ground truth.

A row joins the loop detector's :class:`~slam_lcd.lcd.detector.CandidateRecord` (its
evidence, ``verdict`` = verified or not) with the back end's record of the same
``(query, match)`` (``backend_verdict``, ``backend_reason``). With ground truth, the
distance between the two keyframes' true poses and the error of the loop's metric pose
are added; an accepted loop whose keyframes are further apart than
``run.loop_true_max_distance`` is counted as false.

Position-only ground truth (a ``PointStamped``: EuRoC's Leica) has no rotation, and its
frame is not the estimate's: ``gt_distance_m`` (and so the false-loop count) stays exact;
``err_trans_m`` compares the loop's translation with the true displacement expressed in
the match keyframe's frame through its *corrected* rotation, turned into the ground
truth's frame by the Umeyama rotation between corrected and true keyframe positions
(exact up to the corrected rotation's error, a degree or so: 2 cm at 1 m); ``err_rot_deg``
is left empty.

With a map (``run --map``), a candidate into an earlier session names that session in
``match_session`` and carries the verdict of the map's joint graph (:func:`add_map_verdicts`).
"""
from __future__ import annotations

import csv
import io
from pathlib import Path

import numpy as np

from ..backend.records import ACCEPTED, REJECTED
from ..eval.align import umeyama
from ..eval.errors import AlignmentError
from ..files.atomic import write_text
from ..geometry import interpolate_poses, inv, rotation_angle_deg
from ..types import Trajectory

VERIFIED = "accepted"  # the detector's verdict column: verified by appearance and geometry
NOT_VERIFIED = "rejected"


def loop_columns() -> list[str]:
    """The header of ``loops.csv``: the same with 0 candidates as with 100 (taken from the record type itself)."""
    from ..lcd.detector import CandidateRecord  # lazy: OpenCV

    return ["query_stamp_ns", "match_stamp_ns", *CandidateRecord(0, 0, 0, 0.0).row().keys(),
            "verdict", "backend_verdict", "backend_reason", "gt_distance_m", "err_trans_m", "err_rot_deg",
            "match_session"]


def _fmt(x):
    return "" if x is None else f"{float(x):.6g}"


def gt_at_keyframes(gt: Trajectory, kf_stamp: dict[int, int]) -> dict[int, np.ndarray]:
    """Ground-truth pose (interpolated) of every keyframe id, in one pass over the ground truth."""
    ids = list(kf_stamp)
    if not ids:
        return {}
    P = interpolate_poses(gt.stamps, gt.poses, np.array([kf_stamp[i] for i in ids], np.int64))
    return dict(zip(ids, P, strict=True))


def _position_only_frames(gt_pose: dict, keyframe_poses: Trajectory | None, kf_stamp: dict) -> dict | None:
    """Per keyframe id, the rotation of its body in the ground truth's frame (corrected rotation, aligned)."""
    if keyframe_poses is None or len(keyframe_poses) < 3:
        return None
    by_stamp = {int(s): T for s, T in zip(keyframe_poses.stamps, keyframe_poses.poses, strict=True)}
    ids = [i for i in gt_pose if kf_stamp[i] in by_stamp]
    if len(ids) < 3:
        return None
    est = np.array([by_stamp[kf_stamp[i]][:3, 3] for i in ids])
    true = np.array([gt_pose[i][:3, 3] for i in ids])
    try:
        R, _, _ = umeyama(est, true, with_scale=False)
    except AlignmentError:  # degenerate (all keyframes in one spot): no frame, no error figure
        return None
    return {i: R @ by_stamp[kf_stamp[i]][:3, :3] for i in ids}


def loop_rows(candidate_records, loop_records, keyframes, gt: Trajectory | None, *, position_only: bool = False,
              keyframe_poses: Trajectory | None = None) -> list[dict]:
    """One row per candidate (see the module docstring), in the detector's order.

    ``position_only``: ``gt`` carries positions only; ``keyframe_poses`` (the corrected
    keyframe trajectory) then give the rotations of the translation error.
    """
    backend = {(r.query_id, r.match_id): r for r in loop_records}
    kf_stamp = {k.id: k.stamp for k in keyframes}
    gt_pose = gt_at_keyframes(gt, kf_stamp) if gt is not None else {}
    R_gt_body = _position_only_frames(gt_pose, keyframe_poses, kf_stamp) if position_only else None
    rows = []
    for rec in candidate_records:
        q, mt = int(rec.query_id), int(rec.match_id)
        b = backend.get((q, mt))
        row = {"query_stamp_ns": kf_stamp.get(q, ""), "match_stamp_ns": kf_stamp.get(mt, "")}
        row.update(rec.row())
        row["verdict"] = VERIFIED if rec.accepted else NOT_VERIFIED
        row["backend_verdict"] = b.verdict if b is not None else ""
        row["backend_reason"] = b.reason if b is not None else ""
        row.update({"gt_distance_m": "", "err_trans_m": "", "err_rot_deg": "", "match_session": ""})
        if q in gt_pose and mt in gt_pose and position_only:
            d = gt_pose[q][:3, 3] - gt_pose[mt][:3, 3]
            row["gt_distance_m"] = _fmt(float(np.linalg.norm(d)))
            if rec.pose is not None and rec.pose.ok and R_gt_body is not None and mt in R_gt_body:
                t_true = R_gt_body[mt].T @ d  # the true displacement in the match body's frame
                row["err_trans_m"] = _fmt(float(np.linalg.norm(np.asarray(rec.pose.T_match_query)[:3, 3] - t_true)))
        elif q in gt_pose and mt in gt_pose:
            T_gt = inv(gt_pose[mt]) @ gt_pose[q]  # ground-truth T_match_query (body frames)
            row["gt_distance_m"] = _fmt(float(np.linalg.norm(T_gt[:3, 3])))
            if rec.pose is not None and rec.pose.ok:
                E = inv(T_gt) @ np.asarray(rec.pose.T_match_query)
                row["err_trans_m"] = _fmt(float(np.linalg.norm(E[:3, 3])))
                row["err_rot_deg"] = _fmt(rotation_angle_deg(E))
        rows.append(row)
    return rows


def add_map_verdicts(rows: list[dict], candidate_records, the_map, inter_session_loops: list[dict]) -> int:
    """Fill the rows of candidates into earlier sessions of a map from the map's joint graph; returns how many.

    The session's own back end never sees such a candidate: the joint graph of every session
    judges it (pairwise consistency with the other loops between the two sessions, then GNC),
    so ``backend_verdict`` / ``backend_reason`` are the joint graph's. ``match_session`` names
    the map session of the match; its stamp and ground truth come from the map (the ground
    truth each session was recorded with, assumed to share one frame, as the map's ATE does).
    """
    verdict = {(int(r["query_id"]), int(r["match_id"])): r for r in inter_session_loops}
    where = {int(k): (si, i) for si, s in enumerate(the_map.sessions) for i, k in enumerate(s.ids)}
    names = the_map.session_names
    n = 0
    for row, rec in zip(rows, candidate_records, strict=True):  # loop_rows keeps the detector's order
        q, mt = int(row["query_id"]), int(row["match_id"])
        if mt not in where or q not in where or where[mt][0] == where[q][0]:
            continue
        (sm, im), (sq, iq) = where[mt], where[q]
        row["match_session"] = names[sm]
        row["match_stamp_ns"] = int(the_map.sessions[sm].stamps[im])
        v = verdict.get((q, mt))
        if v is not None:
            row["backend_verdict"] = ACCEPTED if v["accepted"] else REJECTED
            row["backend_reason"] = v["reason"]
        G_q, G_m = the_map.sessions[sq].T_gt[iq], the_map.sessions[sm].T_gt[im]
        if np.all(np.isfinite(G_q)) and np.all(np.isfinite(G_m)):
            T_gt = inv(G_m) @ G_q
            row["gt_distance_m"] = _fmt(float(np.linalg.norm(T_gt[:3, 3])))
            row["err_trans_m"] = row["err_rot_deg"] = ""
            if rec.pose is not None and rec.pose.ok:
                E = inv(T_gt) @ np.asarray(rec.pose.T_match_query)
                row["err_trans_m"] = _fmt(float(np.linalg.norm(E[:3, 3])))
                row["err_rot_deg"] = _fmt(rotation_angle_deg(E))
        n += 1
    return n


def count_false_accepted(rows: list[dict], true_max_distance: float) -> int:
    """Loops the back end accepted whose keyframes are truly further apart than ``true_max_distance``."""
    return sum(1 for r in rows if r["backend_verdict"] == ACCEPTED and r["gt_distance_m"] != ""
               and float(r["gt_distance_m"]) > true_max_distance)


def write_loops_csv(path: Path, rows: list[dict]) -> None:
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=loop_columns())  # a row with a key not in the header fails here
    w.writeheader()
    for r in rows:
        w.writerow(r)
    write_text(path, buf.getvalue())
