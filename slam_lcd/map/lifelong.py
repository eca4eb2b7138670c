"""A map that grows with the place, not with the days: keeping places and variants at every append.

:mod:`slam_lcd.map.places` judges keyframes; this module applies its verdicts to a map's arrays:
the keyframes it does not keep lose their descriptors, keypoints and 3-D points
(``points_source`` becomes :data:`~slam_lcd.map.contents.REMOVED`) and keep their id, stamp,
odometry and ground truth, so every session is still given in the map frame at full rate; the
graph file records each keyframe's place and when it was last matched; the vocabulary snapshot
keeps the kept keyframes' bags of words and the words they use. ``map.lifelong`` turns this on
for appends; ``Map.compact`` applies it to a map built without it, session by session in the
order they were appended, as if each had been appended with it, and to a map that keeps places
already from its records (:func:`compact`).

The joint graph follows: once the loops touching a dropped keyframe are settled, it is folded out
of the graph (:func:`fold_graph`, :mod:`slam_lcd.map.fold`), so the graph's size follows the places
and the last few visits, not every visit.
"""
from __future__ import annotations

import logging
from collections.abc import Collection
from dataclasses import replace

import numpy as np

from ..lcd.config import LcdConfig
from .contents import REMOVED, MapGraph, SessionKeyframes
from .fold import FoldReport, fold, foldable
from .keyframe_arrays import camera_from_json
from .place_geometry import Localises, stored_view
from .places import Kept, Ratios, Verdicts, appearance_of, familiarity, judge, prune
from .session_graph import existing_loops, loop_arrays, session_poses

log = logging.getLogger(__name__)


def strip(sess: SessionKeyframes, keep: np.ndarray) -> SessionKeyframes:
    """``sess`` with the features of the keyframes not in ``keep`` dropped (their poses stay); ``sess`` itself
    when that drops nothing it still holds (the caller rewrites a session's file only when it changed)."""
    keep = np.asarray(keep, bool) & sess.kept()
    if np.array_equal(keep, sess.kept()) or not len(sess):
        return sess
    n = np.diff(sess.offsets)
    rows = np.repeat(keep, n)
    offsets = np.concatenate([[0], np.cumsum(np.where(keep, n, 0))]).astype(np.int64)
    src = np.where(keep, sess.points_source, REMOVED).astype("<U10")
    return replace(sess, offsets=offsets, keypoints=sess.keypoints[rows], descriptors=sess.descriptors[rows],
                   scales=sess.scales[rows] if len(sess.scales) else sess.scales, points3d=sess.points3d[rows],
                   points_source=src)


def camera_pose(T_map_body: np.ndarray, meta: dict) -> np.ndarray:
    return np.asarray(T_map_body, float) @ np.asarray(meta.get("T_body_camera", np.eye(4).tolist()), float)


def kept_keyframes(table: list[dict], sessions: list[SessionKeyframes], graph: MapGraph,
                   poses: dict[int, np.ndarray], components: dict[str, int]) -> tuple[list[Kept], int]:
    """The map's kept keyframes for :func:`slam_lcd.map.places.judge`, and the first free place id.

    A map without place records (built without ``map.lifelong``) gives each kept keyframe a place of
    its own; ``map compact`` judges such a map's sessions properly. In the order the keyframes were
    added (session by session, by id), which :func:`slam_lcd.map.places.prune` follows."""
    place = dict(zip(graph.kf_ids.tolist(), graph.kf_place.tolist(), strict=True)) if graph.kf_place is not None \
        else {}
    used = dict(zip(graph.kf_ids.tolist(), graph.kf_last_used.tolist(), strict=True)) \
        if graph.kf_last_used is not None else {}
    look = dict(zip(graph.kf_ids.tolist(), graph.kf_appearance.tolist(), strict=True)) \
        if graph.kf_appearance is not None else {}
    out: list[Kept] = []
    next_place = max([p for p in place.values() if p >= 0], default=-1) + 1
    for si, (meta, s) in enumerate(zip(table, sessions, strict=True)):
        camera = camera_from_json(meta.get("camera"))
        for i in np.flatnonzero(s.kept()):
            k = int(s.ids[i])
            p = place.get(k, -1)
            if p < 0:
                p, next_place = next_place, next_place + 1
            out.append(Kept(k, camera_pose(poses[k], meta), components[meta["name"]], p, int(used.get(k, si + 1)),
                            _descriptors(s, int(i)), max(0, int(look.get(k, 0))), _view(s, int(i), camera)))
    return out, next_place


def _descriptors(s: SessionKeyframes, i: int):
    return lambda: s.descriptors_of(i)


def _view(s: SessionKeyframes, i: int, camera):
    """Keyframe i's keypoints and 3-D points for the pose check (:mod:`slam_lcd.map.place_geometry`)."""
    r = s.rows(i)
    return stored_view(s.keypoints[r], s.points3d[r], str(s.points_source[i]), camera)


def judge_session(meta: dict, sess: SessionKeyframes, component: int, poses: dict[int, np.ndarray],
                  kept: list[Kept], conf, now: int, next_place: int, used: Collection[int] = (),
                  only: np.ndarray | None = None, pose_conf: LcdConfig | None = None) -> Verdicts:
    """Judge a session's keyframes (module docstring of :mod:`slam_lcd.map.places`); ``used``: map keyframes
    its accepted loops matched (marked used now, before the judging, so a place's variant in use stays);
    ``only``: the keyframes to judge (default all; the others are not kept); ``pose_conf``: the ``lcd``
    settings whose pose stage says whether a kept view would localise a new one (default ones)."""
    for k in kept:
        if k.kf_id in used:
            k.last_used = now
    which = np.ones(len(sess), bool) if only is None else np.asarray(only, bool)
    new = [(int(sess.ids[i]), camera_pose(poses[int(sess.ids[i])], meta), _descriptors(sess, int(i)))
           for i in np.flatnonzero(which)]
    camera = camera_from_json(meta.get("camera"))
    views = {int(sess.ids[i]): _view(sess, int(i), camera) for i in np.flatnonzero(which)}
    ratios = Ratios()
    known, own = familiarity(new, component, kept, conf, ratios)
    look, fresh = appearance_of(known, own, kept, conf)
    out = judge(new, component, kept, conf, now, next_place, look, ratios, views, Localises(pose_conf))
    out.new_appearance = fresh
    log.info("session %s: median match ratio with the kept appearances %s, %s with itself: %s %d; %d variants "
             "kept because the matching view would not localise them", meta.get("name"),
             {a: round(v, 2) for a, v in sorted(known.items())}, "-" if own is None else f"{own:.2f}",
             "a new appearance" if fresh else "judged in appearance", look, len(out.reason))
    out.used |= set(used)
    return out


def apply(kept: list[Kept], sessions: list[SessionKeyframes],
          graph: MapGraph) -> tuple[list[SessionKeyframes], set[int], MapGraph]:
    """The sessions with every keyframe not in ``kept`` stripped, the indices of the sessions that changed, and
    the graph with every keyframe's place (-1: not kept) and last use."""
    keep_ids = {k.kf_id for k in kept}
    changed, out = set(), []
    for si, s in enumerate(sessions):
        mask = np.array([int(k) in keep_ids for k in s.ids])
        new = strip(s, mask)
        if new is not s:
            changed.add(si)
        out.append(new)
    place = {k.kf_id: k.place for k in kept}
    last = {k.kf_id: k.last_used for k in kept}
    look = {k.kf_id: k.appearance for k in kept}
    ids = graph.kf_ids.tolist()
    g = replace(graph, kf_place=np.array([place.get(int(k), -1) for k in ids], np.int64),
                kf_last_used=np.array([last.get(int(k), -1) for k in ids], np.int64),
                kf_appearance=np.array([look.get(int(k), -1) for k in ids], np.int64))
    return out, changed, g


def reduce_append(table: list[dict], sessions: list[SessionKeyframes], old_graph: MapGraph, new_graph: MapGraph,
                  result, meta: dict, sess: SessionKeyframes, loops, conf,
                  pose_conf: LcdConfig | None = None) -> tuple[list[SessionKeyframes], set[int], MapGraph]:
    """An append's verdicts applied: (every session after it, the indices that changed, the graph with places).

    ``table``/``sessions``/``old_graph``: the map before the append; ``new_graph``, ``result``: after its
    joint solve; ``loops``: every loop of that solve (the session's accepted ones to the map mark their
    map keyframe used); ``pose_conf``: the ``lcd`` settings of the pose check (:func:`judge_session`)."""
    kept, next_place = kept_keyframes(table, sessions, old_graph, result.poses, result.component)
    judge_session(meta, sess, int(result.component[meta["name"]]), result.poses, kept, conf, len(sessions) + 1,
                  next_place, _used_by(loops, {int(k) for k in sess.ids}), pose_conf=pose_conf)
    return apply(kept, [*sessions, sess], new_graph)


def compact(table: list[dict], sessions: list[SessionKeyframes], graph: MapGraph, poses: dict[int, np.ndarray],
            loops, conf, pose_conf: LcdConfig | None = None) -> tuple[list[SessionKeyframes], set[int], MapGraph]:
    """A map reduced by the rules: (every session after it, the indices that changed, the graph with places).

    A map built without ``map.lifelong`` is reduced as if each session had been appended with it, in order
    (with the map's present poses). A map that keeps places already keeps its records (the graph's
    ``kf_place``, ``kf_appearance``, ``kf_last_used``) and loses only what the rules drop now
    (:func:`slam_lcd.map.places.prune`: a smaller ``map.max_variants``, poses moved by later appends).
    Why not judge its kept keyframes again: they lie too far apart for a session's own ratio, so the
    appearances would merge (night views judged as days) and every last use would be that of the judging.
    Either way a view is dropped only when the view that stays would localise it (``pose_conf``: the ``lcd``
    settings of that check, :mod:`slam_lcd.map.place_geometry`), as at an append."""
    if graph.kf_place is not None:
        views, _ = kept_keyframes(table, sessions, graph, poses, {m["name"]: int(m["component"]) for m in table})
        prune(views, conf, localises=Localises(pose_conf))
        return apply(views, sessions, graph)
    kept: list[Kept] = []
    for si, (meta, s) in enumerate(zip(table, sessions, strict=True)):
        earlier = {int(k) for t in sessions[:si] for k in t.ids}
        used = {k for k in _used_by(loops, {int(k) for k in s.ids}) if k in earlier}
        next_place = max((k.place for k in kept), default=-1) + 1
        judge_session(meta, s, int(meta["component"]), poses, kept, conf, si + 1, next_place, used, only=s.kept(),
                      pose_conf=pose_conf)
    return apply(kept, sessions, graph)


def fold_graph(table: list[dict], sessions: list[SessionKeyframes], graph: MapGraph,
               conf) -> tuple[MapGraph, FoldReport]:
    """The map's graph with its settled dropped keyframes folded out (:mod:`slam_lcd.map.fold`), and what was
    folded (``report.by_pair``: raw loops folded per pair of sessions, for the pairs' records). A map that keeps
    every keyframe, or ``map.fold_after_appends`` 0: as it is."""
    if not conf.fold_after_appends or graph.kf_place is None:
        return graph, FoldReport()
    poses = {int(k): T for k, T in zip(graph.kf_ids, graph.T_map, strict=True)}
    loops = existing_loops(sessions, graph)
    sp = session_poses(table, sessions, poses, loops, conf, graph.folded_ids())
    drop = foldable(sp, loops, {si: ~s.kept() for si, s in enumerate(sessions)}, conf)
    if not drop:
        return graph, FoldReport()
    loops, report = fold(sp, loops, poses, drop, conf)
    log.info("folded %d keyframes out of the joint graph: %d raw loops and links removed, %d folded factors "
             "(KL %.2f nats)", report.keyframes, report.removed, report.added, report.kl_nats)
    folded = np.concatenate([s.folded if s.folded is not None else np.zeros(len(s.ids), bool) for s in sp])
    order = {int(k): i for i, k in enumerate(np.concatenate([s.ids for s in sp]))}
    out = replace(graph, kf_folded=folded[[order[int(k)] for k in graph.kf_ids]], **loop_arrays(loops))
    return out, report


def count_folded(records: list, by_pair: dict[frozenset, int]) -> None:
    """Add the loops folded per pair (``by_pair``) to the pairs' verdicts (``PairDecision`` or its record)."""
    for r in records:
        names = frozenset(r.sessions if hasattr(r, "sessions") else r["sessions"])
        n = by_pair.get(names, 0)
        if not n:
            continue
        if hasattr(r, "folded"):
            r.folded += n
        else:
            r["folded"] = int(r.get("folded", 0)) + n


def _used_by(loops, ids: set[int]) -> set[int]:
    """The keyframes outside ``ids`` that accepted loops between sessions match from a keyframe in ``ids``."""
    return {int(lp.match) if int(lp.query) in ids else int(lp.query) for lp in loops
            if lp.inter and lp.accepted and (int(lp.query) in ids) != (int(lp.match) in ids)}


def array_bytes(sessions: list[SessionKeyframes], graph: MapGraph, vocab: dict | None) -> int:
    """Bytes of the map's arrays (its files hold them uncompressed): the size a map reaches, as it grows."""
    n = sum(getattr(s, k).nbytes for s in sessions for k in SessionKeyframes.ARRAYS)
    n += sum(a.nbytes for a in graph.arrays().values())
    return int(n + sum(np.asarray(a).nbytes for a in (vocab or {}).values()))


def counts(graph: MapGraph, sessions: list[SessionKeyframes]) -> dict:
    """Places, variants (kept keyframes beyond the first of their place), appearances, kept / total keyframes, and
    the joint graph's variables and factors (odometry steps between variables, accepted loops, links and folded
    factors)."""
    kept = int(sum(int(s.kept().sum()) for s in sessions))
    total = int(sum(len(s) for s in sessions))
    places = len({int(p) for p in graph.kf_place if p >= 0}) if graph.kf_place is not None else kept
    looks = len({int(a) for a in graph.kf_appearance if a >= 0}) if graph.kf_appearance is not None else int(kept > 0)
    gone = graph.folded_ids()
    live = [np.array([int(k) not in gone for k in s.ids], bool) for s in sessions]
    steps = sum(int((v[1:] & v[:-1]).sum()) for v in live)
    return {"places": places, "variants": kept - places, "appearances": looks, "kept_keyframes": kept,
            "keyframes": total, "graph_variables": int(sum(v.sum() for v in live)),
            "graph_factors": steps + int(np.count_nonzero(graph.loop_accepted))}


__all__ = ["apply", "compact", "count_folded", "counts", "fold_graph", "judge_session", "kept_keyframes",
           "reduce_append", "strip"]
