"""What `slam-lcd view` shows, read from folders slam-lcd already wrote (no rerun here, no re-run).

Why read and checked before anything is logged: a folder that is neither a run nor a map, or a
run folder with a file missing, is one line naming the path and the problem (an
:class:`~slam_lcd.errors.InputError`), and no recording is started. The readers are the
library's own (TUM files, ``map.ply``, the map's manifest and graph); ``loops.csv`` is read
against the header the runner writes (:func:`slam_lcd.outputs.loops.loop_columns`).

The run folder holds no keyframe images (the loop pictures' album is removed before the set is
published): ``view`` reads them from the log ``report.json`` names (or ``--log``) at the
keyframes' stamps (:mod:`.images`); where that log has moved, the frusta are drawn without
images and ``moved_log`` says so. ``slam-lcd run --rerun`` logs each keyframe's image and
keypoints while it still has them (:mod:`.live`).
"""
from __future__ import annotations

import csv
import json
import logging
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..cloud.files import read_cloud
from ..errors import FileMissingError, InputError, SlamLcdError
from ..eval.config import EvalConfig
from ..eval.metrics import ate_with_config
from ..io.trajectory_files import read_tum
from ..map.joint_types import FOLD
from ..map.store import is_map
from ..types import Trajectory

log = logging.getLogger(__name__)

# a run folder without these is not one `view` can show
RUN_FILES = ("report.json", "odometry.tum", "corrected.tum", "keyframes_corrected.tum", "loops.csv")
CLOUDS = {"corrected": "map.ply", "odometry": "map_odometry.ply"}
LOCALIZATION_FILES = ("report.json", "keyframes_localized.tum")


@dataclass
class RunFolder:
    """A finished run's outputs: trajectories, loops (``loops.csv`` rows), clouds, camera, ATE over time."""

    root: Path
    report: dict
    odometry: Trajectory
    corrected: Trajectory
    keyframes: Trajectory
    loops: list[dict]
    clouds: dict = field(default_factory=dict)  # "corrected" / "odometry" -> Cloud
    camera: dict | None = None  # report.json's map_cloud.sensor.camera (intrinsics, T_body_camera)
    ate: dict = field(default_factory=dict)  # "odometry" / "corrected" -> (stamps ns, errors m)
    notes: list[str] = field(default_factory=list)
    log: Path | None = None  # the run's log where it is now (report.json's, or --log); None: not found
    images: dict = field(default_factory=dict)  # keyframe stamp (ns) -> thumbnail (uint8), read from ``log``
    # keyframe stamp (ns, keyframes_corrected.tum's) -> (k, 2) pixels, from keyframe_keypoints.npz where the run kept it
    keypoints: dict = field(default_factory=dict)
    moved_log: str | None = None  # the one line that says the log is not where report.json says


@dataclass
class MapSession:
    name: str
    keyframes: Trajectory  # in the map frame (its component's)
    ids: np.ndarray
    component: int


@dataclass
class MapFolder:
    """A map folder: each session's keyframes in the map frame and every loop of the joint graph."""

    root: Path
    sessions: list[MapSession]
    loops: list[dict]  # query / match ids and sessions, accepted, reason, inter_session


@dataclass
class LocalizationFolder:
    root: Path
    name: str
    keyframes: Trajectory  # keyframes_localized.tum (map frame)
    localized: Trajectory | None  # localized.tum, every odometry stamp


def folder_kind(path: str | Path) -> str:
    """``'run'`` or ``'map'``; anything else is an :class:`InputError` naming the path."""
    p = Path(path)
    if not p.exists():
        raise FileMissingError("no such folder", p)
    if not p.is_dir():
        raise InputError("not a folder: give a run output folder (slam-lcd run --out) or a map folder (--map)", p)
    if is_map(p):
        return "map"
    if (p / "report.json").is_file():
        return "run"
    raise InputError("neither a slam-lcd run folder (no report.json) nor a map folder (no map.json)", p)


def _report(root: Path) -> dict:
    path = root / "report.json"
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError, UnicodeDecodeError) as e:
        raise InputError(f"not a readable slam-lcd report ({e.__class__.__name__})", path) from None
    if not isinstance(doc, dict) or "schema" not in doc:
        raise InputError("not a slam-lcd report (no schema)", path)
    return doc


def read_loops_csv(path: Path) -> list[dict]:
    """``loops.csv`` rows as dicts (strings), its header checked against the runner's."""
    from ..outputs.loops import loop_columns  # lazy: GTSAM

    try:
        with open(path, newline="", encoding="utf-8") as fh:
            reader = csv.DictReader(fh)
            missing = [c for c in ("query_id", "match_id", "query_stamp_ns", "match_stamp_ns", "backend_verdict")
                       if c not in (reader.fieldnames or [])]
            if missing:
                raise InputError(f"not a slam-lcd loops.csv (no column {', '.join(missing)}; expected "
                                 f"{len(loop_columns())} columns)", path)
            return list(reader)
    except (OSError, UnicodeDecodeError, csv.Error) as e:
        raise InputError(f"cannot read loops.csv ({e})", path) from None


def read_run(root: str | Path, *, ground_truth: bool = True, gt: Trajectory | None = None, images: bool = False,
             log_path: str | Path | None = None) -> RunFolder:
    """Read run folder ``root`` (typed errors naming the file). ``ground_truth``: read the log's ground
    truth (a topic of the log or a file, as report.json names it) for the ATE over time, when it is there;
    ``gt``: that ground truth already in hand (the run that just wrote the folder), not read again.
    ``images``: read each keyframe's image from the run's log; ``log_path``: that log, where report.json's
    path no longer leads (``view --log``)."""
    root = Path(root)
    missing = [n for n in RUN_FILES if not (root / n).is_file()]
    if missing:
        raise InputError(f"not a complete slam-lcd run folder (no {', '.join(missing)})", root)
    report = _report(root)
    run = RunFolder(root, report, read_tum(root / "odometry.tum"), read_tum(root / "corrected.tum"),
                    read_tum(root / "keyframes_corrected.tum"), read_loops_csv(root / "loops.csv"))
    listed = set(report.get("outputs") or [])
    for kind, name in CLOUDS.items():
        if (root / name).is_file():
            run.clouds[kind] = read_cloud(root / name)
        elif name in listed:
            raise InputError(f"the run's report lists {name} but the folder lacks it", root / name)
    _locate_log(run, log_path)
    sensor = (report.get("map_cloud") or {}).get("sensor") or {}
    run.camera = sensor.get("camera") or None
    if run.camera is None:
        run.notes.append("the run recorded no camera model: keyframes are shown as poses without frusta")
    if ground_truth:
        _add_ate(run, gt)
    if images:
        _add_images(run)
        _add_keypoints(run)
    return run


def _add_keypoints(run: RunFolder) -> None:
    """``run.keypoints`` from the run's keyframe_keypoints.npz (a run written without it: none), by the
    keyframes' stamps as keyframes_corrected.tum gives them (decimal seconds: matched to the nearest)."""
    from ..outputs.keypoints import KEYPOINTS_FILE, read_keyframe_keypoints
    from .images import STAMP_TOLERANCE_NS

    path = run.root / KEYPOINTS_FILE
    if not path.is_file():
        return
    kept = read_keyframe_keypoints(path)
    exact = np.array(sorted(kept), np.int64)
    if not len(exact):
        return
    for s in np.asarray(run.keyframes.stamps, np.int64):
        i = int(np.searchsorted(exact, s))
        j = min((k for k in (i - 1, i) if 0 <= k < len(exact)), key=lambda k: abs(int(exact[k]) - int(s)))
        if abs(int(exact[j]) - int(s)) <= STAMP_TOLERANCE_NS:
            run.keypoints[int(s)] = kept[int(exact[j])]


def _locate_log(run: RunFolder, given: str | Path | None) -> None:
    """``run.log``: ``given`` (it must exist), else the log report.json names when it is still there."""
    if given is not None:
        if not Path(given).exists():
            raise FileMissingError("no such log (--log)", given)
        run.log = Path(given)
        return
    named = (run.report.get("input") or {}).get("log")
    if named and Path(named).exists():
        run.log = Path(named)
    elif named:
        gt_topic = str((run.report.get("input") or {}).get("gt_source") or "").startswith("topic ")
        what = "its keyframe images and the ATE over time are" if gt_topic else "its keyframe images are"
        run.moved_log = (f"{named}: the run's log is not there (moved?): {what} not shown; give its place "
                         "with --log PATH")


def _add_images(run: RunFolder) -> None:
    from .images import read_keyframe_images

    topic = ((run.report.get("input") or {}).get("topics") or {}).get("image")
    if run.log is None or not topic:
        return
    source = ((run.report.get("config") or {}).get("io") or {}).get("stamp_source") or "header"
    run.images = read_keyframe_images(run.log, topic, run.keyframes.stamps, source)
    if len(run.images) < len(run.keyframes):
        run.notes.append(f"{len(run.keyframes) - len(run.images)} of {len(run.keyframes)} keyframes have no image "
                         f"on {topic} of {run.log} at their stamps")


def _ground_truth(run: RunFolder) -> Trajectory | None:
    """The run's ground truth as report.json names it (``file PATH`` / ``topic NAME`` of its log), or None."""
    from ..sensors.trajectories import load_trajectory_source  # lazy: OpenCV

    source = (run.report.get("input") or {}).get("gt_source") or ""
    kind, _, name = source.partition(" ")
    if kind == "file":
        return load_trajectory_source(name)
    if kind == "topic":
        if run.log is None:
            named = (run.report.get("input") or {}).get("log")
            raise FileMissingError("the run's log is not here (its ground truth is not read)", named or "?")
        return load_trajectory_source(f"{run.log}:{name}")
    return None


def _add_ate(run: RunFolder, gt: Trajectory | None = None) -> None:
    """Per-pose ATE of the odometry and the corrected trajectory, with the run's own evaluation settings."""
    ev = run.report.get("eval") or {}
    try:
        gt = gt if gt is not None else _ground_truth(run)
        if gt is None:
            run.notes.append("no ground truth: no ATE over time")
            return
        align = str(ev.get("alignment", "se3")).split(";")[0].strip()
        conf = EvalConfig(align=align if align in ("none", "se3", "sim3", "scale") else "se3",  # type: ignore[arg-type]
                          t_max_diff=float(ev.get("t_max_diff_s", 0.02)), t_offset=float(ev.get("t_offset_s", 0.0)))
        for kind, traj in (("odometry", run.odometry), ("corrected", run.corrected)):
            res = ate_with_config(gt, traj, conf)
            run.ate[kind] = (np.asarray(res.stamps, np.int64), np.asarray(res.errors, float))
    except (SlamLcdError, ValueError) as e:  # a moved log, a ground truth that does not match: said, not fatal
        run.notes.append(f"ATE over time not shown: {e}")
        log.info("ATE over time not shown: %s", e)


def read_map(root: str | Path) -> MapFolder:
    """Map folder ``root``, read only (no lock): sessions in the map frame and the joint graph's loops."""
    from ..map.session_map import Map  # lazy: GTSAM

    root = Path(root)
    m = Map.open(root)
    try:
        session_of: dict[int, str] = {}
        sessions = []
        for i, meta in enumerate(m.manifest.sessions):
            s = m.sessions[i]
            sessions.append(MapSession(meta["name"], m.session_trajectory(i), np.asarray(s.ids, np.int64).copy(),
                                       int(meta.get("component", 0))))
            session_of.update({int(k): meta["name"] for k in s.ids})
        g = m.graph
        loops = []
        for q, t, ok, why in zip(g.loop_query, g.loop_match, g.loop_accepted, g.loop_reason, strict=True):
            if str(why) == FOLD:  # folded keyframes' factors: graph edges, not loops that were seen
                continue
            qs, ts = session_of.get(int(q), "?"), session_of.get(int(t), "?")
            loops.append({"query_id": int(q), "match_id": int(t), "query_session": qs, "match_session": ts,
                          "accepted": bool(ok), "reason": str(why), "inter_session": qs != ts})
    finally:
        m.close()
    return MapFolder(root, sessions, loops)


def read_localization(root: str | Path) -> LocalizationFolder:
    """A ``slam-lcd localize`` output folder: its keyframes (and every stamp) in the map frame."""
    root = Path(root)
    if not root.is_dir():
        raise FileMissingError("no such localize output folder", root)
    missing = [n for n in LOCALIZATION_FILES if not (root / n).is_file()]
    if missing:
        raise InputError(f"not a slam-lcd localize output folder with localised keyframes (no {', '.join(missing)})",
                         root)
    full = root / "localized.tum"
    return LocalizationFolder(root, root.name, read_tum(root / "keyframes_localized.tum"),
                              read_tum(full) if full.is_file() else None)
