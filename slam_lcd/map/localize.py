"""Localise a log against a fixed map: a map-frame pose per keyframe, or "not localised" and why.

Each keyframe of the log is queried against the map's keyframes with the same chain as a
loop (Bag of SuperPoints candidates, graph verification, RANSAC, metric pose); a verified
match ``(q, m, Z)`` says ``T_map_q = T_map_m Z``. Those single-keyframe fixes are then held to
the log's own odometry, which is what makes localisation robust where one look-alike place
could fool appearance:

1. **Agreement with neighbours.** A fix is kept when at least one other fix within
   ``NEIGHBOURS`` keyframes agrees with it through the odometry between them (relative pose
   within ``map.localize_max_disagreement_m`` / ``_deg`` plus the odometry's drift over the
   distance travelled): two independent verified matches rarely agree by chance.
2. **One joint solve.** The log's keyframes are variables, its odometry the factors between
   them, each kept fix a prior with the loop's information; GNC (TLS) drops fixes the rest
   disagree with, Levenberg-Marquardt gives the poses. The map's poses are constants: the map
   is never changed.

A keyframe is *localised* when its own fix survives both; the others get the pose the
odometry carries from the localised ones (and a reason: no verified match, or the fix
rejected). No fix at all, or no fix confirmed: every keyframe is "not localised" with its
reason and the trajectory is empty (nothing to carry the odometry from); the caller still
reports the 0 %.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import gtsam
import numpy as np

from ..backend.gnc import gnc_loop_weights
from ..geometry import inv, rotation_angle_deg
from ..types import Trajectory
from .config import MapConfig
from .joint_graph import information_noise, odometry_covariance, solve_lm

NEIGHBOURS = 10  # keyframes either side whose fixes may confirm a fix
DRIFT_PER_M = 0.05  # odometry drift allowance per metre between two fixes (added to the fixed bound)
DRIFT_DEG_PER_M = 1.0


@dataclass
class KeyframeFix:
    kf_id: int
    stamp: int
    localised: bool
    reason: str
    match_id: int | None = None
    match_session: str | None = None
    inliers: int | None = None
    T_map: np.ndarray | None = None  # final pose in the map frame
    error_m: float | None = None  # position error against ground truth, where known


@dataclass
class Localisation:
    keyframes: list[KeyframeFix]
    trajectory: Trajectory  # keyframe poses in the map frame (empty when no keyframe is localised)
    component: int | None = None  # the map component the log was localised in
    notes: list[str] = field(default_factory=list)

    @property
    def share_localised(self) -> float:
        return float(np.mean([k.localised for k in self.keyframes])) if self.keyframes else 0.0


def localise(map_poses: dict[int, np.ndarray], session_of: dict[int, str], component_of: dict[int, int],
             kf_ids: list[int], stamps: list[int], T_odom: np.ndarray, cov: list, closures,
             conf: MapConfig | None = None) -> Localisation:
    """Localise keyframes (ids, stamps, odometry poses, covariances since the previous) given their map matches.

    ``closures``: the verified matches (LoopClosure, query = a keyframe of the log, match = a
    map keyframe). ``map_poses``, ``session_of``, ``component_of``: of the map's keyframes.
    """
    conf = conf or MapConfig()
    n = len(kf_ids)
    index = {int(k): i for i, k in enumerate(kf_ids)}
    best: dict[int, object] = {}
    for c in closures:  # one fix per keyframe: the one with most inliers
        q = int(c.query_id)
        if q in index and int(c.match_id) in map_poses and np.all(np.isfinite(c.T_match_query)):
            inl = int(c.evidence.get("inliers", 0) or 0)
            if q not in best or inl > int(best[q].evidence.get("inliers", 0) or 0):
                best[q] = c
    fixes = {index[q]: (c, map_poses[int(c.match_id)] @ np.asarray(c.T_match_query, float)) for q, c in best.items()}
    reasons = {i: "no verified match in the map" for i in range(n)}
    if not fixes:
        return _nothing_localised(kf_ids, stamps, reasons, {}, None)
    # the component most fixes point into: a log is localised in one frame
    comps = [component_of[int(c.match_id)] for c, _ in fixes.values()]
    comp = max(set(comps), key=comps.count)
    for i in [i for i, (c, _) in fixes.items() if component_of[int(c.match_id)] != comp]:
        reasons[i] = f"matched a map component ({component_of[int(fixes[i][0].match_id)]}) the others do not"
        del fixes[i]

    # 1. agreement with neighbours through the odometry
    path = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(T_odom[:, :3, 3], axis=0), axis=1))]
    kept = {}
    for i, (c, Ti) in fixes.items():
        support = 0
        for j, (_, Tj) in fixes.items():
            if j == i or abs(j - i) > NEIGHBOURS:
                continue
            rel_map = inv(Ti) @ Tj
            rel_odo = inv(T_odom[i]) @ T_odom[j]
            D = inv(rel_odo) @ rel_map
            d = abs(path[j] - path[i])
            if (np.linalg.norm(D[:3, 3]) <= conf.localize_max_disagreement_m * 0.5 + DRIFT_PER_M * d
                    and rotation_angle_deg(D[:3, :3])
                    <= conf.localize_max_disagreement_deg * 0.5 + DRIFT_DEG_PER_M * d):
                support += 1
        if support:
            kept[i] = (c, Ti)
        else:
            reasons[i] = "fix not confirmed by any neighbouring fix through the odometry"
    if not kept:
        return _nothing_localised(kf_ids, stamps, reasons, fixes, comp)

    # 2. one joint solve: odometry between keyframes, kept fixes as priors (GNC-checked)
    known = gtsam.NonlinearFactorGraph()
    values = gtsam.Values()
    order = sorted(kept)
    for i in range(n):
        # initial value: carried from the nearest kept fix
        j = min(order, key=lambda k: abs(k - i))
        Aj = kept[j][1] @ inv(T_odom[j])
        values.insert(i, gtsam.Pose3(Aj @ T_odom[i]))
        if i:
            noise = gtsam.noiseModel.Gaussian.Covariance(odometry_covariance(cov[i]))
            known.add(gtsam.BetweenFactorPose3(i - 1, i, gtsam.Pose3(inv(T_odom[i - 1]) @ T_odom[i]), noise))
    priors = [gtsam.PriorFactorPose3(i, gtsam.Pose3(kept[i][1]), information_noise(kept[i][0].information))
              for i in order]
    if len(priors) >= 2:
        res = gnc_loop_weights(known, priors, values)
        for i, w in zip(order, res.weights, strict=True):
            if w < 0.5:
                reasons[i] = f"fix rejected by the joint solve (GNC weight {w:.2f})"
                del kept[i]
        values = res.values
    graph = gtsam.NonlinearFactorGraph(known)
    for i in sorted(kept):
        graph.add(gtsam.PriorFactorPose3(i, gtsam.Pose3(kept[i][1]), information_noise(kept[i][0].information)))
    values = solve_lm(graph, values)
    poses = np.array([values.atPose3(i).matrix() for i in range(n)]).reshape(-1, 4, 4)
    out = []
    for i in range(n):
        c = fixes.get(i, (None, None))[0]
        out.append(KeyframeFix(int(kf_ids[i]), int(stamps[i]), i in kept, "ok" if i in kept else reasons[i],
                               int(c.match_id) if c is not None else None,
                               session_of.get(int(c.match_id)) if c is not None else None,
                               int(c.evidence.get("inliers", 0) or 0) if c is not None else None, poses[i]))
    return Localisation(out, Trajectory(np.asarray(stamps, np.int64), poses), comp)


def _nothing_localised(kf_ids, stamps, reasons: dict[int, str], fixes: dict, comp: int | None) -> Localisation:
    """Every keyframe "not localised", each with its reason; no trajectory (no fix to carry it from)."""
    out = []
    for i, k in enumerate(kf_ids):
        c = fixes.get(i, (None, None))[0]
        out.append(KeyframeFix(int(k), int(stamps[i]), False, reasons[i],
                               int(c.match_id) if c is not None else None, None,
                               int(c.evidence.get("inliers", 0) or 0) if c is not None else None, None))
    note = ("no keyframe of the log was matched to the map (is the log inside the mapped area, with the map's "
            "camera and features?)" if not fixes else
            f"{len(fixes)} keyframe(s) matched the map but no two agree through the odometry (too few matches "
            "to trust)")
    return Localisation(out, Trajectory(np.zeros(0, np.int64), np.zeros((0, 4, 4))), comp, [note])
