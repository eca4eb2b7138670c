"""The sources of one ``slam-lcd run``: calibration, camera, odometry, stereo pair, the map cloud's input.

Why a module of its own: :func:`slam_lcd.run.runner.run_log` sequences a run (checks, the one pass
over the log, the outputs); which sensor feeds which part of the pipeline is a separate
question with its own rules, answered here once for every log: a calibration file's camera wins
over the log's CameraInfo, a log without odometry gets the built-in visual odometry (RGB-D on its
depth topic, else stereo on a second camera), a stereo pair without a known baseline gives no
points, a raw pair is rectified. Each function says in its log line which source it chose.
"""
from __future__ import annotations

import dataclasses
import logging

from ..cloud import MapCloudBuilder
from ..errors import PipelineError, stamp_text
from ..features import FeatureCache, load_extractor
from ..outputs.map_cloud import camera_facts
from ..outputs.output_set import OutputSet
from ..outputs.result import RunResult
from ..sensors.calibration import Calibration, load_calibration
from ..sensors.ground_truth import ground_truth_from_tf
from ..sensors.log_vo import visual_odometry_from_log
from ..sensors.mounting import calibrated_mounting
from ..sensors.rectify import is_rectified, stereo_rectifier
from ..sensors.stereo_pairs import StereoFrames, right_camera_info_baseline
from ..sensors.topics import Topics, choose_right_topic, static_tf_topics
from ..types import Trajectory
from .options import MapUse, Models

log = logging.getLogger(__name__)


def ground_truth_tf(reader, topics: Topics) -> Trajectory | None:
    """The ground truth of a TF chain (``topics.gt_frames``), read before the log streams (a tiny topic); else None."""
    if topics.gt is None or topics.gt_frames is None:
        return None
    return ground_truth_from_tf(reader, topics.gt, *topics.gt_frames, static_tf_topics(reader))


def odometry_and_stereo(reader, topics: Topics, right_topic: str | None, cfg, calibration, calibrated, log_path):
    """``(visual odometry or None, stereo pairing or None, right camera topic or None)``.

    A log without depth may have a stereo pair instead: the built-in VO's second camera when
    the log has no odometry, and the loop poses' 3-D points either way. A log with neither
    odometry, depth nor a second camera cannot be run (the error says the three ways out).
    ``topics.right`` is set to the pair's right topic when the pairing is used.
    """
    vo_odometry = None
    right, rectifier, partner, stereo = None, None, None, None
    if topics.depth is None:  # a stereo pair instead: the VO (without odometry) and the loop poses' points
        partner = calibration.stereo_partner(calibrated) if calibrated is not None else None
        right = choose_right_topic(reader, topics.image, right_topic,
                                   partner[0].rostopic if partner is not None else None)
        if right is None and topics.odom is None:
            raise PipelineError(no_odometry_reason(topics.image), log_path)
        if right is not None and (partner is not None or topics.odom is None):
            rectifier = stereo_rectifier_for(calibration, calibrated, log_path)
    if topics.odom is None:
        vo_odometry = visual_odometry(log_path, topics, cfg, calibrated, right, rectifier)
    if right is not None:
        stereo = stereo_frames(reader, right, calibrated, rectifier, vo_odometry)
        topics.right = right if stereo is not None else None
    return vo_odometry, stereo, right


def set_calibrated_camera(pipe, cfg, calibrated, vo_odometry, stereo, tf, body_frame) -> None:
    """Give ``pipe`` the calibration file's camera (CameraInfo is not read then) and its mounting.

    One mounting rule for the VO pass and the main pass: the VO's when it ran. A rectified pair
    is seen rectified by the main pass too; a pair's baseline completes a camera without one.
    """
    T_bc = (vo_odometry.T_body_camera if vo_odometry is not None else
            calibrated_mounting(cfg.frontend, calibrated, tf, body_frame))
    if stereo is not None and stereo.rectifier is not None:  # the main pass sees the rectified pair
        pipe.set_camera(stereo.rectifier.camera, T_bc @ stereo.rectifier.T_cam0_rect)
    elif stereo is not None and not calibrated.camera.baseline:  # the baseline of the pair
        pipe.set_camera(dataclasses.replace(calibrated.camera, baseline=stereo.baseline), T_bc)
    else:
        pipe.set_camera(calibrated.camera, T_bc)


def calibration_of(calib):
    """None, or the :class:`~slam_lcd.sensors.calibration.Calibration` of ``calib`` (paths or loaded)."""
    if calib is None or isinstance(calib, Calibration):
        return calib
    return load_calibration(calib)


def calibrated_camera(calibration, topics: Topics, log_path):
    """The calibration's camera of the image topic; it wins over the log's CameraInfo (said in the log)."""
    if calibration is None:
        return None
    cam = calibration.camera_for(topics.image)
    if topics.camera_info is not None:
        log.warning("%s: --calib wins: camera %s of %s is used, not the log's CameraInfo %s", log_path, cam.name,
                    calibration.describe(), topics.camera_info)
        topics.camera_info = None
    else:
        log.info("%s: camera %s of %s for %s", log_path, cam.name, calibration.describe(), topics.image)
    return cam


def log_frame_ids(first: dict, topics: Topics) -> dict:
    """The odometry's frame_id and child_frame_id and the ground truth's frame_id (from their first messages)."""
    frames = {}
    m = first.get(topics.odom) if topics.odom else None
    if m is not None:
        frames["odom"] = m.msg.header.frame_id.lstrip("/") or None
        frames["body"] = (getattr(m.msg, "child_frame_id", "") or "").lstrip("/") or None
    g = first.get(topics.gt) if topics.gt else None
    if g is not None and hasattr(g.msg, "header"):
        frames["gt"] = g.msg.header.frame_id.lstrip("/") or None
    return {k: v for k, v in frames.items() if v}


def no_odometry_reason(image_topic: str) -> str:
    """What a monocular log without odometry lacks, and the three ways to provide it."""
    return (f"no odometry: the log has no odometry topic (nav_msgs/Odometry), no depth image and no second camera "
            f"beside {image_topic}, and one camera alone gives no metric odometry; pass --odom-topic TOPIC (an "
            f"odometry or pose topic of the log), --depth-topic TOPIC (RGB-D visual odometry) or --right-topic TOPIC "
            f"(a second camera: stereo visual odometry; a raw pair is rectified with --calib)")


def stereo_rectifier_for(calibration, calibrated, log_path):
    """None for a rectified pair (or one described by CameraInfo); else the rectification of the
    calibrated pair (:mod:`slam_lcd.sensors.rectify`): the stereo VO matches along image rows."""
    if calibration is None or calibrated is None:
        return None  # CameraInfo pairs: the right camera's projection gives the baseline of a rectified pair
    partner = calibration.stereo_partner(calibrated)
    if partner is None:
        raise PipelineError(f"{calibration.describe()}: camera {calibrated.name} has no second camera with an "
                            "extrinsic, so the stereo baseline is unknown", log_path)
    if is_rectified(calibrated.camera, partner[0].camera, partner[1]):
        return None
    log.warning("%s: cameras %s and %s of %s are not a rectified pair: the stereo VO rectifies them", log_path,
                calibrated.name, partner[0].name, calibration.describe())
    return stereo_rectifier(calibrated.camera, partner[0].camera, partner[1], calibration.sources[0])


def visual_odometry(log_path, topics: Topics, cfg, calibrated=None, right_topic: str | None = None,
                     rectifier=None):
    """Built-in RGB-D (or, with ``right_topic``, stereo) visual odometry over the whole log (a first
    pass; see slam_lcd.sensors.log_vo)."""
    kind = f"stereo visual odometry on {topics.image} + {right_topic}" if right_topic else \
        f"RGB-D visual odometry on {topics.image} + {topics.depth}"
    log.warning("%s: no odometry topic; running the built-in %s first", log_path, kind)
    cam = calibrated.camera if calibrated is not None else None
    T_bc = calibrated.T_body_camera if calibrated is not None else None
    return visual_odometry_from_log(log_path, cfg.frontend, image_topic=topics.image, depth_topic=topics.depth,
                                    right_topic=right_topic, camera_info_topic=topics.camera_info, camera=cam,
                                    T_body_camera=T_bc, rectifier=rectifier, depth_unit_m=cfg.sensors.depth_unit_m)


def stereo_frames(reader, right: str, calibrated, rectifier, vo_odometry):
    """The pairing of left and right images that gives the loop poses stereo points, or None (with a
    warning that says why) when the baseline of the pair is unknown."""
    if rectifier is not None:
        baseline = rectifier.camera.baseline
    else:
        baseline = ((calibrated.camera.baseline if calibrated is not None else None)
                    or (vo_odometry.camera.baseline if vo_odometry is not None else None)
                    or right_camera_info_baseline(reader, right))
    if not baseline:
        log.warning("%s: stereo pair %s has no baseline (no right CameraInfo projection, no calibration): "
                    "loop poses get no stereo points", reader.path, right)
        return None
    log.info("%s: loop poses take their 3-D points from the stereo pair (+ %s)%s", reader.path, right,
             ", rectified for the main pass too" if rectifier is not None else "")
    return StereoFrames(right, baseline=baseline, rectifier=rectifier)


def map_cloud_builder(cfg, topics: Topics, stereo, outputs: OutputSet, result: RunResult, log_path):
    """The map cloud's builder (its store inside the staging folder), or None with the reason in ``result``."""
    if not cfg.map_cloud.enabled:
        return None
    if topics.depth is None and stereo is None:
        reason = "the log has no depth image and no stereo pair with a baseline"
        # said in the run's summary and report (not a warning: nothing is wrong with the log)
        log.info("%s: no map cloud (map.ply): %s", log_path, reason)
        result.map_cloud = {"built": False, "reason": reason}
        return None

    source = topics.depth if topics.depth is not None else f"{topics.image} + {topics.right}"
    return MapCloudBuilder(cfg.map_cloud, source=f"{log_path}: {source}", folder=outputs.staging)


def cloud_sensor(pipe, topics: Topics, stereo, calibration) -> dict:
    """Where the cloud's points came from: ``export-map`` reads the same topics with the same camera."""
    return {"kind": "depth" if topics.depth is not None else "stereo", "image_topic": topics.image,
            "depth_topic": topics.depth, "right_topic": topics.right if topics.depth is None else None,
            "rectified": bool(stereo is not None and stereo.rectifier is not None),
            "calibration": [str(p) for p in calibration.sources] if calibration is not None else None,
            "camera": camera_facts(pipe.camera, pipe.T_body_camera)}


def no_keyframe_reason(pipe, topics: Topics, n_frames: int, vo=None) -> str:
    """Why a run made no keyframe: the built-in VO tracked no frame (``vo``: its LogVo), or the frames and the
    odometry source's span did not overlap."""
    odom = pipe.odometry_trajectory()
    if vo is not None and len(odom) == 0 and vo.result.frames:
        first = vo.result.frames[0]
        return (f"the built-in visual odometry tracked none of the {len(vo.result.frames)} frames of {topics.image} "
                f"(first frame: {first.reason or first.status}): the images are unusable as a whole (dark, blank or "
                "without depth); nothing to correct")
    span = (f"odometry from {stamp_text(odom.stamps[0])} to {stamp_text(odom.stamps[-1])}" if len(odom)
            else "no odometry sample")
    source = topics.odom or "the visual odometry"
    return (f"no keyframe was made from the {n_frames} frames of {topics.image}: none falls within the odometry "
            f"of {source} ({span}); nothing to correct")


def make_pipeline(cfg, models: Models, log_path, topics: Topics, keyframe_sink=None, rectified: bool = False,
                  map_use: MapUse | None = None, map_cloud=None):
    """The pipeline with its collaborators: the extractor, the vocabulary (None: online), the feature
    cache of this log (``rectified``: the images are the rectified pair's, cached apart from the raw
    ones), whether frames wait for depth, the loop pictures' keyframe album, the map it uses."""
    from .pipeline import Pipeline  # imported late: topic errors need no model

    extractor = models.extractor if models.extractor is not None else load_extractor(cfg.features)
    feature_source = None
    if cfg.features.feature_cache:
        cache = FeatureCache(extractor)

        cache_topic = f"{topics.image}#rectified" if rectified else topics.image

        def feature_source(stamp, img):
            return cache.extract(log_path, cache_topic, stamp, img)

    return Pipeline(cfg, extractor=extractor, vocab=models.vocab, feature_source=feature_source,
                    expect_depth=topics.depth is not None, keyframe_sink=keyframe_sink,
                    loop_sink=getattr(keyframe_sink, "keep_loop", None),
                    map=map_use.session_map if map_use is not None else None,
                    map_mode=map_use.mode if map_use is not None else "append", map_cloud=map_cloud)
