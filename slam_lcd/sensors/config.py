"""Section `sensors`: which topics of a log a run reads when no flag names them, and depth units.

Why in the config: a dataset preset (``--config euroc``, ``tum-rgbd``, ``kitti``) names its
bags' topics once, so ``slam-lcd run BAG --config euroc`` needs no topic flag. A flag
(``--image-topic`` …) always wins; a topic named here that the log lacks is skipped (said
in a warning) and the automatic choice (:mod:`slam_lcd.sensors.topics`) is made instead.
"""
from __future__ import annotations

from dataclasses import dataclass, field

from ..value_range import ranged


@dataclass
class SensorsConfig:
    image_topic: str | None = None  # camera image (the left camera of a pair); None: the log's only image topic
    right_topic: str | None = None  # second camera of a stereo pair; None: found by name or calibration
    depth_topic: str | None = None  # depth image registered to the camera; None: the depth topic beside the camera
    odom_topic: str | None = None  # odometry; None: the log's only nav_msgs/Odometry (else the built-in VO)
    # ground truth, first one the log has: TOPIC (a pose or PointStamped) or TOPIC:PARENT:CHILD (a TF chain)
    gt_topics: list[str] = field(default_factory=list)
    # metres per unit of a 16-bit depth image (16UC1 / mono16; ROS: millimetres)
    depth_unit_m: float = ranged(0.001, "(0, inf)")
