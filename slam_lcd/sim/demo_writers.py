"""The demo log's bytes: a ROS log (MCAP, rosbag2, ROS1 bag) with the topics listed in
:mod:`slam_lcd.sim.demo_log`, or a plain folder of PNG images and TUM trajectories.

Why apart from :mod:`slam_lcd.sim.demo_log`: that module decides what a log holds (route,
stamps, odometry, rendered frames); these writers only lay the same content out in one
format each. They read a scenario (camera, stamps, ground truth, odometry, mounting) and the
rendered frames ``(index, image, depth | None, right | None)`` in camera order, and return
``{topic or file: (type, count)}``. A dataset layout's logs are written by
:mod:`slam_lcd.sim.layouts` instead.
"""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from ..files.atomic import atomic_path
from ..io.config import IOConfig
from ..io.trajectory_files import write_tum
from ..types import CameraModel, Trajectory
from . import rig
from .demo_scenario import DemoScenario


def write_demo_log(out, fmt, sc: DemoScenario, frames_iter, *, depth, stereo, compressed, color, io_conf):
    """The demo topics as a ``fmt`` log at ``out``, in time order (camera first at equal stamps)."""
    from ..io import message_builders as M  # lazy: rosbags, which the folder format does without
    from ..io.writers import open_writer

    conf = demo_io_conf(io_conf)
    cam_frame, right_frame = rig.CAMERA_FRAME, rig.RIGHT_CAMERA_FRAME
    right_cam = CameraModel(**{**sc.camera.__dict__}) if stereo else None
    left_cam = CameraModel(**{**sc.camera.__dict__, "baseline": None})
    types: dict[str, str] = {}
    odo = sc.odom
    assert odo.covariances is not None  # simulated odometry carries its covariances (sim.odometry)
    gt = sc.gt_odo
    cam_index = {int(s): i for i, s in enumerate(sc.cam_stamps)}

    def put(w, topic, msg, stamp):
        types.setdefault(topic, msg.__msgtype__)
        w.write(topic, msg, int(stamp))

    def put_camera(w, prefix, cam, img, stamp, frame):
        """``<prefix>/camera_info`` and the image, raw or JPEG-compressed."""
        put(w, f"{prefix}/camera_info", M.camera_info_msg(cam, stamp, frame), stamp)
        if compressed:
            put(w, f"{prefix}/image_raw/compressed",
                M.compressed_image_msg(img, stamp, frame, "jpeg", conf.jpeg_quality), stamp)
        else:
            put(w, f"{prefix}/image_raw", M.image_msg(img, stamp, frame), stamp)

    with open_writer(out, fmt, conf=conf) as w:
        t0 = int(min(sc.cam_stamps[0], sc.odo_stamps[0]))
        statics = [(sc.T_bc, t0, rig.BODY_FRAME, cam_frame)]
        if not sc.odom_at_start:  # a session's odometry frame is its own: its relation to the world is unknown
            statics.append((np.eye(4), t0, rig.WORLD_FRAME, rig.ODOM_FRAME))
        if stereo:
            statics.append((sc.T_bc @ rig.T_left_right(rig.STEREO_BASELINE), t0, rig.BODY_FRAME, right_frame))
        put(w, "/tf_static", M.tf_message(statics), t0)
        # merge camera frames and odometry samples in time order (camera first at equal stamps)
        events = ([(int(sc.cam_stamps[i]), 0, i) for i in sc.written_frames()]
                  + [(int(s), 1, i) for i, s in enumerate(sc.odo_stamps)])
        events.sort()
        frames_iter = iter(frames_iter)
        for stamp, kind, i in events:
            if kind == 0:
                fi, img, dep, right = next(frames_iter)
                assert fi == cam_index[stamp]
                put_camera(w, "/camera", left_cam, img, stamp, cam_frame)
                if dep is not None:
                    put(w, "/camera/depth", M.image_msg(dep, stamp, cam_frame, "32FC1"), stamp)
                if right is not None:
                    put_camera(w, "/camera/right", right_cam, right, stamp, right_frame)
            else:
                if sc.odom_is_written(i):
                    put(w, "/odom", M.odometry_msg(odo.poses[i], odo.covariances[i], stamp, rig.ODOM_FRAME,
                                                   rig.BODY_FRAME), stamp)
                put(w, "/ground_truth/pose", M.pose_stamped_msg(gt.poses[i], stamp, sc.world_frame), stamp)
        counts = dict(w.counts)
    return {t: (types[t], n) for t, n in counts.items()}


def demo_io_conf(io_conf):
    """``io_conf``, or the defaults with ROS1 bags compressed: raw depth would make them large."""
    conf = io_conf
    if conf is None:
        conf = IOConfig()
        if conf.rosbag1_compression == "none":
            conf.rosbag1_compression = "lz4"  # 1 GB of raw depth otherwise
    return conf


def _stamp_name(stamp_ns: int) -> str:
    return f"{stamp_ns // 1_000_000_000}.{(stamp_ns % 1_000_000_000) // 1000:06d}"


def _write_tum(path: Path, traj: Trajectory) -> None:
    """TUM lines ``t x y z qx qy qz qw``."""
    write_tum(path, traj)


def write_demo_folder(out: Path, sc: DemoScenario, frames_iter, *, color, depth, stereo, stretches=()):
    """PNG images, image lists, TUM trajectories and ``camera.yaml``, written atomically (whole or absent).

    ``stretches``: the bad stretches injected (``['--blur 2:1:15', ...]``), listed in ``camera.yaml``."""
    import yaml

    counts: dict[str, tuple[str, int]] = {}
    with atomic_path(out, directory=True) as tmp:
        tmp.mkdir()
        (tmp / "image").mkdir()
        lists: dict[str, list[str]] = {"image": []}
        if depth:
            (tmp / "depth").mkdir()
            lists["depth"] = []
        if stereo:
            (tmp / "right").mkdir()
            lists["right"] = []
        for i, img, dep, right in frames_iter:
            name = _stamp_name(int(sc.cam_stamps[i]))
            bgr = cv2.cvtColor(img, cv2.COLOR_RGB2BGR) if img.ndim == 3 else img
            cv2.imwrite(str(tmp / "image" / f"{name}.png"), bgr)
            lists["image"].append(name)
            if dep is not None:
                mm = np.clip(np.round(dep * 1000.0), 0, 65535).astype(np.uint16)
                cv2.imwrite(str(tmp / "depth" / f"{name}.png"), mm)
                lists["depth"].append(name)
            if right is not None:
                cv2.imwrite(str(tmp / "right" / f"{name}.png"),
                            cv2.cvtColor(right, cv2.COLOR_RGB2BGR) if right.ndim == 3 else right)
                lists["right"].append(name)
        for key, names in lists.items():
            text = f"# {key} images of the slam-lcd demo world\n# timestamp filename\n"
            text += "".join(f"{n} {key}/{n}.png\n" for n in names)
            (tmp / f"{key}.txt").write_text(text, encoding="utf-8")
            counts[f"{key}/"] = ("png", len(names))
        _write_tum(tmp / "groundtruth.txt", sc.gt_odo)
        odom = sc.odom
        if sc.odom_written is not None:  # --odom-dropout
            odom = Trajectory(stamps=odom.stamps[sc.odom_written], poses=odom.poses[sc.odom_written],
                              frame_id=odom.frame_id, child_frame_id=odom.child_frame_id)
        _write_tum(tmp / "odometry.txt", odom)
        counts["groundtruth.txt"] = ("tum", len(sc.gt_odo))
        counts["odometry.txt"] = ("tum", len(odom))
        cam = sc.camera
        meta = {
            "width": cam.width, "height": cam.height, "fx": cam.fx, "fy": cam.fy, "cx": cam.cx, "cy": cam.cy,
            "distortion_model": "none", "baseline_m": cam.baseline if stereo else None,
            "depth_scale": 1000.0,  # depth PNG value / depth_scale = metres (0 = no depth)
            "T_body_camera": [[float(v) for v in row] for row in sc.T_bc],
            # the median period: a --stamp-jump between two frames is not the rate
            "frame_rate_hz": float(1e9 / np.median(np.diff(sc.cam_stamps))) if len(sc.cam_stamps) > 1 else None,
            "groundtruth": f"base_link pose in '{sc.world_frame}' (TUM: t x y z qx qy qz qw)",
            "odometry": ("drifting base_link pose in 'odom' (the start pose: identity at the first stamp)"
                         if sc.odom_at_start else "drifting base_link pose in 'odom' (= 'world' at the first stamp)"),
        }
        if stretches:
            meta["stretches"] = list(stretches)  # make-demo-log's bad stretches (docs/sim_stretches.md)
        (tmp / "camera.yaml").write_text(yaml.safe_dump(meta, sort_keys=False), encoding="utf-8")
    return counts
