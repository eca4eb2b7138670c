"""What the loop detector records and keeps: a candidate's checks, a past keyframe, time per part.

:class:`CandidateRecord` is the audit trail of one BoW candidate (every check that ran, the
verdict and its reason: ``loops.csv``, ``slam-lcd eval-lcd``); :class:`StoredKeyframe` is what the
detector keeps of a past keyframe (no images; descriptors live in :mod:`slam_lcd.lcd.store`).
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..types import CameraModel, Features, Keyframe, LoopClosure
from .geometry import EpipolarVerdict, PoseVerdict
from .graph import GraphVerdict


class PartClock:
    """Seconds per part of one ``LoopDetector.add`` (BoW, matching, graph, RANSAC, pose, ...)."""

    def __init__(self):
        self.seconds: dict[str, float] = {}
        self._t = time.perf_counter()

    def lap(self, part: str) -> None:
        """Charge the time since the previous lap to ``part``."""
        now = time.perf_counter()
        self.seconds[part] = self.seconds.get(part, 0.0) + (now - self._t)
        self._t = now


def drop_arrays(rec: CandidateRecord) -> None:
    """A record kept for the run's report needs its figures, not its per-match arrays."""
    if rec.graph is not None:
        rec.graph.kept = rec.graph.kept[:0]
    rec.graph_matches = None
    for v in (rec.ransac, rec.ransac_on_graph):
        if v is not None:
            v.mask = v.mask[:0]


@dataclass
class CandidateRecord:
    """One BoW candidate of one query, with every check that ran on it."""

    query_id: int
    match_id: int
    rank: int  # 0 = best BoW score
    bow_score: float
    n_matches: int = 0  # one-to-one matches found
    n_verified: int = 0  # of those, handed to verification (at most ``lcd.verify_max_matches``)
    graph: GraphVerdict | None = None
    ransac: EpipolarVerdict | None = None  # on all mutual matches
    ransac_on_graph: EpipolarVerdict | None = None  # on the graph's surviving nodes
    pose: PoseVerdict | None = None
    accepted: bool = False
    reason: str = "not_checked"
    query_stamp: int | None = None
    match_stamp: int | None = None
    relaxed: bool = False  # verified at lcd.consistent_min_matches (continues the previous keyframe's loop)
    # the matches the graph verified, (query, match) rows (graph.kept indexes them); dropped like the masks
    graph_matches: np.ndarray | None = None

    def passes(self, mode: str) -> bool:
        """Would this candidate pass verification ``mode`` (pose and temporal checks excluded)?"""
        if mode == "none":
            return True
        if mode == "ransac":
            return bool(self.ransac and self.ransac.accepted)
        if mode == "graph":
            return bool(self.graph and self.graph.accepted)
        if mode == "graph+ransac":
            return bool(self.graph and self.graph.accepted and self.ransac_on_graph and self.ransac_on_graph.accepted)
        raise ValueError(f"unknown verification mode {mode!r}")

    def failure(self, mode: str) -> str:
        """The reason a candidate that does not pass ``mode`` gives (the first check that refused it)."""
        if mode == "graph" or (mode == "graph+ransac" and not (self.graph and self.graph.accepted)):
            return f"graph:{self.graph.reason if self.graph else 'not_run'}"
        check = self.ransac if mode == "ransac" else self.ransac_on_graph
        return f"ransac:{check.reason if check else 'not_run'}"

    def support(self, mode: str) -> float:
        """Verified correspondences under ``mode`` (BoW score for 'none'): picks the best of a query's passing
        candidates."""
        if mode == "ransac" and self.ransac is not None:
            return float(self.ransac.inliers)
        if mode == "graph" and self.graph is not None:
            return float(self.graph.n_nodes)
        if mode == "graph+ransac" and self.ransac_on_graph is not None:
            return float(self.ransac_on_graph.inliers)
        return float(self.bow_score)

    def row(self) -> dict[str, Any]:
        """Flat dict for CSV/JSON output."""
        out: dict[str, Any] = {
            "query_id": self.query_id,
            "match_id": self.match_id,
            "rank": self.rank,
            "bow_score": round(float(self.bow_score), 6),
            "n_matches": self.n_matches,
            "n_verified": self.n_verified,
            "accepted": self.accepted,
            "reason": self.reason,
            "graph_nodes": self.graph.n_nodes if self.graph else "",
            "graph_score": round(self.graph.score, 4) if self.graph else "",
            "graph_reason": self.graph.reason if self.graph else "",
            "ransac_inliers": self.ransac.inliers if self.ransac else "",
            "ransac_reason": self.ransac.reason if self.ransac else "",
            "graph_ransac_inliers": self.ransac_on_graph.inliers if self.ransac_on_graph else "",
            "graph_ransac_reason": self.ransac_on_graph.reason if self.ransac_on_graph else "",
            "pose_inliers": self.pose.inliers if self.pose else "",
            "pose_rms_px": (round(self.pose.rms, 4) if self.pose and np.isfinite(self.pose.rms) else ""),
            "pose_reason": self.pose.reason if self.pose else "",
            "relaxed": self.relaxed,
        }
        return out


@dataclass
class StoredKeyframe:
    """What the detector keeps of a past keyframe (no images; descriptors live in the store).

    ``features`` holds the keypoints only (no scores, zero-length descriptors); 3-D points and
    landmarks are float32 (what later verification needs, in the precision it needs).
    """

    id: int
    stamp: int
    position: int
    features: Features
    camera: CameraModel
    T_body_camera: np.ndarray
    points3d: np.ndarray | None
    points_source: str
    keyframe: Keyframe = field(repr=False)  # light copy without images (every entry has one)
    path_m: float = 0.0  # odometry distance travelled from the first keyframe to this one

    def nbytes(self) -> int:
        """Bytes of the arrays this entry holds (descriptors excluded: see the store)."""
        arrays = [self.features.keypoints, self.points3d, self.keyframe.landmarks if self.keyframe else None]
        seen, total = set(), 0
        for a in arrays:
            if a is not None and id(a) not in seen:
                seen.add(id(a))
                total += a.nbytes
        return total


_COUNT_REASONS = ("too_few_matches", "too_few_nodes", "too_few_inliers")


def failed_on_a_count(rec: CandidateRecord) -> bool:
    """Did a candidate fail only because some count was below its minimum (not a ratio or the score)?"""
    if rec.reason == "low_bow_score" or rec.reason.startswith("pose:"):
        return False
    return any(rec.reason.endswith(":" + r) for r in _COUNT_REASONS)


def loop_closure(r: CandidateRecord, verify: str, *, inter_session: bool) -> LoopClosure:
    """An accepted record as the :class:`~slam_lcd.types.LoopClosure` the back end takes, with its evidence.

    Without a metric pose (``lcd.require_pose`` off) the transform is NaN and the information zero:
    the loop is then a detection only, never a factor."""
    evidence: dict[str, Any] = {"bow_score": r.bow_score, "n_matches": r.n_matches, "verify": verify,
                                "inter_session": inter_session}
    if r.graph is not None:
        evidence.update(r.graph.evidence())
        evidence["structural_score"] = r.graph.score
    if r.ransac is not None:
        evidence.update(r.ransac.evidence())
    if r.ransac_on_graph is not None:
        evidence["graph_ransac_inliers"] = r.ransac_on_graph.inliers
    if r.pose is not None:
        evidence.update(r.pose.evidence())
    if r.pose is not None and r.pose.ok:
        T, info, inliers = np.asarray(r.pose.T_match_query), np.asarray(r.pose.information), r.pose.inliers
    else:
        T, info = np.full((4, 4), np.nan), np.zeros((6, 6))
        inliers = (r.ransac_on_graph.inliers if r.ransac_on_graph else
                   (r.ransac.inliers if r.ransac else (r.graph.n_nodes if r.graph else r.n_matches)))
    evidence["inliers"] = inliers
    return LoopClosure(query_id=r.query_id, match_id=r.match_id, T_match_query=T, information=info,
                       evidence=evidence, query_stamp=r.query_stamp, match_stamp=r.match_stamp)
