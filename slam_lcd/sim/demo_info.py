"""What :func:`slam_lcd.sim.demo_log.make_demo_log` wrote, and its summary as the CLI prints it."""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..types import CameraModel

if TYPE_CHECKING:
    from .kinect import KinectDepthModel


@dataclass
class DemoLogInfo:
    """What :func:`make_demo_log` wrote."""

    path: Path
    format: str
    frames: int
    duration_s: float
    path_length_m: float
    topics: dict[str, dict] = field(default_factory=dict)  # topic -> {type, count, rate_hz}
    loop_pairs_path: Path | None = None
    n_loop_pairs: int = 0
    drift: dict = field(default_factory=dict)
    camera: CameraModel | None = None
    T_body_camera: np.ndarray | None = None
    wall_s: float = 0.0
    seed: int = 0
    kind: str = "laps"
    layout: str = "demo"
    depth_model: KinectDepthModel | None = None  # the depth sensor model the depth images carry (None: exact depth)
    calibration_path: Path | None = None  # the Kalibr camchain written beside the log (layout euroc)
    session: int | None = None  # the session preset (slam_lcd.sim.sessions), None: a plain demo log
    world_seed: int = 0
    world_frame: str = "world"  # frame of the ground truth
    start_at: float = 0.0  # arc length (m) of the start point along the route's centre line
    lighting: float = 0.0  # offset added to the lighting epoch of every frame
    exposure: float = 1.0
    odom_at_start: bool = False  # odometry in its own frame (identity at the first stamp)
    appearance: str = "day"  # the world's appearance state (slam_lcd.sim.appearance)
    stretches: list[str] = field(default_factory=list)  # bad stretches injected, as flags ('--dark 5:2')

    def summary(self) -> str:
        lines = [
            f"wrote {self.path} ({self.format}): {self.frames} frames, {self.duration_s:.1f} s, "
            f"{self.path_length_m:.1f} m ({self.kind}, seed {self.seed}) in {self.wall_s:.1f} s",
        ]
        if self.session is not None:
            lines.append(f"session {self.session}: world {self.world_seed} (ground truth in "
                         f"'{self.world_frame}'), start "
                         f"{self.start_at:g} m along the route, lighting +{self.lighting:g}, exposure "
                         f"{self.exposure:g}; odometry in its own frame (identity at the first stamp)")
        if self.appearance != "day":
            lines.append(f"appearance: {self.appearance} (docs/sim_sessions.md)")
        if self.stretches:
            lines.append(f"bad stretches: {', '.join(self.stretches)} (docs/sim_stretches.md)")
        lines += [
            (f"odometry end drift {self.drift.get('end_error_m', float('nan')):.2f} m = "
             f"{self.drift.get('drift_percent', float('nan')):.2f} % of the path "
             f"(yaw {self.drift.get('end_yaw_error_deg', float('nan')):+.1f} deg)") if self.layout == "demo" else
            f"layout {self.layout}: no odometry topic (the run's built-in visual odometry is the source)",
            f"ground-truth loop pairs: {self.n_loop_pairs} -> {self.loop_pairs_path}",
        ]
        if self.depth_model is not None:
            lines.append(f"depth: {self.depth_model.describe()}")
        if self.calibration_path is not None:
            lines.append(f"calibration (Kalibr camchain): {self.calibration_path}")
        for t, d in self.topics.items():
            lines.append(f"  {t:32s} {d['type']:30s} {d['count']:6d} msgs  {d['rate_hz']:5.1f} Hz")
        return "\n".join(lines)
