"""Log a run folder, a map folder and a localisation into a Rerun recording stream.

Entity paths (the docs' table, docs/viewer.md, and the tests read them back):

- ``world/odometry``, ``world/corrected``: the trajectories (static line strips);
- ``world/keyframes``: the corrected keyframe positions (static); ``world/keyframes/camera``: one row
  per keyframe on the ``stamp`` timeline (the corrected pose, a Pinhole frustum when the run
  recorded its camera, and the keyframe's image, a thumbnail read from the run's log, when found);
- ``world/loops/accepted``, ``world/loops/rejected``: one segment per ``loops.csv`` row, query to
  match keyframe, with the row's ids, score, inliers and reason as any-values on the same entity;
  ``loops/events``: a text line per loop at its query stamp; ``loops/table``: a markdown table;
- ``world/map/corrected``, ``world/map/odometry``: ``map.ply`` and ``map_odometry.ply``;
- ``ate/odometry``, ``ate/corrected``: the ATE of each pose over time (with ground truth);
- a map: ``world/sessions/<name>/trajectory``, ``.../keyframes`` (with a pose per keyframe on the
  timeline), the joint graph's loops under ``world/loops/...``, a localisation under
  ``world/localized/<name>``.

Why the whole trajectories are static and only the keyframe poses are on the timeline: what the
estimate was at a past moment is not kept in the run folder, so a trajectory "growing" along the
timeline would show the final estimate anyway; the keyframe frusta moving along it show where
the camera was at each stamp.
"""
from __future__ import annotations

import numpy as np

from ..geometry import interpolate_poses
from ..io.trajectory_files import read_tum
from . import TIMELINE, require_rerun
from .folders import LocalizationFolder, MapFolder, RunFolder
from .images import jpeg

ACCEPTED_RGB = (40, 200, 80)
BACKEND_REJECTED_RGB = (230, 50, 50)  # verified by the detector, rejected by the back end
NOT_VERIFIED_RGB = (240, 150, 40)  # rejected by the detector's checks
SESSION_RGB = [(31, 119, 180), (255, 127, 14), (44, 160, 44), (148, 103, 189), (214, 39, 40), (140, 86, 75),
               (227, 119, 194), (23, 190, 207), (188, 189, 34), (127, 127, 127)]
TABLE_ROWS = 200  # the markdown table lists at most this many loops (the any-values hold every one)
FRUSTUM_M = 0.3  # image plane distance of a keyframe frustum
KEYFRAME_CAMERA = "world/keyframes/camera"


def seconds(stamps_ns) -> np.ndarray:
    return np.asarray(stamps_ns, np.int64).astype(np.float64) * 1e-9


def log_pinhole_pose(rec, path: str, T_world_camera: np.ndarray, camera: dict | None,
                     image: np.ndarray | None = None, keypoints: np.ndarray | None = None) -> None:
    """A camera at ``T_world_camera`` (its frustum when the intrinsics are known), with ``image`` (a
    thumbnail: the frustum is scaled to its width) when given, and ``keypoints`` (full-size pixels) on it."""
    rr = require_rerun()
    parts = [rr.Transform3D(translation=T_world_camera[:3, 3], mat3x3=T_world_camera[:3, :3])]
    if camera:
        s = image.shape[1] / float(camera["width"]) if image is not None else 1.0
        parts.append(rr.Pinhole(focal_length=[float(camera["fx"]) * s, float(camera["fy"]) * s],
                                principal_point=[float(camera["cx"]) * s, float(camera["cy"]) * s],
                                width=round(int(camera["width"]) * s), height=round(int(camera["height"]) * s),
                                camera_xyz=rr.ViewCoordinates.RDF, image_plane_distance=FRUSTUM_M))
    data = jpeg(image) if image is not None else None
    if data is not None:
        parts.append(rr.EncodedImage(contents=data, media_type="image/jpeg"))
    rec.log(path, *parts)
    if data is not None and keypoints is not None and camera:
        s = image.shape[1] / float(camera["width"])  # type: ignore[union-attr]  # data: image given
        rec.log(f"{path}/keypoints", rr.Points2D(np.asarray(keypoints, np.float32) * s, colors=[(255, 220, 0)],
                                                 radii=[1.0]))


def body_camera(camera: dict | None) -> np.ndarray:
    return np.asarray(camera["T_body_camera"], float) if camera and camera.get("T_body_camera") else np.eye(4)


def log_run(rec, run: RunFolder, *, frusta: bool = True) -> None:
    """Everything of ``run`` (see the module docstring); ``frusta=False`` leaves the per-keyframe
    cameras out (the live recorder logged them already, with images)."""
    rr = require_rerun()
    rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
    rec.log("world/odometry", rr.LineStrips3D([run.odometry.positions], colors=[(150, 150, 150)], radii=[0.01]),
            static=True)
    rec.log("world/corrected", rr.LineStrips3D([run.corrected.positions], colors=[(31, 119, 180)], radii=[0.015]),
            static=True)
    kf = run.keyframes
    rec.log("world/keyframes", rr.Points3D(kf.positions, colors=[(31, 119, 180)], radii=[0.04]), static=True)
    if frusta:
        T_bc = body_camera(run.camera)
        for i in range(len(kf)):
            rec.set_time(TIMELINE, timestamp=seconds(kf.stamps[i : i + 1])[0])
            stamp = int(kf.stamps[i])
            log_pinhole_pose(rec, KEYFRAME_CAMERA, kf.poses[i] @ T_bc, run.camera, run.images.get(stamp),
                             run.keypoints.get(stamp))
        rec.reset_time()
    for kind, cloud in run.clouds.items():
        colours = cloud.colours if kind == "corrected" else np.full_like(cloud.colours, 140)
        rec.log(f"world/map/{kind}", rr.Points3D(cloud.points, colors=colours, radii=[0.02]), static=True)
    for kind, (stamps, errors) in run.ate.items():
        if len(stamps):
            rec.send_columns(f"ate/{kind}", indexes=[rr.TimeColumn(TIMELINE, timestamp=seconds(stamps))],
                             columns=rr.Scalars.columns(scalars=np.asarray(errors, float)))
    log_run_loops(rec, run)
    text = [f"# {run.root.name}", "", run_summary_line(run.report)] + [f"- {n}" for n in run.notes]
    rec.log("info", rr.TextDocument("\n".join(text), media_type=rr.MediaType.MARKDOWN), static=True)


def run_summary_line(report: dict) -> str:
    h = report.get("headline") or {}
    ate = (f"; ATE {h['ate_before_m']:.3f} m -> {h['ate_after_m']:.3f} m"
           if h.get("ate_before_m") is not None and h.get("ate_after_m") is not None else "")
    return (f"{report.get('frames', '?')} frames, {report.get('keyframes', '?')} keyframes, "
            f"{h.get('loops_accepted', '?')} loops accepted{ate}")


def _float(row: dict, key: str) -> float:
    try:
        return float(row.get(key) or "nan")
    except ValueError:
        return float("nan")


def _endpoint_frames(run: RunFolder) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Keyframe stamps and positions to draw loop ends from: this run's, and (a run into a map) each
    earlier session's as the run folder's ``map/<session>.tum`` gives them."""
    frames = {"": (run.keyframes.stamps, run.keyframes.poses)}
    for s in {r.get("match_session") or "" for r in run.loops} - {""}:
        p = run.root / "map" / f"{s}.tum"
        if p.is_file():
            t = read_tum(p)
            frames[s] = (t.stamps, t.poses)
    return frames


def _loop_ends(rows: list[dict], frames: dict[str, tuple[np.ndarray, np.ndarray]]) -> list[tuple]:
    """Each loop's query and match positions, interpolated at their stamps (one call per session: a
    call per loop cost a second on the 2-lap demo's candidates)."""
    q = interpolate_poses(*frames[""], np.array([int(r["query_stamp_ns"]) for r in rows], np.int64))[:, :3, 3] \
        if rows else np.zeros((0, 3))
    m = np.zeros((len(rows), 3))
    sessions = np.array([r.get("match_session") or "" for r in rows])
    for s in set(sessions.tolist()):
        idx = np.flatnonzero(sessions == s)
        stamps = np.array([int(rows[i]["match_stamp_ns"]) for i in idx], np.int64)
        m[idx] = interpolate_poses(*frames[s], stamps)[:, :3, 3]
    return list(zip(q, m, strict=True))


def log_run_loops(rec, run: RunFolder) -> None:
    """``loops.csv`` as segments coloured by verdict, any-values, a text line per loop and a table."""
    rr = require_rerun()
    frames = _endpoint_frames(run)
    groups: dict[str, list] = {"accepted": [], "rejected": []}
    drawn = [r for r in run.loops if (r.get("match_session") or "") in frames]  # the others: said in the table
    ends = _loop_ends(drawn, frames)
    for r, (q, m) in zip(drawn, ends, strict=True):
        ok = r.get("backend_verdict") == "accepted"
        groups["accepted" if ok else "rejected"].append((r, q, m))
    for verdict, rows in groups.items():
        if not rows:
            continue
        colours = [ACCEPTED_RGB if verdict == "accepted" else
                   BACKEND_REJECTED_RGB if r.get("verdict") == "accepted" else NOT_VERIFIED_RGB for r, _, _ in rows]
        inliers = [r.get("pose_inliers") or r.get("ransac_inliers") or "" for r, _, _ in rows]
        rec.log(f"world/loops/{verdict}",
                rr.LineStrips3D([np.stack([q, m]) for _, q, m in rows], colors=colours, radii=[0.02]),
                rr.AnyValues(query_id=[int(r["query_id"]) for r, _, _ in rows],
                             match_id=[int(r["match_id"]) for r, _, _ in rows],
                             match_session=[r.get("match_session") or "" for r, _, _ in rows],
                             bow_score=[_float(r, "bow_score") for r, _, _ in rows],
                             inliers=[int(float(x)) if x else -1 for x in inliers],
                             detector_verdict=[r.get("verdict") or "" for r, _, _ in rows],
                             reason=[_reason(r) for r, _, _ in rows]),
                static=True)
    for r in run.loops:
        rec.set_time(TIMELINE, timestamp=seconds([int(r["query_stamp_ns"])])[0])
        ok = r.get("backend_verdict") == "accepted"
        rec.log("loops/events", rr.TextLog(f"loop {r['query_id']} -> {r['match_id']}: "
                                           f"{'accepted' if ok else 'rejected'} ({_reason(r)})",
                                           level=rr.TextLogLevel.INFO if ok else rr.TextLogLevel.WARN))
    rec.reset_time()
    rec.log("loops/table", rr.TextDocument(_run_table(run), media_type=rr.MediaType.MARKDOWN), static=True)


def _reason(r: dict) -> str:
    """The back end's reason for a verified loop, the detector's for one it rejected."""
    return (r.get("backend_reason") or r.get("reason") or "") if r.get("verdict") == "accepted" \
        else (r.get("reason") or "")


def _run_table(run: RunFolder) -> str:
    """The loop table: accepted loops first, then those the back end rejected, then the detector's
    rejections (most of a run's candidates, and the least looked at)."""
    rows = sorted(run.loops, key=lambda r: 0 if r.get("backend_verdict") == "accepted" else
                  1 if r.get("verdict") == "accepted" else 2)
    acc = sum(r.get("backend_verdict") == "accepted" for r in rows)
    lines = [f"**{len(rows)} loop candidates**: {acc} accepted, {len(rows) - acc} rejected", "",
             "| query | match | session | verdict | BoW score | inliers | reason |", "|---|---|---|---|---|---|---|"]
    for r in rows[:TABLE_ROWS]:
        ok = "accepted" if r.get("backend_verdict") == "accepted" else "rejected"
        lines.append(f"| {r['query_id']} | {r['match_id']} | {r.get('match_session') or ''} | {ok} | "
                     f"{_float(r, 'bow_score'):.3f} | {r.get('pose_inliers') or r.get('ransac_inliers') or ''} | "
                     f"{_reason(r).replace('|', '/')} |")
    if len(rows) > TABLE_ROWS:
        lines.append(f"\n... {len(rows) - TABLE_ROWS} more (every loop is in world/loops/* as any-values)")
    return "\n".join(lines)


def log_map(rec, m: MapFolder) -> None:
    """Each session in its own colour in the map frame, and every loop of the joint graph by verdict."""
    rr = require_rerun()
    rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
    where: dict[int, np.ndarray] = {}
    for i, s in enumerate(m.sessions):
        rgb = SESSION_RGB[i % len(SESSION_RGB)]
        base = f"world/sessions/{s.name}"
        pos = s.keyframes.positions
        rec.log(f"{base}/trajectory", rr.LineStrips3D([pos], colors=[rgb], radii=[0.015]), static=True)
        rec.log(f"{base}/keyframes", rr.Points3D(pos, colors=[rgb], radii=[0.04]),
                rr.AnyValues(keyframe_id=s.ids, component=np.full(len(s.ids), s.component)), static=True)
        rec.send_columns(f"{base}/pose", indexes=[rr.TimeColumn(TIMELINE, timestamp=seconds(s.keyframes.stamps))],
                         columns=rr.Points3D.columns(positions=pos).partition(np.ones(len(pos), int)))
        where.update({int(k): p for k, p in zip(s.ids, pos, strict=True)})
    for verdict, ok in (("accepted", True), ("rejected", False)):
        rows = [r for r in m.loops if r["accepted"] == ok and r["query_id"] in where and r["match_id"] in where]
        if not rows:
            continue
        colours = [(ACCEPTED_RGB if ok else BACKEND_REJECTED_RGB) if r["inter_session"] else
                   ((120, 200, 140) if ok else (230, 150, 150)) for r in rows]
        rec.log(f"world/loops/{verdict}",
                rr.LineStrips3D([np.stack([where[r["query_id"]], where[r["match_id"]]]) for r in rows],
                                colors=colours, radii=[0.03 if r["inter_session"] else 0.015 for r in rows]),
                rr.AnyValues(**{k: [r[k] for r in rows] for k in ("query_id", "match_id", "query_session",
                                                                   "match_session", "inter_session", "reason")}),
                static=True)
    rec.log("loops/table", rr.TextDocument(_map_table(m), media_type=rr.MediaType.MARKDOWN), static=True)


def _map_table(m: MapFolder) -> str:
    inter = [r for r in m.loops if r["inter_session"]]
    lines = [f"**{len(m.sessions)} sessions** ({', '.join(s.name for s in m.sessions)}); "
             f"{len(m.loops)} loops, {len(inter)} between sessions "
             f"({sum(r['accepted'] for r in inter)} accepted)", "",
             "| query (session) | match (session) | verdict | reason |", "|---|---|---|---|"]
    for r in (inter + [r for r in m.loops if not r["inter_session"]])[:TABLE_ROWS]:
        lines.append(f"| {r['query_id']} ({r['query_session']}) | {r['match_id']} ({r['match_session']}) | "
                     f"{'accepted' if r['accepted'] else 'rejected'} | {r['reason'].replace('|', '/')} |")
    return "\n".join(lines)


def log_localization(rec, loc: LocalizationFolder) -> None:
    """A localised log in the map frame: its keyframes, its full-rate poses and a pose per keyframe stamp."""
    rr = require_rerun()
    base = f"world/localized/{loc.name}"
    pos = loc.keyframes.positions
    rec.log(f"{base}/keyframes", rr.Points3D(pos, colors=[(0, 0, 0)], radii=[0.05]), static=True)
    if loc.localized is not None:
        rec.log(f"{base}/trajectory", rr.LineStrips3D([loc.localized.positions], colors=[(0, 0, 0)], radii=[0.01]),
                static=True)
    rec.send_columns(f"{base}/pose", indexes=[rr.TimeColumn(TIMELINE, timestamp=seconds(loc.keyframes.stamps))],
                     columns=rr.Points3D.columns(positions=pos).partition(np.ones(len(pos), int)))
