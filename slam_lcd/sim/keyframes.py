"""Keyframes of the demo world with exact ground truth, as a user's own front end would make them.

Why: the plugin's tests and benchmarks (loop information NEES, the user-graph example) need
keyframes a *user* builds (image + camera + depth or a stereo partner, their own ids) and
the exact ground-truth pose of each, without going through our pipeline. Keyframes are
rendered along the demo path at ``rate_hz``; features come from an on-disk
:class:`~slam_lcd.features.FeatureCache` keyed by a virtual log name that holds every
render parameter and the package version (rendering is deterministic), so a second run
extracts nothing.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..features import FeatureCache
from ..features.weights import cache_dir
from ..types import CameraModel, Keyframe, Trajectory
from ..version import __version__
from .renderer import render
from .rig import T_body_camera, T_left_right, demo_camera
from .trajectory import make_trajectory
from .world import build_world


@dataclass
class DemoKeyframes:
    keyframes: list[Keyframe]  # T_world_body = ground truth (simulate odometry separately)
    gt: Trajectory  # ground-truth body poses of the keyframes
    camera: CameraModel
    T_body_camera: np.ndarray


def demo_keyframes(extractor, *, laps: float = 2.0, rate_hz: float = 1.0, width: int = 320, height: int = 240,
                   seed: int = 0, sensor: str = "rgbd", ids=None, cache: bool = True) -> DemoKeyframes:
    """Render the demo world at keyframe rate; ``sensor`` 'rgbd' (depth image) or 'stereo' (right image).

    ``ids(k) -> int``: the keyframe ids (default ``k``). Features are attached to every keyframe.
    """
    if sensor not in ("rgbd", "stereo"):
        raise ValueError(f"sensor must be 'rgbd' or 'stereo', got {sensor!r}")
    world = build_world(seed)
    traj = make_trajectory("laps", laps=laps, rate_hz=rate_hz, seed=seed)
    cam = demo_camera(width, height, baseline=0.12 if sensor == "stereo" else None)
    T_bc = T_body_camera()
    T_lr = T_left_right(cam.baseline) if cam.baseline is not None else None  # set for stereo only
    fc = FeatureCache(extractor) if cache else None
    virtual_log = (cache_dir() / "sim"
                   / f"demo-keyframes-seed{seed}-laps{laps:g}-{rate_hz:g}hz-{width}x{height}-v{__version__}")
    kfs = []
    for k in range(len(traj)):
        T_wc = traj.poses[k] @ T_bc
        img, depth = render(world, cam, T_wc)
        right = render(world, cam, T_wc @ T_lr)[0] if T_lr is not None else None
        stamp = int(traj.stamps[k])
        feats = fc.extract(virtual_log, "/camera/left", stamp, img) if fc is not None else extractor.extract(img)
        kid = int(ids(k)) if ids is not None else k
        kfs.append(Keyframe(kid, stamp, traj.poses[k].copy(), image=img, camera=cam, T_body_camera=T_bc,
                            depth=depth if sensor == "rgbd" else None, right_image=right, features=feats))
    return DemoKeyframes(kfs, traj, cam, T_bc)


def demo_loop_nees(extractor, *, sensor: str = "rgbd", laps: float = 2.0, width: int = 320, height: int = 240,
                   conf=None, frames: DemoKeyframes | None = None):
    """The loop detector run on demo-world keyframes (:func:`demo_keyframes`): the
    :class:`~slam_lcd.eval.nees.NeesReport` of its loops.

    ``frames``: already rendered :class:`DemoKeyframes` (a test's session fixture).
    """
    from ..eval.nees import detector_nees, run_detector  # lazy: scipy, and OpenCV with the detector

    dk = frames or demo_keyframes(extractor, laps=laps, width=width, height=height, sensor=sensor)
    return detector_nees(run_detector(dk, extractor, conf), dk)
