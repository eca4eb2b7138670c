"""What a map holds, in figures: sessions, components, loops within and between sessions, ATE per session.

ATE in the common frame (needs the ground truth a session was recorded with, kept per keyframe
in the map for evaluation only): the keyframe positions of every session of one component are
aligned to their ground truth with **one** SE(3) (Umeyama), and each session's RMSE is read
off that alignment; beside it, the session's odometry ATE with its own SE(3) alignment (what
the session would score alone, without the map).
"""
from __future__ import annotations

import numpy as np

from ..eval.align import umeyama


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
        for (i, n), P, G in zip(spans, P_all, G_all):
            s = m.sessions[i]
            name = m.manifest.sessions[i]["name"]
            ok = np.all(np.isfinite(s.T_gt[:, :3, 3]), axis=1)
            odo = s.T_odom[ok, :3, 3]
            entry = {"keyframes_with_gt": int(n), "component": comp}
            if aligned is not None and n >= 3:
                entry["ate_map"] = _rmse(aligned[start:start + n], G)
                entry["ate_odometry"] = _rmse(_aligned(odo, G), G)
                entry["ratio"] = entry["ate_map"] / entry["ate_odometry"] if entry["ate_odometry"] > 0 else None
            start += n
            out[name] = entry
    return out


def map_summary(m, joined=None, *, current: str | None = None, pipe=None) -> dict:
    """The map as report.json / ``map info`` give it (plain JSON types)."""
    sess_of = {int(k): m.manifest.sessions[si]["name"] for si, s in enumerate(m.sessions) for k in s.ids}
    g = m.graph
    inter = []
    within = accepted_within = 0
    for q, mt, acc, why in zip(g.loop_query, g.loop_match, g.loop_accepted, g.loop_reason):
        a, b = sess_of.get(int(mt)), sess_of.get(int(q))
        if a == b:
            within += 1
            accepted_within += bool(acc)
            continue
        inter.append({"query_id": int(q), "match_id": int(mt), "query_session": b, "match_session": a,
                      "accepted": bool(acc), "reason": str(why)})
    ates = session_ates(m)
    first_comp = int(m.manifest.sessions[0]["component"]) if m.manifest.sessions else 0
    sessions = []
    for meta, s in zip(m.manifest.sessions, m.sessions):
        name = meta["name"]
        n_inter = sum(1 for r in inter if r["accepted"] and name in (r["query_session"], r["match_session"]))
        entry = {"name": name, "keyframes": len(s), "component": int(meta["component"]),
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
            "sessions": sessions, "components": m.components(), "n_keyframes": m.n_keyframes,
            "loops_within_sessions": accepted_within, "loops_within_sessions_offered": within,
            "inter_session_loops": inter, "inter_session_accepted_by_pair": pairs,
            "inter_session_accepted": sum(1 for r in inter if r["accepted"])}


def summary_lines(summary: dict) -> list[str]:
    """A map summary as the CLI prints it."""
    if not summary.get("appended", True) and summary.get("reason"):
        return [f"map {summary['root']}: unchanged ({summary['reason']})"]
    lines = [f"map {summary['root']}: {len(summary['sessions'])} sessions, {summary['n_keyframes']} keyframes, "
             f"{summary['inter_session_accepted']} loops between sessions accepted "
             f"({len(summary['inter_session_loops'])} offered), {len(summary['components'])} component(s)"]
    for s in summary["sessions"]:
        ate = ""
        if s.get("ate_map") is not None:
            ate = f", ATE {s['ate_odometry']:.3f} -> {s['ate_map']:.3f} m (map frame, one alignment)"
        lines.append(f"  {s['name']}: {s['keyframes']} keyframes, {s['inter_session_loops']} loops to other "
                     f"sessions{ate}" + ("" if s["joined"] else f" -- {s['note']}"))
    return lines
