"""The demo world written as public datasets lay out their bags (``make-demo-log --layout``).

Why: the first bag a user tries is a benchmark recording; each layout here has that
dataset's topic names, encodings, rates, ground-truth message and calibration source, with
exact ground truth, so every path of ``slam-lcd run --config <dataset>`` is tested end to end.

========= ================================================ =================================================
layout    topics (no odometry in any)                      ground truth / calibration
========= ================================================ =================================================
euroc     ``/cam0/image_raw``, ``/cam1/image_raw`` mono8,   ``/leica/position`` PointStamped (frame ``leica``,
          20 Hz, **raw**: each camera turned off the        20 Hz, the body position in a shifted, turned
          rectified pair and radtan-distorted; no            Leica frame); ``camchain-<name>.yaml`` (Kalibr:
          CameraInfo, no depth, no TF                        intrinsics, radtan, ``T_cam_imu``, ``T_cn_cnm1``)
tum       ``/camera/rgb/image_color`` rgb8 30 Hz +          ``/tf`` ``/world -> /kinect`` (100 Hz) only;
          ``/camera/rgb/camera_info``,                       ``/tf_static`` ``/kinect ->
          ``/camera/depth_registered/image_raw`` 16UC1 mm   /openni_rgb_optical_frame`` (rotation only)
          (+ its camera_info), Kinect v1 depth noise
          (:mod:`slam_lcd.sim.kinect`; or exact)
kitti     ``/kitti/camera_gray_left/image_raw``,            ``/tf`` ``world -> base_link`` (10 Hz, as kitti2bag
          ``/kitti/camera_gray_right/image_raw`` mono8      writes the OXTS pose); ``/tf_static`` base_link ->
          10 Hz, rectified, + their ``camera_info``          camera_gray_left / camera_gray_right
          (right: ``P[0,3] = -fx * b``)
========= ================================================ =================================================

Where the demo world differs from the datasets (on purpose): image size and focal length
are the demo camera's (``--size``, ``--hfov``), the stereo baseline is the demo rig's
0.12 m (KITTI's 0.54 m would put the demo world's near walls beyond the disparity search),
and no IMU, GPS or Velodyne topics are written.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from ..files.atomic import write_text
from ..geometry import inv, make_T
from ..types import CameraModel
from . import rig
from .image_noise import NOISE_BANK, add_noise
from .kinect import KINECT_V1, KinectDepthModel, depth_mm
from .renderer import render

LAYOUTS = ("demo", "euroc", "tum", "kitti")

# camera rate, ground-truth rate (Hz) of each dataset
RATES = {"euroc": (20.0, 20.0), "tum": (30.0, 100.0), "kitti": (10.0, 10.0)}

# EuRoC-like raw rig: each camera turned off the rectified pair, radtan distortion (k1 k2 p1 p2)
EUROC_TURN_DEG = {"cam0": (0.0, 2.0, 0.0), "cam1": (-1.5, 0.0, 0.0)}  # rotation vectors (deg) off the rectified frame
EUROC_RADTAN = {"cam0": (-0.12, 0.02, 0.0006, -0.0004), "cam1": (-0.11, 0.018, -0.0003, 0.0005)}
# the Leica station's frame: the world turned and shifted (the ATE alignment finds it)
T_LEICA_WORLD = make_T(cv2.Rodrigues(np.radians([0.0, 0.0, 30.0]))[0], np.array([4.0, -2.5, 0.3]))

# the depth sensor of a layout with depth images (``make_demo_log(depth_noise=False)``: exact depth)
DEPTH_MODELS = {"tum": KINECT_V1}

TUM_WORLD, TUM_KINECT, TUM_OPTICAL = "/world", "/kinect", "/openni_rgb_optical_frame"
KITTI_LEFT, KITTI_RIGHT = "camera_gray_left", "camera_gray_right"


def rates(layout: str) -> tuple[float, float]:
    """(camera, ground-truth) rates of a layout; the demo's own 10 Hz / 50 Hz otherwise."""
    return RATES.get(layout, (10.0, 50.0))


# ----------------------------------------------------------------------------- raw (EuRoC) cameras
@dataclass
class RawCamera:
    """A distorted camera rendered through a larger pinhole canvas and warped (raw pixel <- canvas pixel)."""

    name: str
    camera: CameraModel  # the raw camera as its calibration states it (radtan)
    T_rect_raw: np.ndarray  # raw camera in the rectified frame of its side of the pair (rotation only)
    canvas: CameraModel  # the pinhole camera rendered (same focal length, bigger, shifted)
    map_xy: tuple[np.ndarray, np.ndarray]  # per raw pixel, where it lies on the canvas


def raw_camera(name: str, pinhole: CameraModel) -> RawCamera:
    D = np.array(EUROC_RADTAN[name], np.float64)
    cam = CameraModel(width=pinhole.width, height=pinhole.height, fx=pinhole.fx, fy=pinhole.fy, cx=pinhole.cx,
                      cy=pinhole.cy, D=D, distortion_model="plumb_bob")
    u, v = np.meshgrid(np.arange(cam.width, dtype=np.float64), np.arange(cam.height, dtype=np.float64))
    grid = np.stack([u.ravel(), v.ravel()], 1).reshape(-1, 1, 2)
    ideal = cv2.undistortPoints(grid, cam.K, D, P=cam.K).reshape(cam.height, cam.width, 2)
    x0, y0 = np.floor(ideal[..., 0].min()) - 2, np.floor(ideal[..., 1].min()) - 2
    x1, y1 = np.ceil(ideal[..., 0].max()) + 2, np.ceil(ideal[..., 1].max()) + 2
    canvas = CameraModel(width=int(x1 - x0), height=int(y1 - y0), fx=cam.fx, fy=cam.fy, cx=cam.cx - x0,
                         cy=cam.cy - y0)
    mx = (ideal[..., 0] - x0).astype(np.float32)
    my = (ideal[..., 1] - y0).astype(np.float32)
    T = make_T(cv2.Rodrigues(np.radians(EUROC_TURN_DEG[name]))[0], np.zeros(3))
    return RawCamera(name, cam, T, canvas, (mx, my))


@dataclass
class EurocRig:
    cam0: RawCamera
    cam1: RawCamera
    T_body_cam0: np.ndarray
    T_body_cam1: np.ndarray


def euroc_rig(pinhole: CameraModel, T_body_rect0: np.ndarray) -> EurocRig:
    c0, c1 = raw_camera("cam0", pinhole), raw_camera("cam1", pinhole)
    T_b0 = T_body_rect0 @ c0.T_rect_raw
    T_b1 = T_body_rect0 @ rig.T_left_right(rig.STEREO_BASELINE) @ c1.T_rect_raw
    return EurocRig(c0, c1, T_b0, T_b1)


def render_raw(world, raw: RawCamera, T_world_raw: np.ndarray, epoch: float, gain: float = 1.0) -> np.ndarray:
    img, _ = render(world, raw.canvas, T_world_raw, epoch=epoch, with_depth=False, gain=gain)
    return cv2.remap(img, *raw.map_xy, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)


def write_camchain(path: Path, er: EurocRig) -> None:
    """A Kalibr ``camchain.yaml`` of the rig: body = the IMU (here the demo body, base_link)."""
    def block(T):
        return "\n".join("  - [" + ", ".join(f"{x:.12f}" for x in row) + "]" for row in T)

    parts = ["# Kalibr camchain of the slam-lcd demo rig in EuRoC layout (body = IMU = base_link)\n"]
    for k, (raw, T_b) in enumerate(((er.cam0, er.T_body_cam0), (er.cam1, er.T_body_cam1))):
        c = raw.camera
        text = f"cam{k}:\n  T_cam_imu:\n{block(inv(T_b))}\n"
        if k:
            text += f"  T_cn_cnm1:\n{block(inv(T_b) @ er.T_body_cam0)}\n"
        text += (f"  cam_overlaps: [{1 - k}]\n  camera_model: pinhole\n"
                 f"  distortion_coeffs: [{', '.join(f'{x:.9g}' for x in c.D)}]\n  distortion_model: radtan\n"
                 f"  intrinsics: [{c.fx:.9g}, {c.fy:.9g}, {c.cx:.9g}, {c.cy:.9g}]\n"
                 f"  resolution: [{c.width}, {c.height}]\n  rostopic: /{raw.name}/image_raw\n")
        parts.append(text)
    write_text(path, "".join(parts))


def camchain_path_for(out: Path) -> Path:
    """Kalibr's own naming: ``camchain-<bag name>.yaml`` beside the log."""
    out = Path(out)
    stem = out.name[: -len(out.suffix)] if out.suffix and not out.is_dir() else out.name
    return out.with_name(f"camchain-{stem}.yaml")


# ----------------------------------------------------------------------------- per-frame rendering
def depth_model(layout: str, depth_noise: bool = True) -> KinectDepthModel | None:
    """The depth sensor a layout's depth images are written with (None: exact depth, or no depth)."""
    return DEPTH_MODELS.get(layout) if depth_noise else None


def depth_rng(seed: int, frame: int) -> np.random.Generator:
    """The depth noise of one frame: its own stream, so threads and reruns give the same images."""
    return np.random.default_rng(np.random.SeedSequence([seed, 0xD3E97, frame]))


def frame_renderer(layout: str, sc, bank, er: EurocRig | None, *, seed: int = 0, depth_noise: bool = True):
    """``render_one(i) -> (i, image, depth | None, right | None)`` of a layout (noise as the demo log's).

    ``depth_noise``: the layout's depth sensor model (:data:`DEPTH_MODELS`), seeded per frame;
    False: the rendered depth, exact up to the encoding's millimetres.
    """
    sensor = depth_model(layout, depth_noise)

    def euroc(i):
        T_wb, epoch = sc.gt_cam.poses[i], float(sc.laps[i])
        left = render_raw(sc.world, er.cam0, T_wb @ er.T_body_cam0, epoch, sc.exposure)
        right = render_raw(sc.world, er.cam1, T_wb @ er.T_body_cam1, epoch, sc.exposure)
        return (i, add_noise(left, bank[(7 * i) % NOISE_BANK]), None,
                add_noise(right, bank[(7 * i + 3) % NOISE_BANK]))

    def tum(i):
        T_wc = sc.gt_cam.poses[i] @ sc.T_bc
        img, dep = render(sc.world, sc.camera, T_wc, epoch=float(sc.laps[i]), color=True, with_depth=True,
                          gain=sc.exposure)
        img = add_noise(img, bank[(7 * i) % NOISE_BANK])
        if sensor is not None:
            dep = sensor.measure(dep, depth_rng(seed, i))
        return i, img, depth_mm(dep), None

    def kitti(i):
        T_wc = sc.gt_cam.poses[i] @ sc.T_bc
        img, _ = render(sc.world, sc.camera, T_wc, epoch=float(sc.laps[i]), with_depth=False, gain=sc.exposure)
        right, _ = render(sc.world, sc.camera, T_wc @ rig.T_left_right(rig.STEREO_BASELINE),
                          epoch=float(sc.laps[i]), with_depth=False, gain=sc.exposure)
        return (i, add_noise(img, bank[(7 * i) % NOISE_BANK]), None,
                add_noise(right, bank[(7 * i + 3) % NOISE_BANK]))

    return {"euroc": euroc, "tum": tum, "kitti": kitti}[layout]


def T_kinect_optical() -> np.ndarray:
    """TUM's camera body (/kinect) at the optical centre: the optical frame turned, not shifted."""
    T = rig.T_body_camera().copy()
    T[:3, 3] = 0.0
    return T


# ----------------------------------------------------------------------------- writing
def write_layout_log(out, fmt, layout: str, sc, frames_iter, *, conf, er: EurocRig | None) -> dict:
    """Write the frames and ground truth of ``sc`` as ``layout`` lays out its bags; returns {topic: (type, count)}."""
    from ..io import message_builders as M  # lazy: rosbags, which a plain demo log and the folder format do without
    from ..io.writers import open_writer

    types: dict[str, str] = {}
    gt = sc.gt_odo  # body poses at the ground-truth rate
    cam = CameraModel(**{**sc.camera.__dict__, "baseline": None})

    def put(w, topic, msg, stamp):
        types.setdefault(topic, msg.__msgtype__)
        w.write(topic, msg, int(stamp))

    with open_writer(out, fmt, conf=conf) as w:
        t0 = int(min(sc.cam_stamps[0], sc.odo_stamps[0]))
        if layout == "tum":
            put(w, "/tf_static", M.tf_message([(T_kinect_optical(), t0, TUM_KINECT, TUM_OPTICAL)]), t0)
        elif layout == "kitti":
            put(w, "/tf_static", M.tf_message([(sc.T_bc, t0, rig.BODY_FRAME, KITTI_LEFT),
                                               (sc.T_bc @ rig.T_left_right(rig.STEREO_BASELINE), t0, rig.BODY_FRAME,
                                                KITTI_RIGHT)]), t0)
        events = sorted([(int(sc.cam_stamps[i]), 0, i) for i in sc.written_frames()] +
                        [(int(s), 1, i) for i, s in enumerate(sc.odo_stamps)])
        frames_iter = iter(frames_iter)
        T_ko_inv = inv(T_kinect_optical())
        right_cam = CameraModel(**{**sc.camera.__dict__, "baseline": rig.STEREO_BASELINE})
        for stamp, kind, i in events:
            if kind == 0:
                _, img, dep, right = next(frames_iter)
                if layout == "euroc":
                    put(w, "/cam0/image_raw", M.image_msg(img, stamp, "cam0", "mono8"), stamp)
                    put(w, "/cam1/image_raw", M.image_msg(right, stamp, "cam1", "mono8"), stamp)
                elif layout == "tum":
                    put(w, "/camera/rgb/camera_info", M.camera_info_msg(cam, stamp, TUM_OPTICAL), stamp)
                    put(w, "/camera/rgb/image_color", M.image_msg(img, stamp, TUM_OPTICAL, "rgb8"), stamp)
                    put(w, "/camera/depth_registered/camera_info", M.camera_info_msg(cam, stamp, TUM_OPTICAL), stamp)
                    put(w, "/camera/depth_registered/image_raw", M.image_msg(dep, stamp, TUM_OPTICAL, "16UC1"), stamp)
                else:
                    put(w, f"/kitti/{KITTI_LEFT}/camera_info", M.camera_info_msg(cam, stamp, KITTI_LEFT), stamp)
                    put(w, f"/kitti/{KITTI_LEFT}/image_raw", M.image_msg(img, stamp, KITTI_LEFT, "mono8"), stamp)
                    put(w, f"/kitti/{KITTI_RIGHT}/camera_info", M.camera_info_msg(right_cam, stamp, KITTI_RIGHT),
                        stamp)
                    put(w, f"/kitti/{KITTI_RIGHT}/image_raw", M.image_msg(right, stamp, KITTI_RIGHT, "mono8"), stamp)
            else:
                T_wb = gt.poses[i]
                if layout == "euroc":
                    p = (T_LEICA_WORLD @ T_wb)[:3, 3]
                    put(w, "/leica/position", M.point_stamped_msg(p, stamp, "leica"), stamp)
                elif layout == "tum":
                    T_wk = T_wb @ sc.T_bc @ T_ko_inv
                    put(w, "/tf", M.tf_message([(T_wk, stamp, TUM_WORLD, TUM_KINECT)]), stamp)
                else:
                    put(w, "/tf", M.tf_message([(T_wb, stamp, rig.WORLD_FRAME, rig.BODY_FRAME)]), stamp)
        counts = dict(w.counts)
    return {t: (types[t], n) for t, n in counts.items()}
