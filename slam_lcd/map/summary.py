"""What a map holds, in figures: sessions, components, loops within and between sessions, ATE per session.

ATE in the common frame (needs the ground truth a session was recorded with, kept per keyframe
in the map for evaluation only): the keyframe positions of every session of one component are
aligned to their ground truth with **one** SE(3) (Umeyama), and each session's RMSE is read
off that alignment; beside it, the session's odometry ATE with its own SE(3) alignment (what
the session would score alone, without the map).
"""
from __future__ import annotations

from typing import Any

import numpy as np

from ..eval.align import umeyama
from .joint_types import FOLD, LINK
from .lifelong import counts


def _rmse(P: np.ndarray, G: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum((P - G) ** 2, axis=1)))) if len(P) else float("nan")


def _aligned(P: np.ndarray, G: np.ndarray) -> np.ndarray:
    R, t, s = umeyama(P, G, with_scale=False)
    return s * (P @ R.T) + t


def session_ates(m) -> dict[str, dict]:
    """Per session: ``ate_map`` (one SE(3) per component), ``ate_odometry`` (own SE(3)), keyframes with GT."""
    poses = m.poses()
    by_comp: dict[int, list[int]] = {}
    for i, meta in enumerate(m.manifest.sessions):
        by_comp.setdefault(int(meta["component"]), []).append(i)
    out: dict[str, dict] = {}
    for comp, idx in by_comp.items():
        P_all, G_all, spans = [], [], []
        for i in idx:
            s = m.sessions[i]
            ok = np.all(np.isfinite(s.T_gt[:, :3, 3]), axis=1)
            P = np.array([poses[int(k)][:3, 3] for k in s.ids])[ok] if poses else np.zeros((0, 3))
            G = s.T_gt[ok, :3, 3]
            spans.append((i, len(P)))
            P_all.append(P)
            G_all.append(G)
        P_cat, G_cat = np.concatenate(P_all), np.concatenate(G_all)
        aligned = _aligned(P_cat, G_cat) if len(P_cat) >= 3 else None
        start = 0
        for (i, n), G in zip(spans, G_all, strict=True):
            s = m.sessions[i]
            name = m.manifest.sessions[i]["name"]
            ok = np.all(np.isfinite(s.T_gt[:, :3, 3]), axis=1)
            odo = s.T_odom[ok, :3, 3]
            entry: dict[str, Any] = {"keyframes_with_gt": int(n), "component": comp}
            if aligned is not None and n >= 3:
                entry["ate_map"] = _rmse(aligned[start:start + n], G)
                entry["ate_odometry"] = _rmse(_aligned(odo, G), G)
                entry["ratio"] = entry["ate_map"] / entry["ate_odometry"] if entry["ate_odometry"] > 0 else None
            start += n
            out[name] = entry
    return out


def gt_alignment(m, component: int = 0):
    """(R, t) taking this component's map frame to the ground truth's frame, from the sessions' keyframe GT; or None."""
    P, G = [], []
    poses = m.poses()
    for meta, s in zip(m.manifest.sessions, m.sessions, strict=True):
        if int(meta["component"]) != component:
            continue
        ok = np.all(np.isfinite(s.T_gt[:, :3, 3]), axis=1)
        P += [poses[int(k)][:3, 3] for k in s.ids[ok]]
        G += list(s.T_gt[ok, :3, 3])
    if len(P) < 3:
        return None
    R, t, _ = umeyama(np.array(P), np.array(G), with_scale=False)
    return R, t


def map_summary(m, joined=None, *, current: str | None = None, pipe=None) -> dict:
    """The map as report.json / ``map info`` give it (plain JSON types)."""
    sess_of = {int(k): m.manifest.sessions[si]["name"] for si, s in enumerate(m.sessions) for k in s.ids}
    gt_of = {int(k): s.T_gt[i, :3, 3] for s in m.sessions for i, k in enumerate(s.ids)}
    g = m.graph
    inter: list[dict[str, Any]] = []  # JSON rows
    within = accepted_within = links = folded = 0
    for q, mt, acc, why in zip(g.loop_query, g.loop_match, g.loop_accepted, g.loop_reason, strict=True):
        a, b = sess_of.get(int(mt)), sess_of.get(int(q))
        if str(why) == FOLD:  # dropped keyframes' factors marginalised (slam_lcd.map.fold), not a loop
            folded += 1
            continue
        if str(why).startswith(LINK):  # a visual link between consecutive keyframes (or a dropped one), not a loop
            links += bool(acc)
            continue
        if a == b:
            within += 1
            accepted_within += bool(acc)
            continue
        # ground-truth distance between the two keyframes (sessions recorded with ground truth in one frame)
        d = float(np.linalg.norm(gt_of[int(q)] - gt_of[int(mt)])) if int(q) in gt_of and int(mt) in gt_of else None
        inter.append({"query_id": int(q), "match_id": int(mt), "query_session": b, "match_session": a,
                      "accepted": bool(acc), "reason": str(why),
                      "gt_distance_m": round(d, 4) if d is not None and np.isfinite(d) else None})
    ates = session_ates(m)
    first_comp = int(m.manifest.sessions[0]["component"]) if m.manifest.sessions else 0
    sessions = []
    for meta, s in zip(m.manifest.sessions, m.sessions, strict=True):
        name = meta["name"]
        n_inter = sum(1 for r in inter if r["accepted"] and name in (r["query_session"], r["match_session"]))
        entry = {"name": name, "keyframes": len(s), "kept_keyframes": int(s.kept().sum()),
                 "bytes": int(m.manifest.files.get(meta.get("file", ""), {}).get("bytes", 0)),
                 "component": int(meta["component"]),
                 "joined": int(meta["component"]) == first_comp, "inter_session_loops": n_inter,
                 "log_path": meta.get("log_path"), **ates.get(name, {})}
        if not entry["joined"]:
            entry["note"] = ("never met the map's first session: kept in its own frame "
                             f"(component {meta['component']})")
        sessions.append(entry)
    pairs: dict[str, int] = {}
    for r in inter:
        if r["accepted"]:
            key = " - ".join(sorted((r["query_session"], r["match_session"])))
            pairs[key] = pairs.get(key, 0) + 1
    return {"root": str(m.root), "appended": current is not None, "current_session": current,
            "current": _current(m, current, sessions) if current is not None else None,
            **counts(m.graph, m.sessions), "lifelong": m.graph.kf_place is not None,
            "growth": [{"session": t["name"], "keyframes": t.get("map_keyframes_after"),
                        "kept_keyframes": t.get("map_kept_after"), "bytes": t.get("map_bytes_after")}
                       for t in m.manifest.sessions],
            "sessions": sessions, "components": m.components(), "n_keyframes": m.n_keyframes,
            "loops_within_sessions": accepted_within, "loops_within_sessions_offered": within, "visual_links": links,
            "folded_keyframes": len(g.folded_ids()), "folded_factors": folded,
            "inter_session_loops": inter, "inter_session_accepted_by_pair": pairs,
            "inter_session_accepted": sum(1 for r in inter if r["accepted"]), "pairs": pair_verdicts(m)}


def pair_verdicts(m) -> list[dict]:
    """The recorded verdict on each pair of sessions with loops between them (the session table's records)."""
    from .pair_verdicts import judged_pairs

    return [{"sessions": list(names), "decision": r.get("decision"), "offered": r.get("offered"),
             "largest": r.get("largest"), "kept": r.get("kept"), "status": r.get("status"), "reason": r.get("reason"),
             "folded": r.get("folded", 0)}
            for names, r in judged_pairs(m.manifest.sessions).items()]


def _current(m, name: str, sessions: list[dict]) -> dict:
    """This run's session in the map: its loops the joint graph accepted (within it and to other sessions), its ATE."""
    ids = {int(k) for k in m.sessions[m.session_names.index(name)].ids}
    g = m.graph
    within = sum(1 for q, mt, acc, why in zip(g.loop_query, g.loop_match, g.loop_accepted, g.loop_reason, strict=True)
                 if acc and not str(why).startswith((LINK, FOLD)) and int(q) in ids and int(mt) in ids)
    entry = next(s for s in sessions if s["name"] == name)
    return {"name": name, "joined": entry["joined"], "component": entry["component"],
            "loops_accepted": within + entry["inter_session_loops"], "within_session_loops": within,
            "inter_session_loops": entry["inter_session_loops"], "ate_odometry": entry.get("ate_odometry"),
            "ate_map": entry.get("ate_map")}


def summary_lines(summary: dict) -> list[str]:
    """A map summary as the CLI prints it."""
    if not summary.get("appended", True) and summary.get("reason"):
        return [f"map {summary['root']}: unchanged ({summary['reason']})"]
    kept = (f" ({summary['kept_keyframes']} kept: {summary['places']} places, {summary['variants']} more variants)"
            if summary.get("lifelong") else "")
    lines = [f"map {summary['root']}: {len(summary['sessions'])} sessions, {summary['n_keyframes']} keyframes{kept}, "
             f"{summary['inter_session_accepted']} loops between sessions accepted "
             f"({len(summary['inter_session_loops'])} offered), {len(summary['components'])} component(s)"]
    if summary.get("folded_keyframes"):
        lines.append(f"  joint graph: {summary['graph_variables']} variables, {summary['graph_factors']} factors "
                     f"({summary['folded_keyframes']} keyframes folded into {summary['folded_factors']} factors)")
    for s in summary["sessions"]:
        ate = ""
        if s.get("ate_map") is not None:
            ate = f", ATE {s['ate_odometry']:.3f} -> {s['ate_map']:.3f} m (map frame, one alignment)"
        lines.append(f"  {s['name']}: {s['keyframes']} keyframes, {s['inter_session_loops']} loops to other "
                     f"sessions{ate}" + ("" if s["joined"] else f" -- {s['note']}"))
    for p in summary.get("pairs", []):
        why = f": {p['reason']}" if p["decision"] != "joined" and p.get("reason") else ""
        again = " (re-judged: the joint graph contradicted it)" if p.get("status") == "re-judged" else ""
        lines.append(f"  pair {p['sessions'][0]} - {p['sessions'][1]}: {p['decision']}, {p['kept']} of "
                     f"{p['offered']} loops kept{again}{why}")
    return lines


def localisation_report(m, loc, gt=None) -> dict:
    """Figures of a localisation: share localised, reasons, and with ground truth the position errors.

    Errors need the map's own ground truth (kept per keyframe): the map frame is aligned to the
    ground truth's frame once, from the map's keyframes (never from the localised log), and each
    localised keyframe's position is compared with its ground truth at that stamp.
    """
    from ..geometry import interpolate_poses  # lazy: scipy

    ks = loc.keyframes
    reasons: dict[str, int] = {}
    for k in ks:
        if not k.localised:
            key = k.reason.split(" (")[0]
            reasons[key] = reasons.get(key, 0) + 1
    out = {"map": str(m.root), "keyframes": len(ks), "localised": sum(k.localised for k in ks),
           "share_localised": loc.share_localised, "component": loc.component, "not_localised_reasons": reasons,
           "ambiguous": loc.ambiguous, "notes": list(loc.notes), "errors": None, "_loc": loc}
    al = gt_alignment(m, loc.component or 0)
    if gt is not None and len(gt) > 1 and al is not None and len(loc.trajectory):
        R, t = al
        stamps = np.array([k.stamp for k in ks], np.int64)
        inside = (stamps >= gt.stamps[0]) & (stamps <= gt.stamps[-1])
        err = np.full(len(ks), np.nan)
        if inside.any():
            G = interpolate_poses(gt.stamps, gt.poses, stamps[inside])[:, :3, 3]
            P = np.array([k.T_map[:3, 3] for k in ks])[inside] @ R.T + t
            err[inside] = np.linalg.norm(P - G, axis=1)
        for k, e in zip(ks, err, strict=True):
            k.error_m = float(e) if np.isfinite(e) else None
        e_loc = np.array([e for k, e in zip(ks, err, strict=True) if k.localised and np.isfinite(e)])
        e_all = err[np.isfinite(err)]
        out["errors"] = {"median_m": float(np.median(e_loc)) if len(e_loc) else None,
                         "max_m": float(e_loc.max()) if len(e_loc) else None,
                         "over_1m": int((e_loc > 1.0).sum()),
                         "all_keyframes_median_m": float(np.median(e_all)) if len(e_all) else None}
    return out


def localisation_lines(rep: dict) -> list[str]:
    lines = [f"localised {rep['localised']} of {rep['keyframes']} keyframes ({100 * rep['share_localised']:.1f} %) "
             f"against {rep['map']}"]
    for why, n in rep["not_localised_reasons"].items():
        lines.append(f"  not localised: {n} ({why})")
    lines += [f"  {note}" for note in rep.get("notes", [])]
    e = rep.get("errors")
    if e and e["median_m"] is not None:
        lines.append(f"position error of localised keyframes: median {e['median_m']:.3f} m, max {e['max_m']:.3f} m, "
                     f"{e['over_1m']} over 1 m")
    return lines
