"""The rosbags type stores slam-lcd builds and writes messages with.

Messages are built as ROS2 (Humble) objects; the ROS1 writer converts their CDR bytes to
ROS1 wire format (rosbags inserts the ROS1 ``Header.seq``) and describes them with the
ROS1 Noetic definitions, whose md5sums ROS1 tools expect.
"""
from __future__ import annotations

from functools import cache

from rosbags.typesys import Stores, get_typestore


@cache
def ros2_store():
    """ROS2 Humble type store (the types of every message slam-lcd builds)."""
    return get_typestore(Stores.ROS2_HUMBLE)


@cache
def ros1_store():
    """ROS1 Noetic type store (definitions and md5sums for ROS1 bags), plus tf2_msgs/TFMessage,
    which rosbags' Noetic store lacks (same definition as ROS1's tf2_msgs/TFMessage)."""
    from rosbags.typesys import get_types_from_msg

    store = get_typestore(Stores.ROS1_NOETIC)
    store.register(get_types_from_msg("geometry_msgs/TransformStamped[] transforms", "tf2_msgs/msg/TFMessage"))
    return store
