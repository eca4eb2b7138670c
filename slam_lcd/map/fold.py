"""Folding a lifelong map's dropped keyframes out of its joint graph: the graph follows places, not visits.

A keyframe a lifelong map no longer keeps as a candidate (no descriptors: :mod:`.lifelong`) still
has a variable in the joint graph, with its odometry steps, loops and visual links, so the graph
grows with every visit. Folding removes such a variable, as generic node removal does
(Carlevaris-Bianco, Kaess, Eustice, T-RO 2014):

1. **Which.** A dropped keyframe folds once every factor that touches it is *settled*: made at
   least ``map.fold_after_appends`` appends ago (a loop between two sessions counts from the later
   one's append, when its pair was judged). A loop of a recent pair stays raw, so that a later
   contradiction can still judge it again. A whole session may fold (a visit that added no view).
2. **Marginalise.** The factors touching a connected group of such keyframes are linearised at the
   map's solution and the group is eliminated (``eliminatePartialMultifrontal``): what is left is
   the exact Gaussian marginal on the group's blanket, the variables it touched.
3. **Relative factors, not dense ones.** The marginal is re-expressed as a spanning tree of
   ``BetweenFactorPose3`` over the blanket, each with the marginal's covariance of its relative
   pose, measured at the map's solution: every folded factor is satisfied there, so the graph's
   optimum stays where it was, but for the pull the removed factors had on the raw ones that
   stay (a millimetre on a chain that a loop bends by decimetres). Why not the marginal's own
   mean, or measurements that keep the marginal's pull at the solution: the groups folded at
   once pull against each other and against the factors that stay, and a tree, which leaves out
   part of the information, turns those pulls into residuals of metres on its weak edges; on the
   twenty-day benchmark either moved every session by about 5 cm.
4. **Merge.** Folded factors between the same two variables merge by adding their information.

A folded keyframe's pose in the map frame follows the variables nearest to it: where the joint
solution put it when it was folded, moved as they move since (:func:`fill_folded`): every session
stays given at full rate.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import gtsam
import numpy as np
from scipy.spatial import cKDTree

from ..geometry import inv
from .config import MapConfig
from .joint_types import FOLD, JointLoop, SessionPoses
from .pair_verdicts import SessionGraphs
from .pcm import SessionChains
from .session_factors import between


@dataclass
class FoldReport:
    """What one fold did: keyframes folded, raw factors removed and folded ones added, and what it cost."""

    keyframes: int = 0
    removed: int = 0  # raw loops and links removed (odometry steps are not stored as factors)
    added: int = 0  # folded factors after merging
    kl_nats: float = 0.0  # KL divergence of the trees from the exact marginals, summed over the groups
    by_pair: dict[frozenset, int] = field(default_factory=dict)  # raw loops removed, per pair of session names


def settled(age_of_session: dict[int, int], after: int, *sessions: int) -> bool:
    """A factor of these sessions is settled when the latest of them was appended ``after`` appends ago or more."""
    return min(age_of_session[s] for s in sessions) >= after


def foldable(sessions: list[SessionPoses], loops: list[JointLoop], dropped: dict[int, np.ndarray],
             conf: MapConfig) -> set[int]:
    """The keyframes to fold now: dropped (``dropped[si]``: a session's mask), not folded yet, not a session's
    first, in a session ``map.fold_after_appends`` appends old, with every loop touching them settled."""
    n = len(sessions)
    age = {si: n - 1 - si for si in range(n)}
    where = {int(k): si for si, s in enumerate(sessions) for k in s.ids}
    out: set[int] = set()
    for si, s in enumerate(sessions):
        if age[si] < conf.fold_after_appends or si not in dropped:
            continue
        mask = np.asarray(dropped[si], bool) & ~_folded(s)
        out.update(int(k) for k in s.ids[mask])
    for lp in loops:  # a loop of a recent pair keeps both its ends
        a, b = where.get(int(lp.query)), where.get(int(lp.match))
        if a is None or b is None or not settled(age, conf.fold_after_appends, a, b):
            out.discard(int(lp.query))
            out.discard(int(lp.match))
    return out


def _folded(s: SessionPoses) -> np.ndarray:
    return np.zeros(len(s.ids), bool) if s.folded is None else np.asarray(s.folded, bool)


def _adjoint(T: np.ndarray) -> np.ndarray:
    return gtsam.Pose3(T).AdjointMap()


def fold(sessions: list[SessionPoses], loops: list[JointLoop], poses: dict[int, np.ndarray], drop: set[int],
         conf: MapConfig) -> tuple[list[JointLoop], FoldReport]:
    """Fold ``drop`` out of the graph (module docstring): the loops that stay, with the folded factors, and what it
    did. ``poses``: the map's solution (the linearisation point); each session's ``folded`` mask is updated."""
    report = FoldReport()
    if not drop:
        return loops, report
    chains = SessionChains(sessions, conf)
    graphs = SessionGraphs(sessions, loops, chains)
    dropped = np.fromiter(drop, np.int64, len(drop))
    holding = [si for si, s in enumerate(sessions) if np.isin(s.ids, dropped).any()]  # a session's own factors
    factors = [f for si in holding for f in graphs.factors_of(si)]  # touch its keyframes only
    factors += [between(lp) for lp in loops
                if lp.inter and lp.accepted and (int(lp.query) in drop or int(lp.match) in drop)]
    touching = [f for f in factors if any(int(k) in drop for k in f.keys())]
    values = gtsam.Values()
    for f in touching:
        for k in f.keys():
            if not values.exists(k):
                values.insert(k, gtsam.Pose3(poses[int(k)]))
    session_of = {int(k): si for si, s in enumerate(sessions) for k in s.ids}
    new: list[JointLoop] = []
    for group in _groups(touching, drop):
        tree, kl = _tree(group, drop, values, session_of)
        new += tree
        report.kl_nats += kl
    names = [s.name for s in sessions]
    kept: list[JointLoop] = []
    for lp in loops:
        if int(lp.query) in drop or int(lp.match) in drop:
            if lp.reason != FOLD:
                report.removed += 1
            if lp.inter and lp.reason != FOLD:
                pair = frozenset((names[session_of[int(lp.query)]], names[session_of[int(lp.match)]]))
                report.by_pair[pair] = report.by_pair.get(pair, 0) + 1
            continue
        kept.append(lp)
    for s in sessions:
        s.folded = _folded(s) | np.isin(s.ids, dropped)
    merged = merge_parallel([lp for lp in kept if lp.reason == FOLD] + new)
    report.keyframes, report.added = len(drop), len(merged)
    return [lp for lp in kept if lp.reason != FOLD] + merged, report


def _groups(touching: list, drop: set[int]) -> list[list]:
    """The factors touching ``drop``, by connected group of dropped keyframes."""
    parent: dict[int, int] = {}

    def find(k: int) -> int:
        while parent.setdefault(k, k) != k:
            parent[k] = parent[parent[k]]
            k = parent[k]
        return k

    for f in touching:
        ks = [int(k) for k in f.keys() if int(k) in drop]
        for k in ks[1:]:
            parent[find(k)] = find(ks[0])
    out: dict[int, list] = {}
    for f in touching:
        k = next(int(k) for k in f.keys() if int(k) in drop)
        out.setdefault(find(k), []).append(f)
    return list(out.values())


def _tree(group: list, drop: set[int], values: gtsam.Values, session_of: dict[int, int]) -> tuple[list, float]:
    """One group's exact marginal on its blanket, as a spanning tree of relative factors; and the tree's KL."""
    lin = gtsam.GaussianFactorGraph()
    for f in group:
        lin.push_back(f.linearize(values))
    gone = sorted({int(k) for f in group for k in f.keys() if int(k) in drop})
    blanket = sorted({int(k) for f in group for k in f.keys() if int(k) not in drop})
    if len(blanket) < 2:
        return [], 0.0  # a group that touches one variable only adds nothing relative
    order = gtsam.Ordering()
    for k in gone:
        order.push_back(k)
    _, rest = lin.eliminatePartialMultifrontal(order)
    keep = gtsam.Ordering()
    for k in blanket:
        keep.push_back(k)
    H = rest.hessian(keep)[0]
    H = 0.5 * (H + H.T)
    X = [values.atPose3(k).matrix() for k in blanket]
    Sigma = np.zeros_like(H)
    Sigma[6:, 6:] = np.linalg.pinv(H[6:, 6:], hermitian=True)  # the first blanket variable fixed (the gauge)
    b = len(blanket)
    edges = []
    for i in range(b):
        for j in range(i + 1, b):
            z = inv(X[i]) @ X[j]
            J = np.hstack([-_adjoint(inv(z)), np.eye(6)])
            idx = np.r_[6 * i:6 * i + 6, 6 * j:6 * j + 6]
            cov = J @ Sigma[np.ix_(idx, idx)] @ J.T
            cov = 0.5 * (cov + cov.T)
            sign, logdet = np.linalg.slogdet(cov)
            inter = session_of[blanket[i]] != session_of[blanket[j]]
            edges.append((inter, logdet if sign > 0 else np.inf, i, j, z, cov))
    edges.sort(key=lambda e: (e[0], e[1]))
    parent = list(range(b))

    def find(k: int) -> int:
        while parent[k] != k:
            parent[k] = parent[parent[k]]
            k = parent[k]
        return k

    tree, total = [], 0.0
    for inter, logdet, i, j, z, cov in edges:
        if find(i) == find(j) or not np.isfinite(logdet):
            continue
        parent[find(i)] = find(j)
        total += logdet
        tree.append((inter, i, j, z, np.linalg.inv(cov)))
    out = [JointLoop(blanket[j], blanket[i], z, info, inter, True, FOLD) for inter, i, j, z, info in tree]
    _, logdet_all = np.linalg.slogdet(Sigma[6:, 6:])
    return out, max(0.0, 0.5 * (total - logdet_all))


def merge_parallel(factors: list[JointLoop]) -> list[JointLoop]:
    """Folded factors between the same two variables merged into one: information added, the mean weighted
    by it (on the tangent space of the first)."""
    by_pair: dict[tuple[int, int], JointLoop] = {}
    for lp in factors:
        key = (min(lp.match, lp.query), max(lp.match, lp.query))
        T, info = np.asarray(lp.T, float), np.asarray(lp.info, float)
        if (lp.match, lp.query) != key:  # the same relative pose seen the other way round
            A = np.linalg.inv(_adjoint(T))
            T, info = inv(T), A.T @ info @ A
        have = by_pair.get(key)
        if have is None:
            by_pair[key] = JointLoop(key[1], key[0], T, info, lp.inter, True, FOLD)
            continue
        total = have.info + info
        xi = gtsam.Pose3.Logmap(gtsam.Pose3(inv(have.T) @ T))
        step = np.linalg.solve(total, info @ xi)
        have.T = gtsam.Pose3(have.T).retract(step).matrix()
        have.info = 0.5 * (total + total.T)
    return list(by_pair.values())


NEAREST = 3  # variables whose motion a folded keyframe follows


def fill_folded(sessions: list[SessionPoses], comp: dict[int, int], poses: dict[int, np.ndarray]) -> None:
    """The folded keyframes' poses in ``poses``: where the previous solve put them (``T_init``, the joint solution
    when they were folded, carried on), moved as the nearest variables around them moved since (``comp``:
    session index -> component; the variables of the sessions that lay in the same frame before).

    Why the nearest in space and not the session's own variables along its chain: a visit that added one or two
    views keeps one or two variables, tens of metres from most of its keyframes, and a tenth of a degree of
    their rotation moved those keyframes by centimetres. The variables nearest a keyframe are the views of its
    place; their motion is the map's deformation there. Each of the nearest :data:`NEAREST` moves the keyframe
    as a rigid offset from itself; the positions are averaged weighted by inverse distance (plus 0.5 m), the
    orientation is the nearest one's."""
    groups: dict[tuple, list[tuple[SessionPoses, np.ndarray]]] = {}  # one call per group, not per session
    for si, s in enumerate(sessions):
        if (folded := _folded(s)).any():
            groups.setdefault((comp[si], s.prev_component), []).append((s, folded))
    for key, members in groups.items():
        P, ids = _references(sessions, comp, *key)
        prev = np.concatenate([np.asarray(s.T_init, float)[f] for s, f in members])
        out = _follow(prev, P, np.array([poses[k] for k in ids]).reshape(-1, 4, 4))
        folded_ids = np.concatenate([s.ids[f] for s, f in members])
        poses.update({int(k): T for k, T in zip(folded_ids, out, strict=True)})


def _references(sessions: list[SessionPoses], comp: dict[int, int], c: int, prev_component) -> tuple:
    """The variables of component ``c`` whose sessions lay in ``prev_component`` before: where they lay, their ids."""
    P, ids = [], []
    for oi, o in enumerate(sessions):
        if comp[oi] != c or prev_component is None or o.prev_component != prev_component:
            continue
        live = o.in_graph()
        P.append(np.asarray(o.T_init, float)[live])
        ids += [int(k) for k in o.ids[live]]
    return (np.concatenate(P) if P else np.zeros((0, 4, 4))), ids


def _follow(prev: np.ndarray, P: np.ndarray, X: np.ndarray) -> np.ndarray:
    """(n, 4, 4) poses ``prev`` moved as the nearest of the variables that lay at ``P`` and lie at ``X`` now."""
    if not len(P):
        return prev.copy()
    d, near = cKDTree(P[:, :3, 3]).query(prev[:, :3, 3], k=min(NEAREST, len(P)))  # nearest first
    d, near = d.reshape(len(prev), -1), near.reshape(len(prev), -1)
    C = (X @ inv(P))[near]  # (n, k, 4, 4): each variable's motion since
    moved = C @ prev[:, None]
    w = 1.0 / (d + 0.5)
    out = moved[:, 0].copy()
    out[:, :3, 3] = np.einsum("nk,nkj->nj", w / w.sum(1, keepdims=True), moved[:, :, :3, 3])
    return out


__all__ = ["FoldReport", "fill_folded", "fold", "foldable", "merge_parallel"]
