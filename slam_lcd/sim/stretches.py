"""Bad stretches in a demo log: what each camera frame and odometry sample gets
(:class:`~slam_lcd.sim.stretch_spec.Stretches`, ``make-demo-log --blur`` ...).

Real logs have them: motion blur in fast turns, the lights going off, a camera driver that stops
publishing or re-publishes its last buffer, a clock that jumps, odometry with zero covariances or a
gap. Each is applied to the rendered frames and to the scenario's stamps here, so the writers lay
out a log with stretches as they lay out a plain one. Nothing here draws random numbers: a frame
outside every stretch is the plain log's frame, byte for byte.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import cv2
import numpy as np

from ..errors import InputError
from ..types import Trajectory
from .demo_scenario import DemoScenario
from .image_noise import NOISE_BANK, add_noise
from .stretch_spec import Stretch, Stretches

DARK_GAIN = 0.03  # lights off: what is left of the rendered light (before the sensor noise)
BLUR_WIDTH = 640.0  # --blur's PX is at this image width
FLOW_DEPTH_M = 3.0  # depth of the points whose image motion gives the blur's direction
MIN_FLOW_PX = 1.0  # below this mean image motion between neighbour frames (px at 640 px width): horizontal
MIN_COHERENCE = 0.7  # |mean motion| / mean |motion| below this (driving ahead: motion away from the centre): horizontal


@dataclass
class StretchPlan:
    """Per camera frame and odometry sample, what the stretches do (indices of the rendered scenario)."""

    written: np.ndarray  # bool per camera frame: not dropped
    source: np.ndarray  # int per camera frame: the frame whose image it carries (a frozen frame: its run's first)
    blur_px: np.ndarray  # float per camera frame: blur kernel length at the image's width (0: none)
    dark: np.ndarray  # bool per camera frame
    odom_written: np.ndarray  # bool per odometry sample
    cam_shift: np.ndarray  # int64 ns added to each camera stamp (--stamp-jump)
    odo_shift: np.ndarray  # int64 ns added to each odometry / ground-truth stamp

    @property
    def frozen(self) -> np.ndarray:
        """Frames that carry another frame's image."""
        return self.source != np.arange(len(self.source))


def _ns(seconds: float) -> int:
    return min(int(round(seconds * 1e9)), 2**62)  # past any log's end: the stretch is empty


def _inside(rel_ns: np.ndarray, stretches: tuple[Stretch, ...]) -> np.ndarray:
    """Stamps (ns from the first camera frame) inside any of ``stretches``."""
    hit = np.zeros(len(rel_ns), bool)
    for s in stretches:
        a = _ns(s.start_s)
        hit |= (rel_ns >= a) & (rel_ns < a + _ns(s.seconds))
    return hit


def _shift(rel_ns: np.ndarray, jumps: tuple[Stretch, ...]) -> np.ndarray:
    out = np.zeros(len(rel_ns), np.int64)
    for s in jumps:
        out += np.where(rel_ns >= _ns(s.start_s), np.int64(_ns(s.seconds)), np.int64(0))
    return out


def plan_stretches(st: Stretches, sc: DemoScenario) -> StretchPlan:
    """What ``st`` does to each frame and odometry sample of ``sc`` (its world clock)."""
    t0 = int(sc.cam_stamps[0])
    cam_rel = np.asarray(sc.cam_stamps, np.int64) - t0
    odo_rel = np.asarray(sc.odo_stamps, np.int64) - t0
    n = len(cam_rel)
    source = np.arange(n)
    frozen = _inside(cam_rel, st.freeze)
    for i in range(1, n):  # a run of frozen frames repeats its first frame
        if frozen[i] and frozen[i - 1]:
            source[i] = source[i - 1]
    blur_px = np.zeros(n)
    for s in st.blur:
        assert s.px is not None  # Stretches.check
        blur_px = np.where(_inside(cam_rel, (s,)), np.maximum(blur_px, s.px * sc.camera.width / BLUR_WIDTH), blur_px)
    written = ~_inside(cam_rel, st.drop_frames)
    if not written.any():
        raise InputError(f"--drop-frames drops all {n} camera frames; a log needs one at least")
    return StretchPlan(written=written, source=source, blur_px=blur_px,
                       dark=_inside(cam_rel, st.dark), odom_written=~_inside(odo_rel, st.odom_dropout),
                       cam_shift=_shift(cam_rel, st.stamp_jump), odo_shift=_shift(odo_rel, st.stamp_jump))


def check_stretches(st: Stretches, *, layout: str, fmt: str) -> None:
    """InputError where a stretch cannot be written in ``layout`` / ``fmt``."""
    st.check()
    odo = st.odometry
    if odo and layout != "demo":
        raise InputError(f"{odo[0]}: layout {layout} writes no odometry; use --layout demo")
    if st.odom_zero_covariance and fmt == "folder":
        raise InputError("--odom-zero-covariance: the folder format's odometry.txt (TUM) carries no covariances; "
                         "write mcap, rosbag2 or rosbag1")


def _retimed(traj: Trajectory, shift: np.ndarray, **changes) -> Trajectory:
    return dataclasses.replace(traj, stamps=np.asarray(traj.stamps, np.int64) + shift, **changes)


def log_scenario(sc: DemoScenario, plan: StretchPlan, st: Stretches) -> DemoScenario:
    """``sc`` as the log records it: stamps on the log's clock (jumps), frames and odometry samples
    left out, covariances zeroed. Poses and rendering are the world's (``sc``'s) still."""
    odom = sc.odom
    changes = {}
    if st.odom_zero_covariance and odom.covariances is not None:
        changes["covariances"] = np.zeros_like(odom.covariances)
    return dataclasses.replace(
        sc, cam_stamps=np.asarray(sc.cam_stamps, np.int64) + plan.cam_shift,
        odo_stamps=np.asarray(sc.odo_stamps, np.int64) + plan.odo_shift,
        gt_cam=_retimed(sc.gt_cam, plan.cam_shift), gt_odo=_retimed(sc.gt_odo, plan.odo_shift),
        odom=_retimed(odom, plan.odo_shift, **changes),
        cam_written=None if plan.written.all() else plan.written,
        odom_written=None if plan.odom_written.all() else plan.odom_written)


# ----------------------------------------------------------------------------- images
def motion_kernel(length: float, angle_deg: float) -> np.ndarray:
    """A normalised line of ``length`` pixels (fractional ends) turned ``angle_deg`` (image axes, y down)."""
    c = int(np.ceil(length / 2.0))
    size = 2 * c + 1
    k: np.ndarray = np.zeros((size, size), np.float32)
    k[c] = np.clip(length / 2.0 + 0.5 - np.abs(np.arange(-c, c + 1)), 0.0, 1.0)
    if angle_deg % 180.0:
        # getRotationMatrix2D turns counter-clockwise as displayed; image angles (y down) turn clockwise
        k = cv2.warpAffine(k, cv2.getRotationMatrix2D((float(c), float(c)), -angle_deg, 1.0), (size, size),
                           flags=cv2.INTER_LINEAR)
    return k / k.sum()


def image_motion_angle(sc: DemoScenario, i: int) -> float:
    """Direction (deg, image axes) of the mean image motion around frame ``i``: five points
    :data:`FLOW_DEPTH_M` ahead, seen from the neighbour frames. 0 (horizontal) when the view hardly
    moves or its motion has no one direction (driving straight ahead: the points move apart)."""
    n = len(sc.cam_stamps)
    a, b = max(i - 1, 0), min(i + 1, n - 1)
    if a == b:
        return 0.0
    cam = sc.camera
    u = np.array([cam.cx - cam.width / 4, cam.cx + cam.width / 4, cam.cx, cam.cx, cam.cx])
    v = np.array([cam.cy, cam.cy, cam.cy - cam.height / 4, cam.cy + cam.height / 4, cam.cy])
    X_b = np.stack([(u - cam.cx) / cam.fx * FLOW_DEPTH_M, (v - cam.cy) / cam.fy * FLOW_DEPTH_M,
                    np.full(5, FLOW_DEPTH_M), np.ones(5)])
    T_a = sc.gt_cam.poses[a] @ sc.T_bc
    T_b = sc.gt_cam.poses[b] @ sc.T_bc
    X_a = np.linalg.inv(T_a) @ T_b @ X_b
    ua = cam.fx * X_a[0] / X_a[2] + cam.cx
    va = cam.fy * X_a[1] / X_a[2] + cam.cy
    flow = np.array([np.mean(u - ua), np.mean(v - va)])
    size = np.hypot(*flow)
    if size < MIN_FLOW_PX * cam.width / BLUR_WIDTH or size < MIN_COHERENCE * np.mean(np.hypot(u - ua, v - va)):
        return 0.0
    return float(np.degrees(np.arctan2(flow[1], flow[0])))


def motion_blur(img: np.ndarray, length: float, angle_deg: float) -> np.ndarray:
    if length <= 1.0:
        return img
    return cv2.filter2D(img, -1, motion_kernel(length, angle_deg), borderType=cv2.BORDER_REFLECT_101)


def stretch_renderer(render_one, sc: DemoScenario, plan: StretchPlan):
    """``render_one(i, bank)`` with the stretches' images: a frozen frame renders its run's first
    frame; blur and darkness act on the rendered image, then the frame's sensor noise is added again
    (the noise of the bank the plain frame drew: a dark frame is near black, not constant)."""
    angles = {int(i): image_motion_angle(sc, int(i)) for i in np.flatnonzero(plan.blur_px > 0)}

    def effect(img, s, bank, offset):
        if img is None or not (plan.blur_px[s] > 0 or plan.dark[s]):
            return img
        if plan.blur_px[s] > 0:
            img = motion_blur(img, float(plan.blur_px[s]), angles[s])
        if plan.dark[s]:
            img = np.round(img.astype(np.float32) * DARK_GAIN).astype(np.uint8)
        return add_noise(img, bank[(7 * s + offset) % NOISE_BANK])  # the bank entries the renderers use

    def one(i, bank):
        s = int(plan.source[i])
        _, img, dep, right = render_one(s, bank)
        return i, effect(img, s, bank, 0), dep, effect(right, s, bank, 3)

    return one


# ----------------------------------------------------------------------------- loop pairs
def log_loop_pairs(pairs: np.ndarray, log_sc: DemoScenario, plan: StretchPlan) -> tuple[Trajectory, np.ndarray]:
    """The ground-truth loop pairs of the frames a log holds: ``pairs`` (found on the world's clock)
    without dropped frames and frozen ones (they show their run's first frame, not their own
    place), indices renumbered to the log's image sequence; with the frames' trajectory on the log's
    clock, as :func:`~slam_lcd.sim.loops.write_loop_pairs` takes them."""
    keep = plan.written & ~plan.frozen
    index = np.cumsum(plan.written) - 1  # rendered frame -> position in the log's image sequence
    if len(pairs):
        pairs = pairs[keep[pairs[:, 0]] & keep[pairs[:, 1]]]
    written = np.flatnonzero(plan.written)
    g = log_sc.gt_cam
    traj = dataclasses.replace(g, stamps=g.stamps[written], poses=g.poses[written], covariances=None)
    return traj, index[pairs].reshape(-1, 2).astype(np.int64)
