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

    @property
    def world(self):
        return build_world(self.world_seed, self.appearance)  # cached; built only when rendering
