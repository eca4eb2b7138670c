"""``slam-lcd export-map``: the map's point cloud rebuilt from a finished run and its log, with other settings.

Why from the log and not from ``map.ply``: another voxel size (finer than the run's) or depth
range needs the sensor's own pixels again. The run folder says everything else: ``report.json``
names the log, the topics and the camera the run's cloud was built with (``map_cloud.sensor``:
intrinsics, mounting, the calibration files of a pair that was rectified), and
``keyframes_corrected.tum`` (or, with ``odometry=True``, ``odometry.tum``) gives the poses.
The log is read once; only the keyframes' messages are decoded. The keyframes go through the
run's own :class:`~slam_lcd.cloud.MapCloudBuilder` (same settings: the same points as ``map.ply``).

Bad input fails before anything is written, in one line naming the file: a folder that is not
a run, a run without a cloud's sensor, a log that is gone, an output on an input.
"""
from __future__ import annotations

import json
import logging
from pathlib import Path

import numpy as np

from ..cloud import MapCloudBuilder, MapCloudConfig, write_cloud
from ..cloud.files import cloud_suffix
from ..errors import FileMissingError, InputError
from ..files.atomic import check_no_clash, check_writable_target
from ..io import open_log
from ..sensors.rectify import stereo_rectifier
from ..types import CameraModel, Keyframe
from ..vision.gray import image_to_gray

log = logging.getLogger(__name__)

STAMP_TOLERANCE_NS = 1_000_000  # TUM files keep stamps to the microsecond or so: a keyframe's messages within 1 ms


def read_run_poses(run_dir: Path, odometry: bool = False) -> tuple[dict, np.ndarray, np.ndarray]:
    """``(report, keyframe stamps, keyframe poses)`` of a run folder (typed errors naming the file)."""
    from ..io.trajectory_files import read_trajectory  # lazy: scipy, like the others in this module

    report_path = run_dir / "report.json"
    if not run_dir.is_dir():
        raise FileMissingError("no such run folder", run_dir)
    if not report_path.is_file():
        raise InputError("not a slam-lcd run folder (no report.json)", run_dir)
    try:
        report = json.loads(report_path.read_text(encoding="utf-8"))
        report["input"]["log"]
    except (ValueError, KeyError, TypeError, UnicodeDecodeError):
        raise InputError("not a slam-lcd run report (unreadable, or no input log)", report_path) from None
    sensor = (report.get("map_cloud") or {}).get("sensor")
    if not sensor or not sensor.get("camera"):
        why = (report.get("map_cloud") or {}).get("reason") or "the run recorded no camera for a map cloud"
        raise InputError(f"this run has no map cloud to rebuild ({why})", report_path)
    kf_path = run_dir / "keyframes_corrected.tum"
    if not kf_path.is_file():
        raise InputError("not a complete slam-lcd run folder (no keyframes_corrected.tum)", run_dir)
    kf = read_trajectory(kf_path, "tum")
    poses = kf.poses
    if odometry:
        from ..geometry import interpolate_poses

        odo_path = run_dir / "odometry.tum"
        if not odo_path.is_file():
            raise InputError("not a complete slam-lcd run folder (no odometry.tum)", run_dir)
        odo = read_trajectory(odo_path, "tum")
        poses = interpolate_poses(odo.stamps, odo.poses, kf.stamps)
    return report, kf.stamps, poses


def _camera(sensor: dict) -> tuple[CameraModel, np.ndarray]:
    c = sensor["camera"]
    cam = CameraModel(width=int(c["width"]), height=int(c["height"]), fx=c["fx"], fy=c["fy"], cx=c["cx"], cy=c["cy"],
                      distortion_model=c.get("distortion_model", "none"), D=np.asarray(c.get("D", []), float),
                      baseline=c.get("baseline"))
    return cam, np.asarray(c["T_body_camera"], float)


def _near(stamps: np.ndarray, s: int) -> int | None:
    """Index of the keyframe stamp within :data:`STAMP_TOLERANCE_NS` of ``s``, or None."""
    i = int(np.searchsorted(stamps, s))
    best = min((j for j in (i - 1, i) if 0 <= j < len(stamps)), key=lambda j: abs(int(stamps[j]) - s), default=None)
    return best if best is not None and abs(int(stamps[best]) - s) <= STAMP_TOLERANCE_NS else None


def keyframe_frames(log_path: Path, sensor: dict, stamps: np.ndarray, io_conf=None):
    """``(keyframe index, grey, colour | None, depth | None, right | None)`` for each keyframe found in the log."""
    from ..sensors.messages import decode_any_image, decode_depth, decode_gray

    image_t, depth_t, right_t = sensor["image_topic"], sensor.get("depth_topic"), sensor.get("right_topic")
    stereo = None
    if depth_t is None and right_t:
        from ..sensors.stereo_pairs import StereoFrames

        stereo = StereoFrames(right_t, baseline=float(sensor["camera"]["baseline"] or 0.0),
                              rectifier=_rectifier(sensor, log_path) if sensor.get("rectified") else None)
    with open_log(log_path, conf=io_conf) as reader:
        missing = [t for t in (image_t, depth_t, right_t) if t and t not in reader.topics]
        if missing:
            raise InputError(f"the run's topic(s) {', '.join(missing)} are not in this log", log_path)
        waiting: dict[int, list] = {}  # keyframe index -> [grey, colour, depth]
        for m in reader.messages([t for t in (image_t, depth_t, right_t) if t]):
            i = _near(stamps, int(m.stamp))
            if i is None:
                continue
            if m.topic == image_t:
                img = decode_any_image(m)
                gray = image_to_gray(img)
                if stereo is not None:
                    for s, left, right in stereo.add_left(int(m.stamp), gray):
                        yield _near(stamps, s), left, None, None, right
                    continue
                w = waiting.setdefault(i, [None, None, None])
                w[0], w[1] = gray, (img if img.ndim == 3 else None)
            elif m.topic == depth_t:
                waiting.setdefault(i, [None, None, None])[2] = decode_depth(m, sensor.get("depth_unit_m", 1e-3))
            elif stereo is not None:
                for s, left, right in stereo.add_right(int(m.stamp), decode_gray(m)):
                    yield _near(stamps, s), left, None, None, right
                continue
            held = waiting.get(i)
            if held is not None and held[0] is not None and held[2] is not None:
                del waiting[i]
                yield i, held[0], held[1], held[2], None
        if stereo is not None:
            for s, left, right in stereo.flush():
                yield _near(stamps, s), left, None, None, right


def _rectifier(sensor: dict, log_path: Path):
    """The rectification of the run's raw pair, from the calibration files it named."""
    from ..sensors.calibration import load_calibration

    files = sensor.get("calibration") or []
    gone = [f for f in files if not Path(f).is_file()]
    if not files or gone:
        raise FileMissingError("the run rectified its stereo pair with a calibration file that is not there "
                               f"({', '.join(gone) or 'none recorded'})", log_path)
    calibration = load_calibration(files)
    cam = calibration.camera_for(sensor["image_topic"])
    partner = calibration.stereo_partner(cam)
    if partner is None:
        raise InputError(f"{calibration.describe()}: no second camera for the stereo pair", log_path)
    return stereo_rectifier(cam.camera, partner[0].camera, partner[1], calibration.sources[0])


def export_map(run_dir, out, conf: MapCloudConfig | None = None, *, odometry: bool = False, log_path=None,
               io_conf=None) -> dict:
    """Rebuild the map of ``run_dir`` into ``out`` (``.ply`` / ``.pcd``).

    Returns a summary dict (points, keyframes, skipped).
    """
    run_dir, out = Path(run_dir), Path(out)
    cloud_suffix(out)
    report, stamps, poses = read_run_poses(run_dir, odometry)
    sensor = report["map_cloud"]["sensor"]
    log_path = Path(log_path) if log_path is not None else Path(report["input"]["log"])
    if not log_path.exists():
        raise FileMissingError(f"the run's log {log_path} is gone (give its new place with --log)", run_dir)
    check_no_clash({"the cloud": out}, {"the run's report.json": run_dir / "report.json", "the log": log_path,
                                        "the run's keyframes": run_dir / "keyframes_corrected.tum",
                                        "the run's odometry": run_dir / "odometry.tum"})
    check_writable_target(out)
    conf = conf or MapCloudConfig()
    sensor = dict(sensor, depth_unit_m=(report.get("config") or {}).get("sensors", {}).get("depth_unit_m", 1e-3))
    cam, T_bc = _camera(sensor)

    source = f"{log_path}: {sensor.get('depth_topic') or sensor.get('right_topic')}"
    builder = MapCloudBuilder(conf, source=source, folder=out.parent if out.parent.is_dir() else None)
    try:  # each keyframe's points go to the builder's on-disk store: memory stays that of one keyframe
        for i, gray, colour, depth, right in keyframe_frames(log_path, sensor, stamps, io_conf):
            if i is not None:
                builder.add_keyframe(Keyframe(id=i, stamp=int(stamps[i]), T_world_body=poses[i], image=gray,
                                              camera=cam, T_body_camera=T_bc, depth=depth, right_image=right,
                                              colour=colour))
        cloud = builder.cloud({i: poses[i] for i in range(len(stamps))})
        skipped, used = dict(builder.skipped), builder.n_keyframes
    finally:
        builder.close()
    if used == 0:
        raise InputError(f"no keyframe of the run gave points ({'; '.join(skipped) or 'none found in the log'}); "
                         "nothing written", log_path)
    write_cloud(out, cloud, f"slam-lcd export-map of {run_dir} ({'odometry' if odometry else 'corrected'} poses)")
    return {"points": len(cloud), "keyframes": int(len(stamps)), "keyframes_used": used, "skipped": skipped,
            "poses": "odometry" if odometry else "corrected"}
