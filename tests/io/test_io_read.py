"""Reading the real shared logs: counts, first/last stamps and poses against values obtained
independently (plain rosbags for ROS1/rosbag2, the mcap library + mcap_ros2 decoder for MCAP)."""
from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation, Slerp

from slam_lcd.io import open_log, read_trajectory_from_log
from slam_lcd.io.decode import decode_pose
from slam_lcd.io.tf import TfBuffer, TfLookupError


@pytest.fixture(scope="module")
def bags(shared_data) -> Path:
    return shared_data / "bags"


def _ns(t) -> int:
    return int(t.sec) * 1_000_000_000 + int(t.nanosec)


def _T(t, q) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = Rotation.from_quat([q.x, q.y, q.z, q.w]).as_matrix()
    T[:3, 3] = [t.x, t.y, t.z]
    return T


def _rosbags_poses(path: Path, topic: str):
    """(log times, header stamps, 4x4 poses) of a PoseStamped topic read with plain rosbags."""
    from rosbags.highlevel import AnyReader

    logs, stamps, poses = [], [], []
    with AnyReader([path]) as r:
        conns = [c for c in r.connections if c.topic == topic]
        for c, t, raw in r.messages(connections=conns):
            m = r.deserialize(raw, c.msgtype)
            logs.append(t)
            stamps.append(_ns(m.header.stamp))
            poses.append(_T(m.pose.position, m.pose.orientation))
    return logs, stamps, np.array(poses)


def test_ros1_bag_counts_stamps_and_poses(bags):
    path = bags / "ROS_example.bag"
    ref_logs, ref_stamps, ref_poses = _rosbags_poses(path, "groundtruth")
    with open_log(path) as r:
        assert r.format == "rosbag1"
        assert {k: v.count for k, v in r.topics.items()} == {"groundtruth": 12765, "ORB-SLAM": 8362, "S-PTAM": 5439}
        assert r.topics["groundtruth"].msgtype == "geometry_msgs/msg/PoseStamped"
        msgs = list(r.messages(["/groundtruth"]))  # a leading slash is accepted
    assert len(msgs) == len(ref_stamps) == 12765
    assert [m.log_time for m in msgs] == ref_logs
    assert [m.stamp for m in msgs] == ref_stamps
    assert msgs[0].stamp == ref_stamps[0] and msgs[-1].stamp == ref_stamps[-1]
    poses = np.array([decode_pose(m.msg)[0] for m in msgs])
    np.testing.assert_allclose(poses, ref_poses, atol=1e-12)


def test_ros1_bag_is_time_ordered_across_topics(bags):
    with open_log(bags / "ROS_example.bag") as r:
        times = [m.log_time for m in r.raw_messages()]
        assert len(times) == r.message_count == 26566
        assert r.start_ns == times[0] and r.end_ns == times[-1]
    assert all(a <= b for a, b in itertools.pairwise(times))


def test_mcap_counts_stamps_and_odometry_against_mcap_library(bags):
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    path = bags / "nav2_turtlebot.mcap"
    ref = {"stamps": [], "logs": [], "poses": [], "cov": []}
    counts = {}
    with open(path, "rb") as fh:
        for _s, ch, msg, dec in make_reader(fh, decoder_factories=[DecoderFactory()]).iter_decoded_messages():
            counts[ch.topic] = counts.get(ch.topic, 0) + 1
            if ch.topic == "/odom":
                ref["stamps"].append(_ns(dec.header.stamp))
                ref["logs"].append(msg.log_time)
                ref["poses"].append(_T(dec.pose.pose.position, dec.pose.pose.orientation))
            if ch.topic == "/amcl_pose":
                ref["cov"].append(np.array(dec.pose.covariance).reshape(6, 6))
    with open_log(path) as r:
        assert r.format == "mcap"
        assert {k: v.count for k, v in r.topics.items()} == counts
        assert r.topics["/odom"].msgtype == "nav_msgs/msg/Odometry"
        msgs = list(r.messages("/odom"))
    assert [m.stamp for m in msgs] == ref["stamps"]
    assert [m.log_time for m in msgs] == ref["logs"]
    decoded = [decode_pose(m.msg) for m in msgs]
    np.testing.assert_allclose(np.array([d[0] for d in decoded]), np.array(ref["poses"]), atol=1e-12)
    assert all(d[1] is None for d in decoded)  # this robot's /odom covariance is all zeros = unknown
    # covariance: ROS [x y z rx ry rz] about parent axes -> GTSAM [r t] in the body frame
    with open_log(path) as r:
        amcl = [decode_pose(m.msg) for m in r.messages("/amcl_pose")]
    assert len(amcl) == len(ref["cov"]) == 135
    T, cov = amcl[-1]
    R = T[:3, :3]
    c = ref["cov"][-1]
    assert c[0, 0] > 0
    np.testing.assert_allclose(cov[3:, 3:], R.T @ c[:3, :3] @ R, atol=1e-15)
    np.testing.assert_allclose(cov[:3, :3], R.T @ c[3:, 3:] @ R, atol=1e-15)
    np.testing.assert_allclose(cov[:3, 3:], R.T @ c[3:, :3] @ R, atol=1e-15)


def test_rosbag2_sqlite_directory_and_ros1_twin_agree(bags):
    """tf_example exists as a ROS1 bag and as a rosbag2 sqlite3 directory with the same content."""
    from rosbags.rosbag2 import Reader

    with Reader(bags / "tf_example") as ref:
        ref_count = ref.message_count
        ref_start = ref.start_time
    with open_log(bags / "tf_example") as r2, open_log(bags / "tf_example.bag") as r1:
        assert (r2.format, r2.storage) == ("rosbag2", "sqlite3")
        assert r2.message_count == ref_count == 518
        assert r2.start_ns == ref_start
        a = list(r2.messages("/tf"))
        b = list(r1.messages("/tf"))
    assert len(a) == len(b) == 517
    assert [m.stamp for m in a] == [m.stamp for m in b]
    ta = [m.msg.transforms[0].transform.translation.x for m in a]
    tb = [m.msg.transforms[0].transform.translation.x for m in b]
    assert ta == tb


def test_stamp_source_log_time(bags):
    with open_log(bags / "nav2_turtlebot.mcap", stamp_source="log_time") as r:
        m = next(iter(r.messages("/odom")))
    assert m.stamp == m.log_time
    with open_log(bags / "nav2_turtlebot.mcap") as r:
        m2 = next(iter(r.messages("/odom")))
    assert m2.stamp == _ns(m2.msg.header.stamp) != m2.log_time  # sim time in headers


def _tf_edges(path: Path):
    """Every transform of /tf and /tf_static read with the mcap library (independent of slam_lcd)."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    static, dynamic = {}, {}
    with open(path, "rb") as fh:
        for _s, ch, _m, dec in make_reader(fh, decoder_factories=[DecoderFactory()]).iter_decoded_messages(
            topics=["/tf", "/tf_static"]
        ):
            for ts in dec.transforms:
                key = (ts.header.frame_id, ts.child_frame_id)
                T = _T(ts.transform.translation, ts.transform.rotation)
                if ch.topic == "/tf_static":
                    static[key] = T
                else:
                    dynamic.setdefault(key, []).append((_ns(ts.header.stamp), T))
    return static, dynamic


def test_tf_static_chain_returns_known_camera_transform(bags):
    path = bags / "nav2_turtlebot.mcap"
    static, _ = _tf_edges(path)
    chain = [
        ("base_link", "shell_link"),
        ("shell_link", "oakd_camera_bracket"),
        ("oakd_camera_bracket", "oakd_link"),
        ("oakd_link", "oakd_rgb_camera_frame"),
        ("oakd_rgb_camera_frame", "oakd_rgb_camera_optical_frame"),
    ]
    expected = np.eye(4)
    for k in chain:
        expected = expected @ static[k]
    buf = TfBuffer.from_log(path)
    got = buf.lookup("base_link", "oakd_rgb_camera_optical_frame", 0)
    np.testing.assert_allclose(got, expected, atol=1e-12)
    # the URDF numbers: camera 5.96 cm behind and 24.353 cm above base_link, optical axes z-forward
    np.testing.assert_allclose(got[:3, 3], [-0.0596, 0.0, 0.24353], atol=1e-9)
    np.testing.assert_allclose(got[:3, :3], [[0, 0, 1], [-1, 0, 0], [0, -1, 0]], atol=1e-9)
    # reverse direction is the inverse
    np.testing.assert_allclose(buf.lookup("oakd_rgb_camera_optical_frame", "base_link", 0) @ got, np.eye(4), atol=1e-12)


def test_tf_dynamic_chain_interpolates(bags):
    """map -> base_link through map->odom (AMCL, ~10 Hz) and odom->base_link, at an odom stamp:
    map->odom must be slerp/lerp-interpolated between its two neighbouring samples."""
    path = bags / "nav2_turtlebot.mcap"
    _, dynamic = _tf_edges(path)
    mo = sorted(dynamic[("map", "odom")], key=lambda x: x[0])
    ob = sorted(dynamic[("odom", "base_link")], key=lambda x: x[0])
    mo_st = np.array([s for s, _ in mo])
    # an odom sample strictly between two distinct map->odom samples, in the middle of the log
    for s, T_ob in ob[len(ob) // 2 :]:  # noqa: B007  T_ob is the sample found, used after the loop
        i = int(np.searchsorted(mo_st, s))
        if 0 < i < len(mo) and mo_st[i - 1] < s < mo_st[i]:
            break
    (s0, A), (s1, B) = mo[i - 1], mo[i]
    a = (s - s0) / (s1 - s0)
    rot = Slerp([0, 1], Rotation.from_matrix([A[:3, :3], B[:3, :3]]))([a]).as_matrix()[0]
    T_mo = np.eye(4)
    T_mo[:3, :3] = rot
    T_mo[:3, 3] = (1 - a) * A[:3, 3] + a * B[:3, 3]
    expected = T_mo @ T_ob
    buf = TfBuffer.from_log(path)
    np.testing.assert_allclose(buf.lookup("map", "base_link", s), expected, atol=1e-9)
    with pytest.raises(TfLookupError, match="not at"):
        buf.lookup("map", "base_link", mo_st[0] - 10**9)
    with pytest.raises(TfLookupError, match="not in the TF tree"):
        buf.lookup("map", "no_such_frame", s)


def test_trajectory_from_odometry_topic_and_tf_pair_agree(bags):
    path = bags / "nav2_turtlebot.mcap"
    odo = read_trajectory_from_log(path, "/odom")
    assert len(odo) == 2639 and odo.frame_id == "odom" and odo.child_frame_id == "base_link"
    assert odo.covariances is None  # all-zero ROS covariance means unknown
    tf = read_trajectory_from_log(path, "/tf", parent_frame="odom", child_frame="base_link")
    common, i, j = np.intersect1d(odo.stamps, tf.stamps, return_indices=True)
    assert len(common) > 2000
    np.testing.assert_allclose(odo.poses[i], tf.poses[j], atol=1e-9)
    amcl = read_trajectory_from_log(path, "amcl_pose")
    assert len(amcl) == 135 and amcl.frame_id == "map" and amcl.covariances.shape == (135, 6, 6)


def test_trajectory_from_ros1_pose_topic(bags):
    path = bags / "ROS_example.bag"
    _, ref_stamps, ref_poses = _rosbags_poses(path, "ORB-SLAM")
    traj = read_trajectory_from_log(path, "ORB-SLAM")
    order = np.argsort(ref_stamps, kind="stable")
    assert len(traj) == len(np.unique(ref_stamps))
    assert traj.stamps[0] == min(ref_stamps) and traj.stamps[-1] == max(ref_stamps)
    np.testing.assert_allclose(traj.poses[0], ref_poses[order[0]], atol=1e-12)
    np.testing.assert_allclose(traj.poses[-1], ref_poses[order[-1]], atol=1e-12)


def test_ros1_encoded_mcap(tmp_path, bags):
    """An MCAP file with profile ros1 (ros1msg schemas, ros1-encoded messages), as `mcap convert`
    makes from ROS1 bags: built here with the mcap library from the raw bytes of ROS_example.bag."""
    from mcap.writer import Writer
    from rosbags.rosbag1 import Reader

    out = tmp_path / "ros1.mcap"
    with Reader(bags / "ROS_example.bag") as bag, open(out, "wb") as fh:
        conn = next(c for c in bag.connections if c.topic == "S-PTAM")
        w = Writer(fh)
        w.start(profile="ros1", library="test")
        sid = w.register_schema(name="geometry_msgs/PoseStamped", encoding="ros1msg", data=conn.msgdef.data.encode())
        cid = w.register_channel(topic="/s_ptam", message_encoding="ros1", schema_id=sid)
        raws = []
        for _c, t, raw in bag.messages(connections=[conn]):
            w.add_message(cid, log_time=t, data=bytes(raw), publish_time=t)
            raws.append(t)
        w.finish()
    ref = _rosbags_poses(bags / "ROS_example.bag", "S-PTAM")
    with open_log(out) as r:
        assert r.format == "mcap" and r.topics["/s_ptam"] == ("/s_ptam", "geometry_msgs/msg/PoseStamped", 5439)
        msgs = list(r.messages("/s_ptam"))
    assert [m.log_time for m in msgs] == ref[0] and [m.stamp for m in msgs] == ref[1]
    np.testing.assert_allclose([decode_pose(m.msg)[0] for m in msgs], ref[2], atol=1e-12)
