"""One loop candidate verified: descriptor matches, graph and/or RANSAC checks, the metric pose.

Why a module of its own: :class:`~slam_lcd.lcd.detector.LoopDetector` keeps the keyframes,
the database and the decisions across candidates (the best one, temporal consistency, the
relaxed thresholds of a continued loop); the checks of one (query, match) pair read only the
two stored keyframes and the configuration, so they are the same whatever called them (a
BoW query, a map's consecutive keyframes) and can be read on their own.
"""
from __future__ import annotations

import dataclasses

import numpy as np

from .config import LcdConfig
from .geometry import estimate_loop_pose
from .odometry_check import odometry_drift_reason
from .pair import check_pair
from .records import CandidateRecord, PartClock, StoredKeyframe
from .store import DescriptorStore


def verify_candidate(c: LcdConfig, q: StoredKeyframe, q_desc: np.ndarray, m: StoredKeyframe, store: DescriptorStore,
                     cand, rank: int, clock: PartClock, *, run_all_checks: bool, match,
                     same_session: bool) -> CandidateRecord:
    """The record of candidate ``cand`` (match ``m``, BoW rank ``rank``) of query ``q`` under ``c``.

    ``store`` gives the match's descriptors (read only when its BoW score passes); ``match``
    the one-to-one descriptor matcher; ``run_all_checks`` runs graph and RANSAC whatever
    ``c.verify`` says; ``same_session``: the odometry between the two keyframes is known, so a
    metric pose is also checked against it.
    """
    rec = CandidateRecord(q.id, m.id, rank, float(cand.bow_score), query_stamp=q.stamp, match_stamp=m.stamp)
    if cand.bow_score < c.min_bow_score:
        rec.reason = "low_bow_score"
        return rec
    m_desc = store.get(m.id)
    clock.lap("store")
    mode = c.verify
    need_graph = run_all_checks or mode in ("graph", "graph+ransac")
    need_ransac = run_all_checks or mode == "ransac"
    checks = check_pair(q.features, m.features, q_desc, m_desc, q.camera, m.camera, c,
                        graph=need_graph, ransac=need_ransac,
                        graph_ransac=run_all_checks or mode == "graph+ransac",
                        match=match, clock=clock)
    rec.n_matches, rec.n_verified = checks.n_matches, checks.n_verified
    rec.graph, rec.ransac, rec.ransac_on_graph = checks.graph, checks.ransac, checks.ransac_on_graph
    rec.graph_matches = checks.graph_matches if checks.graph is not None else None
    matches = checks.graph_matches if need_graph else checks.ransac_matches
    if not rec.passes(mode):
        rec.reason = rec.failure(mode)
        return rec
    if c.pose:
        used = matches
        if mode in ("graph", "graph+ransac") and rec.graph is not None:
            used = checks.graph_matches[rec.graph.kept]
        if mode == "ransac" and rec.ransac is not None:
            used = checks.ransac_matches[rec.ransac.mask]
        if mode == "graph+ransac" and rec.ransac_on_graph is not None:
            used = used[rec.ransac_on_graph.mask]
        rec.pose = estimate_loop_pose(q.keyframe, m.keyframe, used, c, points3d_m=m.points3d,
                                      source=m.points_source) if m.points3d is not None else \
            estimate_loop_pose(q.keyframe, m.keyframe, used, c)
        if rec.pose.ok and rec.pose.tight and same_session:  # odometry links one session only
            assert rec.pose.T_match_query is not None  # an ok pose has its transform
            why, rec.pose.odometry = odometry_drift_reason(rec.pose.T_match_query, m.keyframe.T_world_body,
                                                           q.keyframe.T_world_body, q.path_m - m.path_m, c)
            if why:
                rec.pose = dataclasses.replace(rec.pose, ok=False, reason=why)
        clock.lap("pose")
        if not rec.pose.ok and c.require_pose:
            rec.reason = f"pose:{rec.pose.reason}"
            return rec
    rec.accepted, rec.reason = True, "ok"
    return rec
