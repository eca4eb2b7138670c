"""Write the demo world as a real log (MCAP, rosbag2, ROS1 bag) or as a plain folder.

Topics (camera 10 Hz, odometry and ground truth 50 Hz; every message's log time is its
header stamp; messages are written in time order):

=============================== =========================== ======================================
topic                           type                        content
=============================== =========================== ======================================
/camera/image_raw               sensor_msgs/Image           mono8 (rgb8 with ``color``), left camera
/camera/image_raw/compressed    sensor_msgs/CompressedImage instead of the above with ``compressed``
/camera/camera_info             sensor_msgs/CameraInfo      pinhole, no distortion
/camera/depth                   sensor_msgs/Image           32FC1 metric z, 1/1024 m steps (``depth``)
/camera/right/image_raw         sensor_msgs/Image           rectified right camera (``stereo``)
/camera/right/camera_info       sensor_msgs/CameraInfo      P[0,3] = -fx * baseline (``stereo``)
/odom                           nav_msgs/Odometry           drifting wheel odometry, odom -> base_link
/ground_truth/pose              geometry_msgs/PoseStamped   exact base_link pose in 'world'
/tf_static                      tf2_msgs/TFMessage          base_link -> camera(s); world -> odom
=============================== =========================== ======================================

The odometry frame coincides with 'world' at the first stamp (identity world -> odom). A
session (``session=K``, :mod:`slam_lcd.sim.sessions`) differs: its odometry starts at the
identity (its own frame; no world -> odom on /tf_static), its stamps start K days later,
and its ground truth is in the frame of its world (``world``, or ``world_<seed>`` for
another world).
Beside the log, ``<name>_loops.csv`` lists the ground-truth loop pairs of the camera frames.
The same arguments give byte-identical files.
"""
from __future__ import annotations

import logging
import math
import os
import time
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InputError
from ..runtime.progress import progress_bar
from . import layouts as L
from . import rig
from .appearance import check_appearance
from .demo_info import DemoLogInfo
from .demo_scenario import DemoScenario
from .demo_writers import demo_io_conf, write_demo_folder, write_demo_log
from .image_noise import NOISE_BANK, add_noise, noise_bank
from .loops import gt_loop_pairs, write_loop_pairs
from .odometry import end_drift, simulate_odometry
from .renderer import render
from .sessions import session_preset, session_start_ns, world_frame
from .stretch_spec import Stretches
from .stretches import check_stretches, log_loop_pairs, log_scenario, plan_stretches, stretch_renderer
from .trajectory import KINDS, START_AT, START_NS, make_path, path_trajectory, sample_stamps

log = logging.getLogger(__name__)

FORMATS = ("mcap", "rosbag2", "rosbag1", "folder")
DEPTH_STEP = 1.0 / 1024.0  # depth quantisation (m): like a sensor's millimetre steps, and compresses 40x


MAX_CAMERA_RATE_HZ = 1000.0  # a camera period of 1 ms; more is no camera, and the frames would never end
MAX_ODOM_RATE_HZ = 10000.0


def _scenario(frames, seed, kind, laps, width, height, camera_rate, odom_rate, stereo, hfov_deg=70.0, *,
              world_seed: int | None = None, start_at: float | None = None, lighting: float = 0.0,
              exposure: float = 1.0, start_ns: int = START_NS, odom_at_start: bool = False,
              world_frame: str = rig.WORLD_FRAME, appearance: str = "day") -> DemoScenario:
    """Everything of a log but its images: stamps, ground truth, odometry, lighting epochs.

    Cheap (no world is built until ``.world`` is read), so the routes and odometry of
    sessions can be studied without rendering.
    """
    for name, rate, most in (("--rate (camera rate)", camera_rate, MAX_CAMERA_RATE_HZ),
                             ("odometry rate", odom_rate, MAX_ODOM_RATE_HZ)):
        if not 0 < float(rate) <= most:  # NaN fails too
            raise InputError(f"{name} must be a number of Hz above 0 and at most {most:g}, got {rate}")
    if not (math.isfinite(float(laps)) and laps > 0):
        raise InputError(f"--laps must be a finite number above 0, got {laps}")
    if int(seed) < 0:
        raise InputError(f"--seed must be 0 or more, got {seed}")
    if not np.isfinite(exposure) or exposure <= 0:
        raise InputError(f"exposure must be a positive factor, got {exposure}")
    if not np.isfinite(lighting) or lighting < 0:
        raise InputError(f"the lighting epoch offset must be >= 0, got {lighting}")
    if start_at is not None and not np.isfinite(start_at):
        raise InputError(f"the start point must be a finite arc length (m), got {start_at}")
    check_appearance(appearance)
    path = make_path(kind, laps=laps, seed=seed, start_at=start_at)
    cam_period = int(round(1e9 / camera_rate))
    if frames is None:
        cam_stamps = sample_stamps(path.duration_s, camera_rate, start_ns)
    else:
        if frames < 2:
            raise InputError(f"--frames must be at least 2, got {frames}")
        need = (frames - 1) * cam_period * 1e-9
        while path.duration_s < need:
            path = make_path(kind, laps=path.distance[-1] / path.lap_length * need / path.duration_s * 1.05 + 0.05,
                             seed=seed, start_at=start_at)
        cam_stamps = start_ns + cam_period * np.arange(frames, dtype=np.int64)
    end_s = (cam_stamps[-1] - start_ns) * 1e-9
    odo_stamps = sample_stamps(end_s, odom_rate, start_ns)
    if not 20.0 <= hfov_deg <= 150.0:
        raise InputError(f"horizontal field of view must be within 20-150 degrees, got {hfov_deg}")
    camera = rig.demo_camera(width, height, hfov_deg=hfov_deg, baseline=rig.STEREO_BASELINE if stereo else None)
    gt_cam = path_trajectory(path, cam_stamps, start_ns)
    gt_odo = path_trajectory(path, odo_stamps, start_ns)
    gt_cam.frame_id = gt_odo.frame_id = world_frame
    odom = simulate_odometry(gt_odo, seed=seed, frame_id=rig.ODOM_FRAME, child_frame_id=rig.BODY_FRAME,
                             start_at_identity=odom_at_start)
    laps_at = path.laps_at((cam_stamps - start_ns) * 1e-9) + float(lighting)
    return DemoScenario(camera, rig.T_body_camera(), cam_stamps, odo_stamps, gt_cam, gt_odo, odom, laps_at,
                     seed if world_seed is None else int(world_seed), exposure=float(exposure),
                     world_frame=world_frame, odom_at_start=odom_at_start, appearance=appearance)


def _resolve(session: int | None, **given) -> dict:
    """The scenario settings of ``session`` (None: a plain demo log): ``given`` values that are
    not None win over the preset's, the preset's over the plain log's defaults."""
    plain = {"kind": "laps", "laps": 2.0, "seed": 0, "world_seed": None, "start_at": None, "lighting": 0.0,
             "exposure": 1.0, "appearance": "day"}
    out: dict[str, Any] = {k: given.get(k) for k in plain}
    extra = {"start_ns": START_NS, "odom_at_start": False, "world_frame": rig.WORLD_FRAME}
    if session is not None:
        pre = session_preset(session)
        for k in plain:
            if out[k] is None:
                out[k] = getattr(pre, k)
        extra = {"start_ns": session_start_ns(session), "odom_at_start": True,
                 "world_frame": world_frame(out["world_seed"])}
    for k, v in plain.items():
        if out[k] is None:
            out[k] = v
    if out["world_seed"] is None:
        out["world_seed"] = out["seed"]  # a plain log: --seed makes the world too
    return {**out, **extra}


def session_scenario(session: int | None, *, frames: int | None = None, camera_rate: float = 10.0,
                     odom_rate: float = 50.0, width: int = 640, height: int = 480, **given) -> DemoScenario:
    """The scenario (stamps, ground truth, odometry, lighting) a log of ``session`` would hold,
    without rendering anything: for studying routes and shared places. ``given``: ``kind``,
    ``laps``, ``seed``, ``world_seed``, ``start_at``, ``lighting``, ``exposure``, ``appearance``
    overriding the preset, as :func:`make_demo_log` takes them."""
    r = _resolve(session, **given)
    return _scenario(frames, r["seed"], r["kind"], r["laps"], width, height, camera_rate, odom_rate, False,
                     world_seed=r["world_seed"], start_at=r["start_at"], lighting=r["lighting"],
                     exposure=r["exposure"], start_ns=r["start_ns"], odom_at_start=r["odom_at_start"],
                     world_frame=r["world_frame"], appearance=r["appearance"])


def make_path_start(kind: str, start_at: float | None) -> float:
    """The start point's arc length a route ``kind`` uses for ``start_at`` (None: the route's default)."""
    return START_AT["laps" if kind == "laps-wide" else kind] if start_at is None else float(start_at)


def _render_one(sc: DemoScenario, i: int, bank: np.ndarray, *, color: bool, depth: bool, stereo: bool):
    T_wc = sc.gt_cam.poses[i] @ sc.T_bc
    img, dep = render(sc.world, sc.camera, T_wc, epoch=float(sc.laps[i]), color=color, with_depth=depth,
                      gain=sc.exposure)
    img = add_noise(img, bank[(7 * i) % NOISE_BANK])
    if dep is not None:
        dep = (np.round(dep / DEPTH_STEP) * DEPTH_STEP).astype(np.float32)
    right = None
    if stereo:
        T_lr = rig.T_left_right(rig.STEREO_BASELINE)
        right, _ = render(sc.world, sc.camera, T_wc @ T_lr, epoch=float(sc.laps[i]), color=color, with_depth=False,
                          gain=sc.exposure)
        right = add_noise(right, bank[(7 * i + 3) % NOISE_BANK])
    return i, img, dep, right


def render_frames(sc: DemoScenario, *, color: bool, depth: bool, stereo: bool, seed: int, workers: int = 1,
                  render_one=None):
    """Yield ``(index, image, depth | None, right | None)`` for every camera frame the log holds, in order.

    With ``workers >= 1`` frames are rendered ahead in that many threads (OpenCV and numpy
    release the GIL) while the caller serialises and compresses; the output is identical
    either way. Threads, not forked processes: forking after OpenCV started its thread pool
    can deadlock the child. ``render_one(i, bank)``: a dataset layout's own frame
    (:func:`slam_lcd.sim.layouts.frame_renderer`) instead of the demo log's.
    """
    shape = (sc.camera.height, sc.camera.width) + ((3,) if color else ())
    bank = noise_bank(seed, shape)
    flags = dict(color=color, depth=depth, stereo=stereo)
    if render_one is None:
        def render_one(i, bank):
            return _render_one(sc, i, bank, **flags)
    frames = sc.written_frames()
    n = len(frames)
    if workers < 1 or n < 8:
        for i in frames:
            yield render_one(i, bank)
        return
    from collections import deque
    from concurrent.futures import ThreadPoolExecutor

    ahead = 4 * workers
    with ThreadPoolExecutor(max_workers=workers, thread_name_prefix="demo-render") as pool:
        pending: deque = deque()
        nxt = 0
        try:
            while nxt < n or pending:
                while nxt < n and len(pending) < ahead:
                    pending.append(pool.submit(render_one, frames[nxt], bank))
                    nxt += 1
                yield pending.popleft().result()
        finally:
            for f in pending:
                f.cancel()


def loops_path_for(out: Path) -> Path:
    """Where the loop-pairs CSV of a log goes: beside it, ``<stem>_loops.csv``."""
    out = Path(out)
    stem = out.name[: -len(out.suffix)] if out.suffix and not out.is_dir() else out.name
    return out.with_name(f"{stem}_loops.csv")


def make_demo_log(out, fmt: str = "mcap", frames: int | None = None, seed: int | None = None, stereo: bool = False,
                  depth: bool = True, *, compressed: bool = False, color: bool = False, kind: str | None = None,
                  laps: float | None = None, width: int = 640, height: int = 480, camera_rate: float | None = None,
                  odom_rate: float | None = None, loops_csv: str | Path | None = None, progress: bool = False,
                  io_conf=None, workers: int | None = None, hfov_deg: float = 70.0,
                  layout: str = "demo", depth_noise: bool = True, session: int | None = None,
                  world_seed: int | None = None, start_at: float | None = None, lighting: float | None = None,
                  exposure: float | None = None, appearance: str | None = None,
                  stretches: Stretches | None = None) -> DemoLogInfo:
    """Render the demo world along a trajectory and write it as ``fmt`` at ``out``.

    ``frames`` None means ``laps`` laps (default 2 laps of block A: ~850 frames at 10 Hz);
    otherwise exactly ``frames`` camera frames. ``workers``: render threads running ahead of
    the writer (default 1 on a machine with 2+ cores; 0 = render inline).
    ``layout``: ``demo`` (the topics above), or ``euroc`` / ``tum`` / ``kitti``: the topics,
    encodings, rates, ground truth and calibration file of that dataset's bags
    (:mod:`slam_lcd.sim.layouts`; ``stereo``, ``depth``, ``color`` and ``compressed`` are the
    layout's then). ``camera_rate`` / ``odom_rate`` (ground truth) None: the layout's rates.
    ``depth_noise``: a layout's depth images carry its depth sensor's errors (``tum``: the
    Kinect v1 model of :mod:`slam_lcd.sim.kinect`); False writes the exact rendered depth
    (millimetre steps only). The demo layout's depth is exact (1/1024 m steps) either way.

    ``session`` (1-8): one recording of a multi-session set (:mod:`slam_lcd.sim.sessions`):
    the preset gives ``kind``, ``laps``, ``seed``, ``world_seed``, ``start_at``, ``lighting``
    and ``exposure`` where they are None; the odometry starts at the identity (its own
    frame; no world -> odom on /tf_static), stamps start ``session`` days after the plain
    log's, and the ground truth is in the world's frame (:func:`~slam_lcd.sim.sessions.world_frame`).
    Without a session: ``seed`` 0, ``kind`` laps, 2 laps, ``world_seed`` = ``seed``, the
    route's usual start, ``lighting`` 0 (offset added to every frame's lighting epoch),
    ``exposure`` 1 (global gain of the renderer), ``appearance`` ``day``: the world as its seed
    paints it; ``night``, ``moved`` or ``renovated`` change what the camera sees
    (:mod:`slam_lcd.sim.appearance`; a session's preset is ``day``).
    ``stretches``: bad stretches put into the log (blur, darkness, dropped or frozen frames, stamp
    jumps, odometry gaps or zero covariances: :mod:`slam_lcd.sim.stretches`); none: the plain log.
    Returns a :class:`DemoLogInfo`.
    """
    t_start = time.perf_counter()
    out = Path(out)
    r = _resolve(session, kind=kind, laps=laps, seed=seed, world_seed=world_seed, start_at=start_at,
                 lighting=lighting, exposure=exposure, appearance=appearance)
    kind, laps, seed, world_seed, start_at, lighting, exposure = (
        r["kind"], r["laps"], r["seed"], r["world_seed"], r["start_at"], r["lighting"], r["exposure"])
    start_ns, odom_at_start, gt_frame = r["start_ns"], r["odom_at_start"], r["world_frame"]
    if fmt not in FORMATS:
        raise InputError(f"unknown demo-log format {fmt!r}; use one of {list(FORMATS)}", out)

    if kind not in KINDS:
        raise InputError(f"unknown trajectory kind {kind!r}; use one of {', '.join(KINDS)}")
    if layout not in L.LAYOUTS:
        raise InputError(f"unknown demo-log layout {layout!r}; use one of {', '.join(L.LAYOUTS)}")
    cam_rate, gt_rate = L.rates(layout)
    camera_rate = cam_rate if camera_rate is None else camera_rate
    odom_rate = gt_rate if odom_rate is None else odom_rate
    if layout != "demo":
        if fmt == "folder":
            raise InputError(f"layout {layout} is a log layout: write it as mcap, rosbag2 or rosbag1, not a folder")
        stereo, depth, color, compressed = layout in ("euroc", "kitti"), layout == "tum", layout == "tum", False
    st = stretches or None  # an empty Stretches is the plain log
    if st is not None:
        check_stretches(st, layout=layout, fmt=fmt)
    sc = _scenario(frames, seed, kind, laps, width, height, camera_rate, odom_rate, stereo, hfov_deg,
                   world_seed=world_seed, start_at=start_at, lighting=lighting, exposure=exposure, start_ns=start_ns,
                   odom_at_start=odom_at_start, world_frame=gt_frame, appearance=r["appearance"])
    world_sc, plan = sc, None  # world_sc: the world's clock and every frame; sc: what the log records
    if st is not None:
        plan = plan_stretches(st, sc)
        sc = log_scenario(sc, plan, st)
    if workers is None:
        workers = 1 if (os.cpu_count() or 1) >= 2 else 0
    er = L.euroc_rig(sc.camera, sc.T_bc) if layout == "euroc" else None
    render_one = None
    if layout != "demo":
        def render_one(i, bank):
            return L.frame_renderer(layout, sc, bank, er, seed=seed, depth_noise=depth_noise)(i)
    if plan is not None:
        if render_one is None:
            def render_one(i, bank):
                return _render_one(sc, i, bank, color=color, depth=depth, stereo=stereo)
        render_one = stretch_renderer(render_one, sc, plan)
    frames_iter = render_frames(sc, color=color, depth=depth, stereo=stereo, seed=seed, workers=workers,
                                render_one=render_one)
    if progress:
        frames_iter = progress_bar(frames_iter, total=len(sc.written_frames()), unit="frame", desc="rendering")
    try:
        if fmt == "folder":
            counts = write_demo_folder(out, sc, frames_iter, color=color, depth=depth, stereo=stereo,
                                       stretches=st.flags() if st is not None else ())
        elif layout != "demo":
            counts = L.write_layout_log(out, fmt, layout, sc, frames_iter, conf=demo_io_conf(io_conf), er=er)
        else:
            counts = write_demo_log(out, fmt, sc, frames_iter, depth=depth, stereo=stereo, compressed=compressed,
                                color=color, io_conf=io_conf)
    finally:
        if progress:
            frames_iter.close()  # an error message must not be glued to a half-drawn bar
    calib_path = None
    if er is not None:
        calib_path = L.camchain_path_for(out)
        L.write_camchain(calib_path, er)
    pairs = gt_loop_pairs(world_sc.gt_cam, T_body_camera=sc.T_bc)
    gt_frames = sc.gt_cam
    if plan is not None:
        gt_frames, pairs = log_loop_pairs(pairs, sc, plan)
    if loops_csv is not None:
        lp = Path(loops_csv)
    else:
        lp = out / "loop_pairs.csv" if fmt == "folder" else loops_path_for(out)
    write_loop_pairs(lp, gt_frames, pairs, T_body_camera=sc.T_bc)
    written = sc.written_frames()
    duration = (sc.cam_stamps[written[-1]] - sc.cam_stamps[written[0]]) * 1e-9 if written else 0.0
    topics = {}
    for t, (typ, n) in counts.items():
        topics[t] = {"type": typ, "count": n, "rate_hz": (n - 1) / duration if n > 1 and duration > 0 else 0.0}
    return DemoLogInfo(path=out, format=fmt, frames=len(written), duration_s=float(duration),
                       path_length_m=sc.gt_odo.path_length(), topics=topics, loop_pairs_path=lp,
                       n_loop_pairs=len(pairs), drift=end_drift(world_sc.gt_odo, world_sc.odom), camera=sc.camera,
                       T_body_camera=sc.T_bc, wall_s=time.perf_counter() - t_start, seed=seed, kind=kind,
                       layout=layout, calibration_path=calib_path,
                       depth_model=L.depth_model(layout, depth_noise), session=session, world_seed=sc.world_seed,
                       world_frame=sc.world_frame, lighting=float(lighting), exposure=float(exposure),
                       start_at=float(make_path_start(kind, start_at)), odom_at_start=odom_at_start,
                       appearance=sc.appearance, stretches=st.flags() if st is not None else [])
