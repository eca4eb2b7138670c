"""Localise a log against a fixed map: a map-frame pose per keyframe, or "not localised" and why.

Each keyframe of the log is queried against the map's keyframes with the same chain as a
loop (Bag of SuperPoints candidates, graph verification, RANSAC, metric pose); a verified
match ``(q, m, Z)`` says ``T_map_q = T_map_m Z``. Those single-keyframe fixes are then held to
the log's own odometry, which is what makes localisation robust where a look-alike place
could fool appearance:

1. **Confirmation by a distinct place.** A fix is kept when another fix within
   ``NEIGHBOURS`` keyframes agrees with it through the odometry between them (relative pose
   within ``map.localize_max_disagreement_m`` / ``_deg`` plus the odometry's drift over the
   distance travelled) and comes from another place: their map keyframes at least
   ``map.localize_min_place_separation_m`` apart (or the log travelled that far between them),
   or looking in directions at least ``map.localize_min_view_angle_deg`` apart (the angle of
   the rotation between the two map keyframes' orientations: no camera mounting needed; the
   angle between the optical axes for a level camera turning, an upper bound on it otherwise).
   Neighbouring keyframes that see one look-alike place agree with each other as well as true
   fixes do; they are one match seen several times, not independent evidence. Views of two
   walls of one room are two places: a log that turns in place or walks a small room confirms
   its fixes by direction where it cannot by distance.
2. **Groups that disagree.** Fixes that agree with each other through the odometry, link by
   link along the log, form a group, confirmed or not. Where two groups disagree (their fixes
   closest along the log do not agree through the odometry: a look-alike place and the true
   one), the one with at least ``map.localize_min_group_ratio`` times the other's fixes wins
   and the other's fixes are dropped; when neither is that much larger, both are *ambiguous*
   and not localised. Only confirmed fixes are kept and counted, but every group is a rival (one
   with no confirmed fix counts all its fixes): a run of keyframes along a look-alike can confirm
   itself across its own length, and the true place's few fixes, too close together to confirm
   themselves, must still count against it. The joint solve cannot be left to choose: the
   odometry between two groups bends to fit both before the solve calls either an outlier.
3. **One joint solve.** The log's keyframes are variables, its odometry the factors between
   them, each kept fix a prior with the loop's information; GNC (TLS) drops fixes the rest
   disagree with, Levenberg-Marquardt gives the poses. The map's poses are constants: the map
   is never changed.

A keyframe is *localised* when its own fix survives all three; the others get the pose the
odometry carries from the localised ones (and a reason). No fix kept at all: every keyframe
is "not localised" with its reason and the trajectory is empty (nothing to carry the odometry
from); the caller still reports the 0 %.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import gtsam
import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import connected_components

from ..backend.gnc import gnc_loop_weights
from ..geometry import inv, rotation_angle_deg
from ..types import LoopClosure, Trajectory
from .config import MapConfig
from .contents import MapError
from .joint_graph import solve_lm
from .session_factors import information_noise, odometry_covariance

NEIGHBOURS = 10  # keyframes either side whose fixes may confirm a fix
# fixes this close along the log (or within NEIGHBOURS keyframes) that agree are one group: near
# enough for the odometry's drift allowance to hold link by link
GROUP_WINDOW_M = 15.0
DRIFT_PER_M = 0.05  # odometry drift allowance per metre between two fixes (added to the fixed bound)
DRIFT_DEG_PER_M = 1.0
AMBIGUOUS = "ambiguous"  # the start of the reason of a keyframe whose fix is in one of two rival groups


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
    ambiguous: int = 0  # keyframes not localised because their fixes agree on two places

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
    reasons = {i: "no verified match in the map" for i in range(n)}
    fixes = _best_fixes(map_poses, kf_ids, closures)
    if not fixes:
        return _nothing_localised(kf_ids, stamps, reasons, {}, None)
    comp = _main_component(fixes, component_of, reasons)
    path = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(T_odom[:, :3, 3], axis=0), axis=1))]
    order = sorted(fixes)
    pair = _pairs(order, fixes, map_poses, T_odom, path, conf)
    confirmed = _confirmed(order, pair, conf, reasons)
    settled = _settle_groups(order, confirmed, pair, conf, reasons)
    kept = {order[a]: fixes[order[a]] for a in settled}
    if kept:
        kept, poses = _joint_solve(kept, T_odom, cov, reasons)
    if not kept:
        return _nothing_localised(kf_ids, stamps, reasons, fixes, comp)
    out = []
    for i in range(n):
        c = fixes.get(i, (None, None))[0]
        out.append(KeyframeFix(int(kf_ids[i]), int(stamps[i]), i in kept, "ok" if i in kept else reasons[i],
                               int(c.match_id) if c is not None else None,
                               session_of.get(int(c.match_id)) if c is not None else None,
                               int(c.evidence.get("inliers", 0) or 0) if c is not None else None, poses[i]))
    return Localisation(out, Trajectory(np.asarray(stamps, np.int64), poses), comp, ambiguous=_n_ambiguous(reasons))


def _best_fixes(map_poses: dict, kf_ids: list[int], closures) -> dict[int, tuple]:
    """One fix per keyframe (index -> (closure, T_map_keyframe)): its match with most inliers."""
    index = {int(k): i for i, k in enumerate(kf_ids)}
    best: dict[int, LoopClosure] = {}
    for c in closures:
        q = int(c.query_id)
        if q in index and int(c.match_id) in map_poses and np.all(np.isfinite(c.T_match_query)):
            inl = int(c.evidence.get("inliers", 0) or 0)
            if q not in best or inl > int(best[q].evidence.get("inliers", 0) or 0):
                best[q] = c
    return {index[q]: (c, map_poses[int(c.match_id)] @ np.asarray(c.T_match_query, float)) for q, c in best.items()}


def _main_component(fixes: dict, component_of: dict, reasons: dict) -> int:
    """The map component most fixes point into (a log is localised in one frame); drops the others' fixes."""
    comps = [component_of[int(c.match_id)] for c, _ in fixes.values()]
    comp = max(set(comps), key=comps.count)
    for i in [i for i, (c, _) in fixes.items() if component_of[int(c.match_id)] != comp]:
        reasons[i] = f"matched a map component ({component_of[int(fixes[i][0].match_id)]}) the others do not"
        del fixes[i]
    return comp


@dataclass
class _Pairs:
    """Every two fixes compared (rows and columns in the fixes' keyframe order)."""

    agree: np.ndarray  # (k, k) bool: the two fixes agree through the odometry between them
    neighbours: np.ndarray  # (k, k) bool: within NEIGHBOURS keyframes (may confirm each other)
    near: np.ndarray  # (k, k) bool: close enough along the log to be linked into one group
    travelled: np.ndarray  # (k, k) metres the log travelled between the two
    separation: np.ndarray  # (k, k) metres between the places: map keyframes apart or log travelled
    view_deg: np.ndarray  # (k, k) degrees between the map keyframes' viewing directions


def _pairs(order: list[int], fixes: dict, map_poses: dict, T_odom: np.ndarray, path: np.ndarray,
           conf: MapConfig) -> _Pairs:
    """Compare every two fixes: agreement through the odometry, closeness on the log, their places' separation."""
    F = np.array([fixes[i][1] for i in order]).reshape(-1, 4, 4)
    odo = T_odom[order]
    s = path[order]
    mapped = np.array([map_poses[int(fixes[i][0].match_id)] for i in order]).reshape(-1, 4, 4)
    place, R = mapped[:, :3, 3], mapped[:, :3, :3]
    k = len(order)
    agree = np.zeros((k, k), bool)
    odo_inv = inv(odo)
    for a in range(k):
        # D = (odometry from a to j)^-1 (map from a to j): identity when the two fixes agree
        D = odo_inv @ (odo[a] @ inv(F[a])) @ F
        d = np.abs(s - s[a])
        agree[a] = ((np.linalg.norm(D[:, :3, 3], axis=1) <= conf.localize_max_disagreement_m * 0.5 + DRIFT_PER_M * d)
                    & (np.atleast_1d(rotation_angle_deg(D[:, :3, :3]))
                       <= conf.localize_max_disagreement_deg * 0.5 + DRIFT_DEG_PER_M * d))
    agree &= agree.T  # seen from either keyframe
    idx = np.asarray(order)
    gap = np.abs(idx[:, None] - idx[None, :])
    travelled = np.abs(s[:, None] - s[None, :])
    neighbours = (gap <= NEIGHBOURS) & (gap > 0)
    near = neighbours | ((travelled <= GROUP_WINDOW_M) & (gap > 0))
    separation = np.maximum(np.linalg.norm(place[:, None] - place[None, :], axis=2), travelled)
    # the angle of R_a^T R_b from its trace, sum(R_a * R_b): (k, k) at once, no (k, k, 3, 3) stack
    flat = R.reshape(-1, 9)
    view_deg = np.degrees(np.arccos(np.clip((flat @ flat.T - 1.0) / 2.0, -1.0, 1.0)))
    return _Pairs(agree, neighbours, near, travelled, separation, view_deg)


def _confirmed(order: list[int], pair: _Pairs, conf: MapConfig, reasons: dict) -> list[int]:
    """Fixes (rows of ``pair``) that a neighbouring fix to a distinct place confirms through the odometry."""
    distinct = (pair.separation >= conf.localize_min_place_separation_m) | (
        pair.view_deg >= conf.localize_min_view_angle_deg)
    ok = (pair.agree & pair.neighbours & distinct).any(axis=1)
    for a in np.flatnonzero(~ok):
        reasons[order[a]] = "fix not confirmed by a neighbouring fix to another place through the odometry"
    return [int(a) for a in np.flatnonzero(ok)]


def _groups(rows: list[int], pair: _Pairs) -> list[list[int]]:
    """Fixes linked by agreement, fix to nearby fix along the log: each group one hypothesis of where the log is."""
    if not rows:
        return []
    idx = np.asarray(rows, int)
    links = (pair.agree & pair.near)[np.ix_(idx, idx)]
    _, label = connected_components(csr_matrix(links), directed=False)
    return [idx[label == g].tolist() for g in np.unique(label)]


def _settle_groups(order: list[int], confirmed: list[int], pair: _Pairs, conf: MapConfig,
                   reasons: dict) -> list[int]:
    """The confirmed fixes kept: a group wins over a rival it clearly outnumbers; similar rivals are ambiguous.

    Groups are made of every fix, confirmed or not, and a group is judged against every rival, so
    that a few true fixes too close together to confirm themselves still stand against a long run
    of look-alike fixes. A group counts its confirmed fixes; one with none counts all its fixes
    (it has no others to show). Only a group's confirmed fixes are kept (the others already have
    their reason). Two groups are rivals when they disagree where the odometry between them is
    shortest: they cannot both be right. (Two groups that agree there are two stretches of one
    hypothesis.)
    """
    groups = _groups(list(range(len(order))), pair)
    sure = set(confirmed)

    def size(g: list[int]) -> int:  # its confirmed fixes; a group with none, all its fixes
        return sum(a in sure for a in g) or len(g)

    kept: list[int] = []
    for g in groups:
        mine = [a for a in g if a in sure]
        if not mine:
            continue
        rival = max((size(h) for h in groups if h is not g and _rivals(g, h, pair)), default=0)
        why = _verdict(len(mine), rival, conf.localize_min_group_ratio)
        if why is None:
            kept += mine
            continue
        for a in mine:
            reasons[order[a]] = why
    return sorted(kept)


def _verdict(size: int, rival: int, ratio: float) -> str | None:
    """None when a group of ``size`` fixes stands against its largest rival's ``rival`` fixes, else why not."""
    if rival == 0 or (size > rival and size >= ratio * rival):
        return None
    if rival > size and rival >= ratio * size:
        return f"fix disagrees with a larger group of fixes ({rival} against {size})"
    return f"{AMBIGUOUS}: {size} fixes agree on one place, {rival} on another"


def _rivals(g: list[int], h: list[int], pair: _Pairs) -> bool:
    """Whether groups ``g`` and ``h`` disagree at their fixes closest along the log."""
    between = pair.travelled[np.ix_(g, h)]
    a, b = np.unravel_index(int(np.argmin(between)), between.shape)
    return not pair.agree[g[a], h[b]]


def _joint_solve(kept: dict, T_odom: np.ndarray, cov: list, reasons: dict) -> tuple[dict, np.ndarray]:
    """Odometry between all keyframes, the kept fixes as priors: GNC drops the fixes the rest disagree with, LM
    gives every keyframe's map-frame pose. Returns the fixes that survive and the poses (N, 4, 4)."""
    n = len(T_odom)
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
    kept = dict(kept)
    if len(priors) >= 2:
        res = gnc_loop_weights(known, priors, values)
        for i, w in zip(order, res.weights, strict=True):
            if w < 0.5:
                reasons[i] = f"fix rejected by the joint solve (GNC weight {w:.2f})"
                del kept[i]
        values = res.values
    if not kept:
        return kept, np.zeros((0, 4, 4))
    graph = gtsam.NonlinearFactorGraph(known)
    for i in sorted(kept):
        graph.add(gtsam.PriorFactorPose3(i, gtsam.Pose3(kept[i][1]), information_noise(kept[i][0].information)))
    values = solve_lm(graph, values)
    return kept, np.array([values.atPose3(i).matrix() for i in range(n)]).reshape(-1, 4, 4)


def _n_ambiguous(reasons: dict[int, str]) -> int:
    return sum(r.startswith(AMBIGUOUS) for r in reasons.values())


def _nothing_localised(kf_ids, stamps, reasons: dict[int, str], fixes: dict, comp: int | None) -> Localisation:
    """Every keyframe "not localised", each with its reason; no trajectory (no fix to carry it from)."""
    out = []
    for i, k in enumerate(kf_ids):
        c = fixes.get(i, (None, None))[0]
        out.append(KeyframeFix(int(k), int(stamps[i]), False, reasons[i],
                               int(c.match_id) if c is not None else None, None,
                               int(c.evidence.get("inliers", 0) or 0) if c is not None else None, None))
    n_amb = _n_ambiguous(reasons)
    if not fixes:
        note = ("no keyframe of the log was matched to the map (is the log inside the mapped area, with the map's "
                "camera and features?)")
    elif n_amb:
        note = (f"{len(fixes)} keyframe(s) matched the map, but {n_amb} of their fixes fall into groups that agree "
                "among themselves and not with each other, none clearly larger: ambiguous (a look-alike place?)")
    else:
        note = (f"{len(fixes)} keyframe(s) matched the map but no two fixes to distinct places agree through the "
                "odometry (too few matches to trust)")
    return Localisation(out, Trajectory(np.zeros(0, np.int64), np.zeros((0, 4, 4))), comp, [note], n_amb)


def localise_pipeline(m, pipeline) -> Localisation:
    """:func:`localise` of a finished pipeline's keyframes against the map ``m`` (``Map.localise``)."""
    session_of, component_of = {}, {}
    for meta, s in zip(m.manifest.sessions, m.sessions, strict=True):
        for k in s.ids:
            session_of[int(k)] = meta["name"]
            component_of[int(k)] = int(meta["component"])
    kfs = list(pipeline.keyframes)
    if not kfs:
        raise MapError("the log gave no keyframe: nothing to localise", m.root)
    return localise(m.poses(), session_of, component_of, [k.id for k in kfs], [k.stamp for k in kfs],
                    np.array([k.T_world_body for k in kfs], float).reshape(-1, 4, 4),
                    [k.covariance_since_last for k in kfs], getattr(pipeline, "map_closures", []), m.conf)
