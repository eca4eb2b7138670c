"""Everything of a demo log but its images: camera, stamps, ground truth, odometry, lighting epochs.

Why a module of its own: :mod:`slam_lcd.sim.demo_log` builds a scenario and renders its frames,
:mod:`slam_lcd.sim.demo_writers` lays the same scenario out as files; both read this one type,
and neither needs the other to know what a scenario holds.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..types import CameraModel, Trajectory
from . import rig
from .world import build_world


@dataclass
class DemoScenario:
    camera: CameraModel
    T_bc: np.ndarray
    cam_stamps: np.ndarray
    odo_stamps: np.ndarray
    gt_cam: Trajectory
    gt_odo: Trajectory
    odom: Trajectory
    laps: np.ndarray  # lighting epoch per camera frame
    world_seed: int
    exposure: float = 1.0  # global exposure factor of the renderer
    world_frame: str = rig.WORLD_FRAME  # frame of the ground truth
    odom_at_start: bool = False  # the odometry starts at the identity (its own frame), not at the world pose
    appearance: str = "day"  # the world's appearance state (slam_lcd.sim.appearance)
    cam_written: np.ndarray | None = None  # bool per camera frame: written (None: all; slam_lcd.sim.stretches)
    odom_written: np.ndarray | None = None  # bool per odometry sample: written (None: all)

    def written_frames(self) -> list[int]:
        """Indices of the camera frames the log holds, in order."""
        if self.cam_written is None:
            return list(range(len(self.cam_stamps)))
        return [int(i) for i in np.flatnonzero(self.cam_written)]

    def odom_is_written(self, i: int) -> bool:
        return self.odom_written is None or bool(self.odom_written[i])

    @property
    def world(self):
        return build_world(self.world_seed, self.appearance)  # cached; built only when rendering
