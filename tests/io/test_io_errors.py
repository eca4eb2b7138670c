"""Bad input: truncated MCAP, text file named .bag, missing path, missing topic, bad messages.
The CLI must answer with one line and exit status 2 (never a traceback), or recover with one warning."""
from __future__ import annotations

import logging
import shutil

import numpy as np
import pytest

from slam_lcd.cli.main import main
from slam_lcd.errors import (
    FileMissingError,
    InvalidPoseError,
    MessageEncodingError,
    TopicNotFoundError,
    TruncatedLogError,
    UnsupportedFormatError,
)
from slam_lcd.io import message_builders as M
from slam_lcd.io import open_log, read_trajectory_from_log
from slam_lcd.io.config import IOConfig
from slam_lcd.io.decode import decode_camera_info, decode_image, decode_pose
from slam_lcd.io.writers import open_writer
from slam_lcd.types import CameraModel


@pytest.fixture()
def truncated(tmp_path, shared_data):
    src = shared_data / "bags" / "nav2_turtlebot.mcap"
    data = src.read_bytes()
    out = tmp_path / "half.mcap"
    out.write_bytes(data[: len(data) // 2])
    return out


def _one_line_error(capsys, argv):
    rc = main(argv)
    cap = capsys.readouterr()
    err_lines = [ln for ln in cap.err.splitlines() if ln.strip()]
    return rc, cap.out, err_lines


def test_truncated_mcap_recovers_with_one_warning(truncated, shared_data, capsys, caplog):
    from mcap.exceptions import EndOfFile, McapError
    from mcap.reader import make_reader
    from mcap.stream_reader import StreamReader

    # the plain mcap library gives up on the cut chunk: it reads no message at all
    n_plain = 0
    with open(truncated, "rb") as fh, pytest.raises(EndOfFile):
        for rec in StreamReader(fh).records:
            n_plain += type(rec).__name__ == "Message"
    assert n_plain == 0
    with open(truncated, "rb") as fh, pytest.raises(McapError):
        make_reader(fh).get_summary()
    # slam-lcd recovers the messages in the readable half of the chunk
    with caplog.at_level(logging.WARNING, logger="slam_lcd"):
        with open_log(truncated) as r:
            assert r.truncated
            got = list(r.messages("/odom"))
            n = r.recovered
            counts = {k: v.count for k, v in r.topics.items()}
    warnings = [rec for rec in caplog.records if rec.levelno >= logging.WARNING]
    assert len(warnings) == 1
    assert "truncated" in warnings[0].getMessage() and f"recovered {n} " in warnings[0].getMessage()
    assert 1000 < n < 8197 and sum(counts.values()) == n
    # the recovered messages are exactly the first ones of the intact file
    with open_log(shared_data / "bags" / "nav2_turtlebot.mcap") as full:
        ref = list(full.messages("/odom"))[: len(got)]
    assert [m.log_time for m in got] == [m.log_time for m in ref]
    np.testing.assert_array_equal([decode_pose(m.msg)[0] for m in got], [decode_pose(m.msg)[0] for m in ref])
    # the CLI in-process: exit 0 and the same single warning
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="slam_lcd"):
        rc, out, _ = _one_line_error(capsys, ["info", str(truncated)])
    assert rc == 0
    assert [r.getMessage() for r in caplog.records] == [warnings[0].getMessage()]
    assert "TRUNCATED" in out and "/odom" in out


def test_truncated_mcap_cli_stderr_is_one_warning_line(truncated):
    """As a user runs it: stderr holds exactly one line, the warning with the count."""
    import subprocess
    import sys

    p = subprocess.run([sys.executable, "-m", "slam_lcd", "info", str(truncated)], capture_output=True, text=True,
                       timeout=120)
    assert p.returncode == 0, p.stderr
    err = [ln for ln in p.stderr.splitlines() if ln.strip()]
    assert len(err) == 1, p.stderr
    assert err[0].startswith("WARNING: ") and "truncated" in err[0] and "recovered 5441 readable messages" in err[0]


def test_truncated_mcap_can_be_refused(truncated):
    with pytest.raises(TruncatedLogError, match="truncated"):
        open_log(truncated, conf=IOConfig(on_truncated="error"))


def test_text_file_named_bag(tmp_path, capsys):
    p = tmp_path / "notes.bag"
    p.write_text("this is not a bag\n")
    with pytest.raises(UnsupportedFormatError):
        open_log(p)
    rc, out, err = _one_line_error(capsys, ["info", str(p)])
    assert rc == 2 and len(err) == 1 and "notes.bag" in err[0] and "not a ROS1 bag" in err[0]
    assert "Traceback" not in out + "".join(err)


def test_missing_path(tmp_path, capsys):
    with pytest.raises(FileMissingError):
        open_log(tmp_path / "nope.mcap")
    rc, _, err = _one_line_error(capsys, ["info", str(tmp_path / "nope.mcap")])
    assert rc == 2 and len(err) == 1 and "no such file" in err[0]


def test_truncated_ros1_bag_is_one_line_error(tmp_path, shared_data, capsys):
    data = (shared_data / "bags" / "tf_example.bag").read_bytes()
    p = tmp_path / "cut.bag"
    p.write_bytes(data[: len(data) // 2])
    rc, _, err = _one_line_error(capsys, ["info", str(p)])
    assert rc == 2 and len(err) == 1 and "cut.bag" in err[0]


def test_missing_topic_lists_available(shared_data, capsys):
    path = shared_data / "bags" / "nav2_turtlebot.mcap"
    with open_log(path) as r, pytest.raises(TopicNotFoundError) as ei:
        list(r.messages("/camera/image_raw"))
    assert ei.value.available == ["/amcl_pose", "/odom", "/tf", "/tf_static"]
    assert "/amcl_pose, /odom, /tf, /tf_static" in str(ei.value) and "\n" not in str(ei.value)


def test_rosbag2_folder_without_metadata(tmp_path, shared_data):
    d = tmp_path / "bag"
    d.mkdir()
    shutil.copy(shared_data / "bags" / "tf_example" / "tf_example.db3", d)
    with pytest.raises(UnsupportedFormatError, match="metadata.yaml"):
        open_log(d)
    # the storage file itself can be opened directly
    with open_log(d / "tf_example.db3") as r:
        assert r.topics["/tf"].count == 517


def test_bad_image_encoding_and_size():
    msg = M.image_msg(np.zeros((4, 6), np.uint8), 1, "cam")
    msg.encoding = "yuv422"
    with pytest.raises(MessageEncodingError, match="yuv422"):
        decode_image(msg)
    msg = M.image_msg(np.zeros((4, 6), np.uint8), 1, "cam")
    msg.height = 10
    with pytest.raises(MessageEncodingError, match="needs"):
        decode_image(msg)
    with pytest.raises(MessageEncodingError):
        M.image_msg(np.zeros((4, 6), np.float64), 1, "cam")


def test_uncalibrated_camera_info():
    msg = M.camera_info_msg(CameraModel(64, 48, 50, 50, 32, 24), 1, "cam")
    msg.k = np.zeros(9)
    with pytest.raises(MessageEncodingError, match="uncalibrated"):
        decode_camera_info(msg)


def test_nan_poses_are_refused(tmp_path):
    T = np.eye(4)
    T[0, 3] = np.nan
    with pytest.raises(InvalidPoseError):
        M.pose_stamped_msg(T, 1, "map")
    msg = M.pose_stamped_msg(np.eye(4), 1, "map")
    msg.pose.position.y = float("nan")
    with pytest.raises(InvalidPoseError, match="NaN"):
        decode_pose(msg)
    msg = M.pose_stamped_msg(np.eye(4), 1, "map")
    msg.pose.orientation.w = 0.0
    with pytest.raises(InvalidPoseError, match="not a rotation"):
        decode_pose(msg)
    # a NaN pose inside a log: the trajectory reader names the topic and the stamp
    out = tmp_path / "nan.mcap"
    with open_writer(out) as w:
        for i in range(3):
            m = M.pose_stamped_msg(np.eye(4), 10 + i, "map")
            if i == 2:
                m.pose.orientation.x = float("nan")
            w.write("/pose", m, 10 + i)
    with pytest.raises(InvalidPoseError, match=r"'/pose' message 2 \(stamp 12 ns\)"):
        read_trajectory_from_log(out, "/pose")
