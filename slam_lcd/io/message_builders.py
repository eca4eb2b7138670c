"""Builders of ROS messages (rosbags ROS2 objects) for the writers in :mod:`slam_lcd.io.writers`.

Every builder returns an object of the ROS2 Humble type store; all three writers (MCAP,
rosbag2, rosbag1) accept them. Stamps are int nanoseconds; poses are 4x4 ``T_frame_child``;
covariances are 6x6 in GTSAM order/body frame (see :mod:`slam_lcd.io.transforms`).
Colour images are given as RGB (the convention :func:`slam_lcd.io.decode.decode_image`
returns), whatever the stored encoding, so that write-then-read is the identity.
"""
from __future__ import annotations

from collections.abc import Iterable

import cv2
import numpy as np

from ..errors import InvalidPoseError, MessageEncodingError
from ..types import CameraModel, Trajectory
from .decode import IMAGE_ENCODINGS
from .transforms import gtsam_cov_to_ros, tq_from_pose, tq_from_poses
from .typestores import ros2_store

_T = ros2_store().types
Time = _T["builtin_interfaces/msg/Time"]
Header = _T["std_msgs/msg/Header"]
Point = _T["geometry_msgs/msg/Point"]
Vector3 = _T["geometry_msgs/msg/Vector3"]
Quaternion = _T["geometry_msgs/msg/Quaternion"]
Pose = _T["geometry_msgs/msg/Pose"]
PoseStamped = _T["geometry_msgs/msg/PoseStamped"]
PointStamped = _T["geometry_msgs/msg/PointStamped"]
PoseWithCovariance = _T["geometry_msgs/msg/PoseWithCovariance"]
PoseWithCovarianceStamped = _T["geometry_msgs/msg/PoseWithCovarianceStamped"]
Twist = _T["geometry_msgs/msg/Twist"]
TwistWithCovariance = _T["geometry_msgs/msg/TwistWithCovariance"]
Transform = _T["geometry_msgs/msg/Transform"]
TransformStamped = _T["geometry_msgs/msg/TransformStamped"]
Odometry = _T["nav_msgs/msg/Odometry"]
Path = _T["nav_msgs/msg/Path"]
TFMessage = _T["tf2_msgs/msg/TFMessage"]
Image = _T["sensor_msgs/msg/Image"]
CompressedImage = _T["sensor_msgs/msg/CompressedImage"]
CameraInfo = _T["sensor_msgs/msg/CameraInfo"]
RegionOfInterest = _T["sensor_msgs/msg/RegionOfInterest"]


def stamp_msg(stamp_ns: int):
    """builtin_interfaces/Time of an int-nanosecond stamp (must be >= 0)."""
    stamp_ns = int(stamp_ns)
    if stamp_ns < 0:
        raise InvalidPoseError(f"negative stamp {stamp_ns} ns cannot be written as a ROS time")
    return Time(sec=stamp_ns // 1_000_000_000, nanosec=stamp_ns % 1_000_000_000)


def header(stamp_ns: int, frame_id: str):
    return Header(stamp=stamp_msg(stamp_ns), frame_id=str(frame_id))


def _pose_from(t, q):
    """geometry_msgs/Pose of a translation and a quaternion (x, y, z, w) already checked."""
    return Pose(position=Point(x=float(t[0]), y=float(t[1]), z=float(t[2])),
                orientation=Quaternion(x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3])))


def _transform_from(t, q):
    """geometry_msgs/Transform of a translation and a quaternion (x, y, z, w) already checked."""
    return Transform(translation=Vector3(x=float(t[0]), y=float(t[1]), z=float(t[2])),
                     rotation=Quaternion(x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3])))


def pose_msg(T: np.ndarray, what: str = "pose"):
    """geometry_msgs/Pose of a 4x4 pose (refuses NaN and non-rotations)."""
    return _pose_from(*tq_from_pose(T, what))


def pose_stamped_msgs(Ts: np.ndarray, stamps_ns, frame_id: str) -> list:
    """:func:`pose_stamped_msg` of a stack of poses (one vectorised conversion)."""
    t, q = tq_from_poses(Ts)
    return [PoseStamped(header=header(int(s), frame_id), pose=_pose_from(t[i], q[i]))
            for i, s in enumerate(np.asarray(stamps_ns).tolist())]


def tf_messages(Ts: np.ndarray, stamps_ns, parent: str, child: str) -> list:
    """One single-transform :func:`tf_message` per pose of the stack ``T_parent_child`` (vectorised conversion)."""
    t, q = tq_from_poses(Ts, "transform")
    return [TFMessage(transforms=[TransformStamped(header=header(int(s), parent), child_frame_id=str(child),
                                                   transform=_transform_from(t[i], q[i]))])
            for i, s in enumerate(np.asarray(stamps_ns).tolist())]


def transform_msg(T: np.ndarray, what: str = "transform"):
    return _transform_from(*tq_from_pose(T, what))


# ---- images -------------------------------------------------------------------------------

_AUTO_ENCODING = {
    (np.dtype(np.uint8), 1): "mono8",
    (np.dtype(np.uint8), 3): "rgb8",
    (np.dtype(np.uint8), 4): "rgba8",
    (np.dtype(np.uint16), 1): "mono16",
    (np.dtype(np.float32), 1): "32FC1",
}
# the same encoding table as the decoder: what we write, we read back
_LAYOUT = IMAGE_ENCODINGS


def image_msg(img: np.ndarray, stamp_ns: int, frame_id: str, encoding: str | None = None):
    """sensor_msgs/Image of an array: HxW uint8/uint16/float32 or HxWx3/4 uint8 (RGB/RGBA order).

    ``encoding`` defaults to mono8 / mono16 / 32FC1 / rgb8 / rgba8 from dtype and shape;
    'bgr8'/'bgra8' store the RGB(A) input with the channels swapped.
    """
    img = np.asarray(img)
    channels = 1 if img.ndim == 2 else (img.shape[2] if img.ndim == 3 else -1)
    if encoding is None:
        encoding = _AUTO_ENCODING.get((img.dtype, channels))
        if encoding is None:
            raise MessageEncodingError(f"cannot pick an image encoding for dtype {img.dtype} with shape {img.shape}")
    if encoding not in _LAYOUT:
        raise MessageEncodingError(f"image encoding {encoding!r} cannot be written; supported: {sorted(_LAYOUT)}")
    dtype, nch = _LAYOUT[encoding]
    if img.dtype != np.dtype(dtype) or channels != nch:
        raise MessageEncodingError(
            f"image of dtype {img.dtype} and shape {img.shape} does not fit encoding {encoding!r}"
        )
    if encoding in ("bgr8", "bgra8"):
        img = img[..., [2, 1, 0, 3][:nch]]
    h, w = img.shape[:2]
    data = np.ascontiguousarray(img).astype(img.dtype.newbyteorder("<"), copy=False).reshape(-1).view(np.uint8)
    return Image(
        header=header(stamp_ns, frame_id),
        height=h,
        width=w,
        encoding=encoding,
        is_bigendian=0,
        step=w * nch * np.dtype(dtype).itemsize,
        data=data,
    )


def compressed_image_msg(img: np.ndarray, stamp_ns: int, frame_id: str, fmt: str = "jpeg", quality: int = 90):
    """sensor_msgs/CompressedImage (format 'jpeg' or 'png') of a gray or RGB uint8 image."""
    img = np.asarray(img)
    if fmt not in ("jpeg", "png"):
        raise MessageEncodingError(f"compressed image format {fmt!r} not supported; use 'jpeg' or 'png'")
    if img.ndim == 3 and img.shape[2] == 3:
        bgr = cv2.cvtColor(np.ascontiguousarray(img), cv2.COLOR_RGB2BGR)
    elif img.ndim == 2:
        bgr = img
    else:
        raise MessageEncodingError(f"compressed images must be HxW or HxWx3, got shape {img.shape}")
    if fmt == "jpeg" and img.dtype != np.uint8:
        raise MessageEncodingError(f"jpeg needs uint8 pixels, got {img.dtype}")
    params = [cv2.IMWRITE_JPEG_QUALITY, int(quality)] if fmt == "jpeg" else [cv2.IMWRITE_PNG_COMPRESSION, 3]
    ok, buf = cv2.imencode(".jpg" if fmt == "jpeg" else ".png", bgr, params)
    if not ok:
        raise MessageEncodingError(f"OpenCV could not encode a {img.shape} {img.dtype} image as {fmt}")
    return CompressedImage(header=header(stamp_ns, frame_id), format=fmt, data=buf.reshape(-1))


def camera_info_msg(camera: CameraModel, stamp_ns: int, frame_id: str):
    """sensor_msgs/CameraInfo of a :class:`CameraModel` (rectification identity; P from K and baseline)."""
    model = camera.distortion_model
    D = np.asarray(camera.D, dtype=np.float64).reshape(-1)
    if model == "none":
        model, D = "plumb_bob", np.zeros(5)
    K = np.array([camera.fx, 0, camera.cx, 0, camera.fy, camera.cy, 0, 0, 1], dtype=np.float64)
    Tx = -camera.fx * camera.baseline if camera.baseline else 0.0
    P = np.array([camera.fx, 0, camera.cx, Tx, 0, camera.fy, camera.cy, 0, 0, 0, 1, 0], dtype=np.float64)
    return CameraInfo(
        header=header(stamp_ns, frame_id),
        height=int(camera.height),
        width=int(camera.width),
        distortion_model=model,
        d=D,
        k=K,
        r=np.eye(3).reshape(9),
        p=P,
        binning_x=0,
        binning_y=0,
        roi=RegionOfInterest(x_offset=0, y_offset=0, height=0, width=0, do_rectify=False),
    )


# ---- poses --------------------------------------------------------------------------------


def pose_stamped_msg(T: np.ndarray, stamp_ns: int, frame_id: str):
    return PoseStamped(header=header(stamp_ns, frame_id), pose=pose_msg(T))


def point_stamped_msg(position, stamp_ns: int, frame_id: str):
    """geometry_msgs/PointStamped (a position-only ground truth, e.g. EuRoC's Leica ``/leica/position``)."""
    x, y, z = (float(v) for v in np.asarray(position, dtype=np.float64).reshape(3))
    if not all(np.isfinite([x, y, z])):
        raise InvalidPoseError(f"position ({x}, {y}, {z}) holds NaN or inf")
    return PointStamped(header=header(stamp_ns, frame_id), point=Point(x=x, y=y, z=z))


def pose_with_covariance_stamped_msg(T: np.ndarray, cov6x6: np.ndarray | None, stamp_ns: int, frame_id: str):
    T = np.asarray(T, dtype=np.float64)
    pose = pose_msg(T)
    cov = gtsam_cov_to_ros(cov6x6, T[:3, :3])
    return PoseWithCovarianceStamped(header=header(stamp_ns, frame_id),
                                     pose=PoseWithCovariance(pose=pose, covariance=cov))


def odometry_msg(T: np.ndarray, cov6x6: np.ndarray | None, stamp_ns: int, frame_id: str, child_frame_id: str):
    """nav_msgs/Odometry with pose ``T_frame_child`` and its covariance (GTSAM order); zero twist."""
    T = np.asarray(T, dtype=np.float64)
    pose = pose_msg(T, "odometry pose")
    cov = gtsam_cov_to_ros(cov6x6, T[:3, :3])
    zero = Vector3(x=0.0, y=0.0, z=0.0)
    return Odometry(
        header=header(stamp_ns, frame_id),
        child_frame_id=str(child_frame_id),
        pose=PoseWithCovariance(pose=pose, covariance=cov),
        twist=TwistWithCovariance(twist=Twist(linear=zero, angular=zero), covariance=np.zeros(36)),
    )


def transform_stamped_msg(T: np.ndarray, stamp_ns: int, parent: str, child: str):
    return TransformStamped(header=header(stamp_ns, parent), child_frame_id=str(child), transform=transform_msg(T))


def tf_message(transforms: Iterable[tuple[np.ndarray, int, str, str]]):
    """tf2_msgs/TFMessage of ``[(T_parent_child, stamp_ns, parent, child), ...]``."""
    return TFMessage(transforms=[transform_stamped_msg(T, s, p, c) for T, s, p, c in transforms])


def path_msg(traj: Trajectory, frame_id: str | None = None):
    """nav_msgs/Path of a trajectory; header stamp is the last pose's stamp (0 when empty)."""
    frame = str(frame_id if frame_id is not None else traj.frame_id)
    poses = pose_stamped_msgs(traj.poses, traj.stamps, frame) if len(traj) else []
    last = int(traj.stamps[-1]) if len(traj) else 0
    return Path(header=header(last, frame), poses=poses)


def growing_path_msgs(traj: Trajectory, ends, frame_id: str) -> list:
    """nav_msgs/Path of the first ``e`` poses for each ``e`` in ``ends``; the poses are converted once and shared."""
    frame = str(frame_id)
    poses = pose_stamped_msgs(traj.poses, traj.stamps, frame) if len(traj) else []
    return [Path(header=header(int(traj.stamps[e - 1]), frame), poses=poses[:e]) for e in ends]


# ---- visualisation ------------------------------------------------------------------------

def line_marker(segments, stamp_ns: int, frame_id: str, ns: str, marker_id: int,
                rgba=(0.1, 0.8, 0.2, 1.0), width: float = 0.03):
    """visualization_msgs/Marker LINE_LIST of ``[(p0, p1), ...]`` 3-D segments (m), one colour."""
    T = _T
    Marker = T["visualization_msgs/msg/Marker"]
    ColorRGBA = T["std_msgs/msg/ColorRGBA"]
    Duration = T["builtin_interfaces/msg/Duration"]
    pts = [Point(x=float(p[0]), y=float(p[1]), z=float(p[2])) for seg in segments for p in seg]
    if not all(np.isfinite([pt.x, pt.y, pt.z]).all() for pt in pts):
        raise InvalidPoseError(f"marker {ns}/{marker_id} has NaN/inf points")
    return Marker(
        header=header(stamp_ns, frame_id), ns=str(ns), id=int(marker_id), type=Marker.LINE_LIST, action=Marker.ADD,
        pose=pose_msg(np.eye(4)), scale=Vector3(x=float(width), y=0.0, z=0.0),
        color=ColorRGBA(r=rgba[0], g=rgba[1], b=rgba[2], a=rgba[3]), lifetime=Duration(sec=0, nanosec=0),
        frame_locked=False, points=pts, colors=[], texture_resource="",
        texture=CompressedImage(header=header(0, ""), format="", data=np.zeros(0, np.uint8)),
        uv_coordinates=[], text="", mesh_resource="",
        mesh_file=T["visualization_msgs/msg/MeshFile"](filename="", data=np.zeros(0, np.uint8)),
        mesh_use_embedded_materials=False)


def marker_array(markers):
    return _T["visualization_msgs/msg/MarkerArray"](markers=list(markers))


def point_cloud2_msg(points: np.ndarray, colours: np.ndarray, stamp_ns: int, frame_id: str):
    """sensor_msgs/PointCloud2 of x y z (float32) and rgb (float32 holding 0x00RRGGBB, as PCL and RViz pack it)."""
    PointCloud2, PointField = _T["sensor_msgs/msg/PointCloud2"], _T["sensor_msgs/msg/PointField"]
    pts = np.asarray(points, np.float32).reshape(-1, 3)
    c = np.asarray(colours, np.uint32).reshape(-1, 3)
    rec = np.empty(len(pts), [("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("rgb", "<u4")])
    rec["x"], rec["y"], rec["z"] = pts[:, 0], pts[:, 1], pts[:, 2]
    rec["rgb"] = (c[:, 0] << 16) | (c[:, 1] << 8) | c[:, 2]
    fields = [PointField(name=n, offset=4 * i, datatype=PointField.FLOAT32, count=1) for i, n in enumerate("xyz")]
    fields.append(PointField(name="rgb", offset=12, datatype=PointField.FLOAT32, count=1))
    return PointCloud2(header=header(stamp_ns, frame_id), height=1, width=len(pts), fields=fields,
                       is_bigendian=False, point_step=16, row_step=16 * len(pts),
                       data=np.frombuffer(rec.tobytes(), np.uint8), is_dense=True)
