"""make-demo-log: real MCAP / rosbag2 / ROS1 files that read back with the right content,
byte-identical for the same seed; the plain-folder export; the CLI."""
from __future__ import annotations

import hashlib
from pathlib import Path

import cv2
import numpy as np
import pytest

from slam_lcd.cli.main import main
from slam_lcd.io import open_log
from slam_lcd.io.decode import decode_camera_info, decode_image, decode_pose
from slam_lcd.sim import T_body_camera, make_demo_log, read_loop_pairs
from slam_lcd.sim.demo_log import DEPTH_STEP, loops_path_for

SMALL = dict(frames=12, width=160, height=120)


def _digest(path: Path) -> str:
    h = hashlib.sha256()
    files = sorted(p for p in path.rglob("*") if p.is_file()) if path.is_dir() else [path]
    for f in files:
        h.update(str(f.relative_to(path) if path.is_dir() else f.name).encode())
        h.update(f.read_bytes())
    return h.hexdigest()


@pytest.mark.parametrize("fmt,name", [("mcap", "demo.mcap"), ("rosbag2", "demo_bag"), ("rosbag1", "demo.bag"),
                                      ("folder", "demo_dir")])
def test_same_seed_gives_identical_bytes(tmp_path, fmt, name):
    a = make_demo_log(tmp_path / "a" / name, fmt=fmt, seed=1, stereo=True, **SMALL)
    b = make_demo_log(tmp_path / "b" / name, fmt=fmt, seed=1, stereo=True, **SMALL)
    c = make_demo_log(tmp_path / "c" / name, fmt=fmt, seed=0, stereo=True, **SMALL)
    assert _digest(a.path) == _digest(b.path)
    assert a.loop_pairs_path.read_bytes() == b.loop_pairs_path.read_bytes()
    assert _digest(a.path) != _digest(c.path)


def test_render_workers_do_not_change_the_bytes(tmp_path):
    a = make_demo_log(tmp_path / "a.mcap", frames=30, width=96, height=72, workers=0)
    b = make_demo_log(tmp_path / "b.mcap", frames=30, width=96, height=72, workers=2)
    assert a.path.read_bytes() == b.path.read_bytes()


@pytest.mark.parametrize("fmt,name", [("mcap", "demo.mcap"), ("rosbag2", "demo_bag"), ("rosbag1", "demo.bag")])
def test_log_reads_back_with_topics_rates_and_content(tmp_path, fmt, name):
    info = make_demo_log(tmp_path / name, fmt=fmt, frames=25, width=160, height=120, stereo=True, seed=1)
    assert info.path.exists() and loops_path_for(info.path).exists()
    with open_log(info.path) as r:
        assert r.format == fmt
        topics = r.topics
        expect = {
            "/camera/image_raw": ("sensor_msgs/msg/Image", 25),
            "/camera/camera_info": ("sensor_msgs/msg/CameraInfo", 25),
            "/camera/depth": ("sensor_msgs/msg/Image", 25),
            "/camera/right/image_raw": ("sensor_msgs/msg/Image", 25),
            "/camera/right/camera_info": ("sensor_msgs/msg/CameraInfo", 25),
            "/odom": ("nav_msgs/msg/Odometry", 121),
            "/ground_truth/pose": ("geometry_msgs/msg/PoseStamped", 121),
            "/tf_static": ("tf2_msgs/msg/TFMessage", 1),
        }
        for t, (typ, n) in expect.items():
            assert topics[t].msgtype == typ and topics[t].count == n, (t, topics[t])
        stamps: dict[str, list[int]] = {}
        gt, odo, images, depths, tf = {}, {}, [], [], None
        last = -1
        for m in r.messages():
            assert m.log_time >= last  # time ordered
            last = m.log_time
            stamps.setdefault(m.topic, []).append(m.stamp)
            if m.topic == "/ground_truth/pose":
                gt[m.stamp] = decode_pose(m.msg)[0]
            elif m.topic == "/odom":
                odo[m.stamp] = decode_pose(m.msg)
                assert m.msg.header.frame_id == "odom" and m.msg.child_frame_id == "base_link"
            elif m.topic == "/camera/image_raw":
                images.append(decode_image(m.msg))
            elif m.topic == "/camera/depth":
                depths.append(decode_image(m.msg))
            elif m.topic == "/camera/camera_info" and len(stamps[m.topic]) == 1:
                cam = decode_camera_info(m.msg)
            elif m.topic == "/camera/right/camera_info" and len(stamps[m.topic]) == 1:
                P = m.msg.P if fmt == "rosbag1" else m.msg.p  # ROS1 field names are upper case
                assert P[3] == pytest.approx(-cam.fx * 0.12)
            elif m.topic == "/tf_static":
                tf = {t.child_frame_id: t for t in m.msg.transforms}
    # rates: camera 10 Hz, odometry / ground truth 50 Hz
    for t, hz in [("/camera/image_raw", 10.0), ("/camera/depth", 10.0), ("/odom", 50.0), ("/ground_truth/pose", 50.0)]:
        period = np.diff(stamps[t]) * 1e-9
        assert np.allclose(period, 1.0 / hz), t
    assert cam.width == 160 and cam.height == 120 and cam.fx == pytest.approx(info.camera.fx)
    assert images[0].shape == (120, 160) and images[0].dtype == np.uint8
    assert depths[0].dtype == np.float32 and (depths[0] > 0.3).all()
    assert np.allclose(np.round(depths[5] / DEPTH_STEP) * DEPTH_STEP, depths[5])  # quantised to 1/1024 m
    # tf_static: camera mounting and the right camera
    tr = tf["camera_optical_frame"].transform.translation
    assert (tr.x, tr.y, tr.z) == pytest.approx(tuple(T_body_camera()[:3, 3]))
    assert "camera_right_optical_frame" in tf and "odom" in tf
    # odometry drifts away from ground truth but starts on it; covariance grows
    first, final = min(odo), max(odo)
    assert np.allclose(odo[first][0], gt[first], atol=1e-9)
    assert 0.0 < np.linalg.norm(odo[final][0][:3, 3] - gt[final][:3, 3]) < 1.0
    assert odo[final][1][3, 3] > odo[first][1][3, 3]


def test_info_reports(tmp_path):
    info = make_demo_log(tmp_path / "d.mcap", frames=15, width=96, height=72, compressed=True, depth=False)
    assert "/camera/image_raw/compressed" in info.topics and "/camera/depth" not in info.topics
    assert info.topics["/camera/image_raw/compressed"]["rate_hz"] == pytest.approx(10.0)
    assert info.topics["/odom"]["rate_hz"] == pytest.approx(50.0)
    assert info.frames == 15 and info.duration_s == pytest.approx(1.4)
    text = info.summary()
    assert "drift" in text and "/odom" in text


def test_folder_export(tmp_path):
    info = make_demo_log(tmp_path / "seq", fmt="folder", frames=8, width=160, height=120, color=True)
    root = info.path
    names = (root / "image.txt").read_text().split("\n")
    rows = [ln.split() for ln in names if ln and not ln.startswith("#")]
    assert len(rows) == 8
    img = cv2.imread(str(root / rows[3][1]), cv2.IMREAD_UNCHANGED)
    assert img.shape == (120, 160, 3)
    dep = cv2.imread(str(root / "depth" / Path(rows[3][1]).name), cv2.IMREAD_UNCHANGED)
    assert dep.dtype == np.uint16 and dep.min() > 300  # millimetres
    from slam_lcd.io.trajectory_files import read_tum

    gt = read_tum(root / "groundtruth.txt")
    od = read_tum(root / "odometry.txt")
    assert len(gt) == len(od) == 36 and float(rows[0][0]) == pytest.approx(gt.times_s[0])
    import yaml

    meta = yaml.safe_load((root / "camera.yaml").read_text())
    assert meta["width"] == 160 and meta["depth_scale"] == 1000.0
    assert np.allclose(meta["T_body_camera"], T_body_camera())
    assert read_loop_pairs(root / "loop_pairs.csv").shape[1] == 2


def test_cli_make_demo_log_and_info(tmp_path, capsys):
    out = tmp_path / "cli.mcap"
    assert main(["make-demo-log", str(out), "--frames", "10", "--size", "128x96", "--seed", "1"]) == 0
    text = capsys.readouterr().out
    assert "10 frames" in text and "drift" in text
    assert out.exists() and (tmp_path / "cli_loops.csv").exists()
    assert main(["info", str(out)]) == 0
    text = capsys.readouterr().out
    for t in ("/camera/image_raw", "/camera/camera_info", "/camera/depth", "/odom", "/ground_truth/pose"):
        assert t in text
    # bad input: one-line error, exit status 2
    assert main(["make-demo-log", str(tmp_path / "x.mcap"), "--size", "big"]) == 2
    assert main(["make-demo-log", str(tmp_path / "x.mcap"), "--frames", "1"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 2 and "error" in err
