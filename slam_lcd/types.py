"""Shared vocabulary of types.

Conventions (used everywhere in slam-lcd):
- a stamp is an ``int`` of nanoseconds;
- a pose is a 4x4 float64 homogeneous matrix ``T_a_b`` that maps points from frame b to
  frame a; a bare "pose" is ``T_world_body``;
- gtsam appears only inside :mod:`slam_lcd.backend` and :mod:`slam_lcd.loop_factor` (one loop as a
  factor; GTSAM imported inside its functions).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .loop_factor import between_factor

Stamp = int


@dataclass
class Trajectory:
    """Time-stamped poses ``T_world_body``; stamps are int64 nanoseconds, sorted."""

    stamps: np.ndarray  # (N,) int64 ns
    poses: np.ndarray  # (N, 4, 4) float64
    covariances: np.ndarray | None = None  # (N, 6, 6), order [rx ry rz tx ty tz] unless noted
    frame_id: str = "world"
    child_frame_id: str = "body"

    def __post_init__(self):
        self.stamps = np.asarray(self.stamps, dtype=np.int64).reshape(-1)
        self.poses = np.asarray(self.poses, dtype=np.float64).reshape(-1, 4, 4)
        if len(self.stamps) != len(self.poses):
            raise ValueError(f"{len(self.stamps)} stamps but {len(self.poses)} poses")

    def __len__(self) -> int:
        return len(self.stamps)

    @property
    def positions(self) -> np.ndarray:
        return self.poses[:, :3, 3]

    @property
    def times_s(self) -> np.ndarray:
        return self.stamps.astype(np.float64) * 1e-9

    def path_length(self) -> float:
        p = self.positions
        return float(np.linalg.norm(np.diff(p, axis=0), axis=1).sum()) if len(p) > 1 else 0.0


@dataclass
class CameraModel:
    """Pinhole camera with optional distortion (``model`` in {'none','plumb_bob','equidistant'})."""

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    distortion_model: str = "none"
    D: np.ndarray = field(default_factory=lambda: np.zeros(0))
    baseline: float | None = None  # stereo baseline in metres (rectified pair), if any

    @property
    def K(self) -> np.ndarray:
        return np.array([[self.fx, 0, self.cx], [0, self.fy, self.cy], [0, 0, 1.0]])


@dataclass
class Features:
    """Keypoints and descriptors of one image.

    ``descriptors`` are float32 (N, 256) unit vectors for SuperPoint, uint8 (N, 32) for ORB.
    ``image_size`` is (width, height).
    """

    keypoints: np.ndarray  # (N, 2) float32 pixels (x, y)
    scores: np.ndarray  # (N,) float32
    descriptors: np.ndarray  # (N, D)
    image_size: tuple[int, int]
    kind: str = "superpoint"

    def __len__(self) -> int:
        return len(self.keypoints)


@dataclass
class Keyframe:
    """One keyframe handed to loop detection and the back end."""

    id: int
    stamp: Stamp
    T_world_body: np.ndarray  # odometry pose (4x4)
    image: np.ndarray | None = None  # grayscale uint8 or float
    camera: CameraModel | None = None
    T_body_camera: np.ndarray = field(default_factory=lambda: np.eye(4))
    depth: np.ndarray | None = None  # metric depth (float32, metres), aligned with image
    right_image: np.ndarray | None = None  # rectified stereo partner
    covariance_since_last: np.ndarray | None = None  # 6x6 odometry covariance since previous keyframe
    features: Features | None = None
    landmarks: np.ndarray | None = None  # (N, 3) camera-frame points per keypoint (NaN where unknown)
    colour: np.ndarray | None = None  # the colour image (RGB uint8) when the camera has colour: the map cloud's colours
    # the odometry broke before this keyframe (tracking lost): it opens a new segment of the pose graph
    segment_start: bool = False
    # where covariance_since_last comes from: "given" (the log's odometry covariances) or "model" (the
    # front end's motion model: the log gave none, all-zero ones, or frontend.odom_covariance is "model")
    covariance_source: str = "given"


@dataclass
class LoopCandidate:
    query_id: int
    match_id: int
    bow_score: float


@dataclass
class LoopClosure:
    """A verified loop: ``T_match_query`` maps points of the query body frame into the match body frame."""

    query_id: int
    match_id: int
    T_match_query: np.ndarray  # 4x4
    information: np.ndarray  # 6x6, order [rx ry rz tx ty tz] (GTSAM Pose3 tangent order)
    evidence: dict[str, Any] = field(default_factory=dict)
    query_stamp: Stamp | None = None
    match_stamp: Stamp | None = None

    def between_factor(self, key_match: int, key_query: int, *, kernel=None, kernel_width: float = 3.0):
        """This loop as ``gtsam.BetweenFactorPose3(key_match, key_query, Pose3(T_match_query))``.

        Noise: Gaussian from ``information`` (right perturbation of ``T_match_query``, tangent
        order ``[rx ry rz tx ty tz]``, body frames), wrapped in a robust kernel when ``kernel``
        names one ('huber', 'cauchy', 'dcs', 'geman_mcclure') or is a GTSAM mEstimator.
        See :func:`slam_lcd.loop_factor.between_factor` (GTSAM is imported inside it).
        """
        return between_factor(self, key_match, key_query, kernel=kernel, kernel_width=kernel_width)


@dataclass
class Rectangles:
    """Flat rectangles ``origin + a*u + b*v``, ``a`` in ``[0, width]``, ``b`` in ``[0, height]`` (unit ``u``, ``v``).

    The true surfaces of a simulated world (:func:`slam_lcd.sim.world_surfaces`), against which
    a map's points are measured (:func:`slam_lcd.cloud.surface_distances`): (R, 3) arrays and (R,) sizes.
    """

    origins: np.ndarray
    u: np.ndarray
    v: np.ndarray
    widths: np.ndarray
    heights: np.ndarray

    def __len__(self) -> int:
        return len(self.origins)
