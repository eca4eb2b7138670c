"""Writers: logs written by slam-lcd read back by slam-lcd and by plain rosbags / mcap with equal content."""
from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np
import pytest

from slam_lcd.errors import InputError
from slam_lcd.io import message_builders as M
from slam_lcd.io import open_log, read_trajectory_from_log
from slam_lcd.io.config import IOConfig
from slam_lcd.io.decode import decode_camera_info, decode_compressed_image, decode_image, decode_pose
from slam_lcd.io.writers import copy_topics, open_writer, write_trajectory_log
from slam_lcd.types import CameraModel, Trajectory

CAM = CameraModel(640, 480, 525.0, 526.0, 319.5, 239.5, "plumb_bob", np.array([0.1, -0.2, 0.001, 0.002, 0.05]))


def _pose(i: int) -> np.ndarray:
    a = 0.1 * i
    T = np.eye(4)
    T[:3, :3] = [[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]]
    T[:3, 3] = [i * 0.5, np.sin(i), 0.1 * i]
    return T


def _content(n=4, seed=0):
    """The demo-like content: (topic, stamp, payload) with images, depth, camera info, odometry, poses, TF."""
    rng = np.random.default_rng(seed)
    items = []
    for i in range(n):
        s = 1_700_000_000_000_000_000 + i * 100_000_000
        gray = rng.integers(0, 256, (480, 640), dtype=np.uint8)
        rgb = rng.integers(0, 256, (24, 32, 3), dtype=np.uint8)
        depth = rng.random((48, 64), dtype=np.float32) * 5
        cov = np.diag([1e-4, 2e-4, 3e-4, 1e-2, 2e-2, 3e-2])
        items += [
            ("/camera/image_raw", s, M.image_msg(gray, s, "camera")),
            ("/camera/color", s, M.image_msg(rgb, s, "camera", "bgr8")),
            ("/camera/depth", s, M.image_msg(depth, s, "camera")),
            ("/camera/camera_info", s, M.camera_info_msg(CAM, s, "camera")),
            ("/camera/compressed", s, M.compressed_image_msg(gray, s, "camera", "png")),
            ("/odom", s, M.odometry_msg(_pose(i), cov, s, "odom", "base_link")),
            ("/ground_truth/pose", s, M.pose_stamped_msg(_pose(i), s, "world")),
            ("/tf", s, M.tf_message([(_pose(i), s, "odom", "base_link")])),
        ]
    items.append(("/path", s, M.path_msg(Trajectory([1, 2, 3], [_pose(0), _pose(1), _pose(2)]), "map")))
    return items


def _write(path, fmt, items, conf=None):
    with open_writer(path, fmt, conf=conf) as w:
        for topic, s, msg in items:
            w.write(topic, msg, s)
    return path


def _digest(path: Path) -> str:
    h = hashlib.sha256()
    files = sorted(p for p in path.rglob("*") if p.is_file()) if path.is_dir() else [path]
    for f in files:
        h.update(f.name.encode())
        h.update(f.read_bytes())
    return h.hexdigest()


def _summary(topic, msgtype, msg):
    """Comparable content of one message, from plain attribute access (works on ROS1/ROS2 objects)."""
    if msgtype == "sensor_msgs/msg/Image":
        return (msg.encoding, msg.height, msg.width, msg.step, bytes(msg.data))
    if msgtype == "sensor_msgs/msg/CompressedImage":
        return (msg.format, bytes(msg.data))
    if msgtype == "sensor_msgs/msg/CameraInfo":
        K = getattr(msg, "k", None) if hasattr(msg, "k") else msg.K
        D = getattr(msg, "d", None) if hasattr(msg, "d") else msg.D
        return (msg.width, msg.height, msg.distortion_model, tuple(K), tuple(D))
    if msgtype == "nav_msgs/msg/Odometry":
        p = msg.pose.pose
        return (msg.child_frame_id, p.position.x, p.position.y, p.orientation.z, tuple(msg.pose.covariance))
    if msgtype == "geometry_msgs/msg/PoseStamped":
        return (msg.header.frame_id, msg.pose.position.x, msg.pose.position.y, msg.pose.orientation.w)
    if msgtype == "tf2_msgs/msg/TFMessage":
        t = msg.transforms[0]
        return (t.header.frame_id, t.child_frame_id, t.transform.translation.x, t.transform.rotation.z)
    if msgtype == "nav_msgs/msg/Path":
        return tuple(p.pose.position.x for p in msg.poses)
    raise AssertionError(msgtype)


def _stamp(msg):
    h = msg.header
    return h.stamp.sec * 1_000_000_000 + h.stamp.nanosec


def _read_with_rosbags(path: Path):
    from rosbags.highlevel import AnyReader

    out = []
    with AnyReader([path]) as r:
        for c, t, raw in r.messages():
            msg = r.deserialize(raw, c.msgtype)
            out.append((c.topic, t, _summary(c.topic, c.msgtype, msg)))
    return out


@pytest.mark.parametrize("fmt,name", [("mcap", "out.mcap"), ("rosbag2", "out_bag2"), ("rosbag1", "out.bag")])
def test_round_trip_slam_lcd_and_rosbags(tmp_path, fmt, name):
    items = _content()
    path = _write(tmp_path / name, fmt, items)
    expected = [(t, s, _summary(t, m.__msgtype__, m)) for t, s, m in items]
    # plain rosbags sees exactly what we wrote, in time order
    got = _read_with_rosbags(path)
    key = lambda x: (x[1], x[0])  # noqa: E731
    assert sorted(got, key=key) == sorted(expected, key=key)
    # slam-lcd reads it back and decodes to the arrays we started from
    rng = np.random.default_rng(0)
    with open_log(path) as r:
        assert r.format == fmt
        assert {k: v.count for k, v in r.topics.items()} == {t: sum(1 for x in items if x[0] == t)
                                                              for t in {x[0] for x in items}}
        msgs = list(r.messages())
    assert [m.log_time for m in msgs] == sorted(m.log_time for m in msgs)
    by = {}
    for m in msgs:
        by.setdefault(m.topic, []).append(m)
    for i in range(4):
        gray = rng.integers(0, 256, (480, 640), dtype=np.uint8)
        rgb = rng.integers(0, 256, (24, 32, 3), dtype=np.uint8)
        depth = rng.random((48, 64), dtype=np.float32) * 5
        s = 1_700_000_000_000_000_000 + i * 100_000_000
        assert by["/camera/image_raw"][i].stamp == s
        np.testing.assert_array_equal(decode_image(by["/camera/image_raw"][i].msg), gray)
        np.testing.assert_array_equal(decode_image(by["/camera/color"][i].msg), rgb)
        np.testing.assert_array_equal(decode_image(by["/camera/depth"][i].msg), depth)
        np.testing.assert_array_equal(decode_compressed_image(by["/camera/compressed"][i].msg), gray)
        T, cov = decode_pose(by["/odom"][i].msg)
        np.testing.assert_allclose(T, _pose(i), atol=1e-12)
        np.testing.assert_allclose(cov, np.diag([1e-4, 2e-4, 3e-4, 1e-2, 2e-2, 3e-2]), atol=1e-15)
        np.testing.assert_allclose(decode_pose(by["/ground_truth/pose"][i].msg)[0], _pose(i), atol=1e-12)
    cam = decode_camera_info(by["/camera/camera_info"][0].msg)
    assert (cam.fx, cam.fy, cam.cx, cam.cy, cam.distortion_model) == (525.0, 526.0, 319.5, 239.5, "plumb_bob")
    np.testing.assert_array_equal(cam.D, CAM.D)


def test_mcap_is_readable_by_mcap_ros2_decoder(tmp_path):
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    path = _write(tmp_path / "out.mcap", "mcap", _content(2))
    with open(path, "rb") as fh:
        reader = make_reader(fh, decoder_factories=[DecoderFactory()])
        assert reader.get_header().profile == "ros2"
        schemas = {s.name: s.encoding for s in reader.get_summary().schemas.values()}
        decoded = list(reader.iter_decoded_messages())
    assert schemas["sensor_msgs/msg/Image"] == "ros2msg"
    img = next(d for _s, ch, _m, d in decoded if ch.topic == "/camera/image_raw")
    assert (img.width, img.height, img.encoding) == (640, 480, "mono8")
    path_msg = next(d for _s, ch, _m, d in decoded if ch.topic == "/path")
    assert [p.pose.position.x for p in path_msg.poses] == [0.0, 0.5, 1.0]


@pytest.mark.parametrize(
    "fmt,name,storage",
    [("mcap", "a.mcap", "mcap"), ("rosbag2", "a_bag2", "mcap"), ("rosbag2", "a_bag2", "sqlite3"),
     ("rosbag1", "a.bag", "mcap")],
)
def test_writers_are_deterministic(tmp_path, fmt, name, storage):
    items = _content(2)
    conf = IOConfig(rosbag2_storage=storage)
    a = _digest(_write(tmp_path / "1" / name, fmt, items, conf))
    b = _digest(_write(tmp_path / "2" / name, fmt, items, conf))
    assert a == b
    c = _digest(_write(tmp_path / "3" / name, fmt, _content(2, seed=1), conf))
    assert c != a  # the digest does see the content


def test_rosbag2_sqlite3_storage(tmp_path):
    items = _content(2)
    path = _write(tmp_path / "sq", "rosbag2", items, IOConfig(rosbag2_storage="sqlite3"))
    assert (path / "sq.db3").is_file()
    with open_log(path) as r:
        assert r.topics["/camera/image_raw"].count == 2
        img = decode_image(next(iter(r.messages("/camera/image_raw"))).msg)
    assert img.shape == (480, 640)


def test_failed_write_leaves_nothing_and_input_is_protected(tmp_path, shared_data):
    out = tmp_path / "x.mcap"
    with pytest.raises(RuntimeError):
        with open_writer(out) as w:
            w.write("/p", M.pose_stamped_msg(np.eye(4), 1, "map"), 1)
            raise RuntimeError("boom")
    assert not out.exists() and list(tmp_path.iterdir()) == []
    src = tmp_path / "in.mcap"
    _write(src, "mcap", _content(1))
    before = src.read_bytes()
    with pytest.raises(InputError, match="same as an input"):
        write_trajectory_log(src, Trajectory([1], [np.eye(4)]), copy_from=src)
    assert src.read_bytes() == before
    # an unrelated folder is never replaced by a rosbag2 output; a previous bag is
    keep = tmp_path / "results"
    keep.mkdir()
    (keep / "notes.txt").write_text("mine")
    with pytest.raises(InputError, match="not a rosbag2 bag"):
        _write(keep, "rosbag2", _content(1))
    assert (keep / "notes.txt").read_text() == "mine"
    bag = _write(tmp_path / "bag2", "rosbag2", _content(1))
    _write(bag, "rosbag2", _content(2))
    with open_log(bag) as r:
        assert r.topics["/odom"].count == 2


@pytest.mark.parametrize("src_name,fmt,name",
                         [("nav2_turtlebot.mcap", "rosbag1", "o.bag"), ("tf_example.bag", "mcap", "o.mcap")])
def test_copy_topics_between_ros1_and_ros2(tmp_path, shared_data, src_name, fmt, name):
    src = shared_data / "bags" / src_name
    with open_log(src) as r, open_writer(tmp_path / name, fmt) as w:
        counts = copy_topics(r, w, ["/tf", "/tf_static"])
    with open_log(src) as a, open_log(tmp_path / name) as b:
        assert {k: v.count for k, v in b.topics.items()} == counts == {t: a.topics[t].count
                                                                       for t in ("/tf", "/tf_static")}
        ma, mb = list(a.messages("/tf")), list(b.messages("/tf"))
    assert [m.log_time for m in ma] == [m.log_time for m in mb]
    assert [m.stamp for m in ma] == [m.stamp for m in mb]
    xa = [[t.transform.translation.x for t in m.msg.transforms] for m in ma]
    xb = [[t.transform.translation.x for t in m.msg.transforms] for m in mb]
    assert xa == xb


def test_write_trajectory_log_with_copied_topics(tmp_path, shared_data):
    src = shared_data / "bags" / "nav2_turtlebot.mcap"
    odo = read_trajectory_from_log(src, "/odom")
    traj = Trajectory(odo.stamps[::10], odo.poses[::10])
    out = tmp_path / "corrected.mcap"
    counts = write_trajectory_log(out, traj, copy_from=src, copy_topics=["/odom", "/tf_static"],
                                  child_frame_id="base_corrected")
    n = len(traj)
    assert counts == {"/slam_lcd/corrected": n, "/tf": n, "/slam_lcd/corrected/path": 1, "/odom": 2639, "/tf_static": 1}
    back = read_trajectory_from_log(out, "/slam_lcd/corrected")
    np.testing.assert_array_equal(back.stamps, traj.stamps)
    np.testing.assert_allclose(back.poses, traj.poses, atol=1e-12)
    assert back.frame_id == "map"
    via_tf = read_trajectory_from_log(out, "/tf", parent_frame="map", child_frame="base_corrected")
    np.testing.assert_allclose(via_tf.poses, traj.poses, atol=1e-12)
    with open_log(out) as r:
        times = [m.log_time for m in r.raw_messages()]
        path_msg = next(iter(r.messages("/slam_lcd/corrected/path"))).msg
    assert times == sorted(times)
    assert len(path_msg.poses) == n
