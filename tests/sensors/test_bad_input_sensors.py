"""Parsers at the edge and sensor data that contradicts itself (docs/robustness.md).

Ground truth with repeated stamps (a ``--gt`` file, a ``--gt-topic``, the real TUM fr2/desk
file), a config whose key is a number, ``make-demo-log`` numbers, a foreign file in the
feature cache, calibration / CameraInfo / depth sizes that differ from the images, and
rotation figures against position-only ground truth. Each case runs the command line on a
short demo log or a file built in a temporary folder, and checks the exit status, the one
line (or the one warning) and what it names.
"""
from __future__ import annotations

import json

import numpy as np
import pytest

from support.bad_input_files import assert_one_line, message_lines, rewrite_log, run_cli, tum_lines

ORB = ["--set", "features.kind=orb", "--set", "features.feature_cache=false", "--no-progress",
       "--set", "run.plots=false", "--set", "run.loop_pictures=false", "--no-mcap"]
GT_TOPIC = "/ground_truth/pose"


@pytest.fixture(scope="module")
def demo(tmp_path_factory):
    """A 30-frame RGB-D demo log (3 s, 160x120): odometry, depth, camera info, ground truth."""
    from slam_lcd.sim import make_demo_log

    path = tmp_path_factory.mktemp("sensors_demo") / "demo.mcap"
    make_demo_log(path, "mcap", frames=30, seed=3, width=160, height=120)
    return path


def _warnings(err: str) -> list[str]:
    return [w for w in message_lines(err) if w.startswith("WARNING")]


# ---------------------------------------------------------------------------- ground truth, repeated stamps


def test_gt_file_with_a_repeated_stamp_is_accepted_with_one_warning(demo, tmp_path, capfd):
    """``--gt`` whose stamps repeat (as fr2/desk and EuRoC V102 do): one warning naming the file, the ATE as usual."""
    rc, _, err = run_cli(["export", f"{demo}:{GT_TOPIC}", tmp_path / "gt.tum", "--to", "tum"], capfd)
    assert rc == 0, err
    lines = tum_lines(tmp_path / "gt.tum")
    lines.insert(11, lines[10])
    gt = tmp_path / "gt_repeated.tum"
    gt.write_text("\n".join(lines) + "\n")
    rc, out, err = run_cli(["run", demo, "--out", tmp_path / "out", "--gt", gt, *ORB], capfd)
    assert rc == 0, err
    warnings = _warnings(err)
    assert len(warnings) == 1 and "gt_repeated.tum" in warnings[0] and "repeated" in warnings[0], warnings
    report = json.loads((tmp_path / "out" / "report.json").read_text())
    assert report["eval"]["ate"]["after"]["translation_m"]["rmse"] < 0.05


def test_gt_topic_with_a_repeated_stamp_is_accepted_with_one_warning(demo, tmp_path, capfd):
    """``--gt-topic`` whose messages repeat a stamp: one warning naming the log and the topic."""
    last = {}

    def edit(topic, i, msg):
        if topic == GT_TOPIC:
            if i == 10:
                msg.header.stamp = last["stamp"]
            last["stamp"] = msg.header.stamp
        return msg

    log = rewrite_log(demo, tmp_path / "gt_repeated.mcap", edit)
    rc, _, err = run_cli(["run", log, "--out", tmp_path / "out", *ORB], capfd)
    assert rc == 0, err
    warnings = _warnings(err)
    assert len(warnings) == 1 and "gt_repeated.mcap" in warnings[0] and GT_TOPIC in warnings[0], warnings
    assert "repeated" in warnings[0]


def test_interpolation_on_real_ground_truth_with_a_repeated_stamp(shared_data):
    """The real TUM fr2/desk ground truth (a repeated stamp) interpolates; a repeated stamp counts with its first
    pose."""
    from slam_lcd.geometry import interpolate_poses
    from slam_lcd.io.trajectory_files import read_trajectory

    gt = read_trajectory(shared_data / "trajectories" / "fr2_desk_groundtruth.txt")
    rep = np.flatnonzero(np.diff(gt.stamps) == 0)
    assert rep.size
    query = np.concatenate([gt.stamps[rep], gt.stamps[::300]])
    P = interpolate_poses(gt.stamps, gt.poses, query)
    assert np.allclose(P[: rep.size], gt.poses[rep], atol=1e-9)


# ---------------------------------------------------------------------------- config keys that are not names


@pytest.mark.parametrize("text,needle", [("1: 2\n", "key 1 in section top"),
                                         ("lcd:\n  5: 3\n", "key 5 in section lcd"),
                                         ("true: 1\n", "key True in section top")])
def test_config_key_that_is_not_a_name_is_one_line(demo, tmp_path, capfd, text, needle):
    """A config file whose key YAML reads as a number or a boolean: one line naming the file and the key."""
    cfg = tmp_path / "bad.yaml"
    cfg.write_text(text)
    rc, _, err = run_cli(["run", demo, "--out", tmp_path / "out", "--config", cfg, "--no-progress"], capfd)
    assert rc == 2, err
    assert_one_line(err, "bad.yaml", needle, "not a name")
    assert not (tmp_path / "out").exists()


# ---------------------------------------------------------------------------- make-demo-log numbers


@pytest.mark.parametrize("flag,value", [("--rate", "nan"), ("--rate", "inf"), ("--laps", "0"), ("--laps", "nan"),
                                        ("--seed", "-1")])
def test_make_demo_log_bad_number_is_one_line(tmp_path, capfd, flag, value):
    """A rate, lap count or seed that means nothing: one line naming the flag, before anything is written."""
    out = tmp_path / "demo.mcap"
    rc, _, err = run_cli(["make-demo-log", out, "--frames", "20", "--size", "160x120", flag, value], capfd)
    assert rc == 2, err
    assert_one_line(err, flag, value)
    assert sorted(p.name for p in tmp_path.iterdir()) == []


# ---------------------------------------------------------------------------- feature cache entries


def test_foreign_or_broken_feature_cache_entries_are_recomputed_with_one_warning(demo, tmp_path, capfd):
    """A foreign ``.npz`` (other shapes) and a text file in the feature cache: skipped, recomputed, one warning;
    the result is the one of a run on a clean cache."""
    cached = ["--set", "features.kind=orb", "--set", f"features.cache_dir={tmp_path / 'cache'}", "--no-progress",
              "--set", "run.plots=false", "--set", "run.loop_pictures=false", "--no-mcap"]
    rc, _, err = run_cli(["run", demo, "--out", tmp_path / "first", *cached], capfd)
    assert rc == 0, err
    entries = sorted((tmp_path / "cache").rglob("*.npz"))
    assert len(entries) >= 2
    np.savez(entries[0], keypoints=np.zeros((5, 3), np.float32), scores=np.zeros(5, np.float32),
             descriptors=np.zeros((5, 7), np.uint8), image_size=np.array([160, 120]), kind=np.array("orb"))
    entries[1].write_text("not features\n")
    rc, _, err = run_cli(["run", demo, "--out", tmp_path / "second", *cached], capfd)
    assert rc == 0, err
    warnings = _warnings(err)
    assert len(warnings) == 1 and "feature cache entry skipped" in warnings[0], warnings
    assert entries[0].name in warnings[0] or entries[1].name in warnings[0]
    assert (tmp_path / "first" / "corrected.tum").read_text() == (tmp_path / "second" / "corrected.tum").read_text()
    with np.load(entries[0], allow_pickle=False) as z:  # overwritten with this extractor's features
        assert z["keypoints"].shape[1] == 2 and z["descriptors"].shape[1] == 32


# ---------------------------------------------------------------------------- sizes that contradict the images


@pytest.fixture(scope="module")
def euroc(tmp_path_factory):
    """A 40-frame EuRoC-layout log (160x120 stereo, no odometry, Leica PointStamped) and its Kalibr camchain."""
    from slam_lcd.sim import make_demo_log

    folder = tmp_path_factory.mktemp("sensors_euroc")
    make_demo_log(folder / "eu.mcap", "mcap", frames=40, seed=0, width=160, height=120, layout="euroc")
    return folder / "eu.mcap", folder / "camchain-eu.yaml"


@pytest.mark.parametrize("size", ["[320, 240]", "[80, 60]"])
def test_calibration_of_another_image_size_is_one_line(euroc, tmp_path, capfd, size):
    """``--calib`` whose resolution is not the images': one line naming the calibration file, camera, topic, sizes."""
    log, camchain = euroc
    calib = tmp_path / "camchain.yaml"
    calib.write_text(camchain.read_text().replace("resolution: [160, 120]", f"resolution: {size}"))
    rc, _, err = run_cli(["run", log, "--out", tmp_path / "out", "--calib", calib, "--image-topic", "/cam0/image_raw",
                          *ORB], capfd)
    assert rc == 2, err
    wh = size.strip("[]").replace(", ", "x")
    assert_one_line(err, "camchain.yaml", "cam0", "/cam0/image_raw", wh, "160x120")
    assert not (tmp_path / "out").exists()


def _half_depth(msg):
    """The same depth image at half the width and height (every second pixel)."""
    import dataclasses

    d = np.frombuffer(bytes(msg.data), np.uint16 if msg.encoding in ("16UC1", "mono16") else np.float32)
    d = d.reshape(msg.height, msg.width)[::2, ::2]
    return dataclasses.replace(msg, height=d.shape[0], width=d.shape[1], step=d.shape[1] * d.itemsize,
                               data=np.frombuffer(np.ascontiguousarray(d).tobytes(), np.uint8))


def _big_camera_info(msg):
    import dataclasses

    return dataclasses.replace(msg, width=msg.width * 2, height=msg.height * 2)


@pytest.mark.parametrize("what,edit,needles", [
    ("camera_info", _big_camera_info, ["/camera/camera_info", "320x240", "160x120"]),
    ("depth", _half_depth, ["/camera/depth", "80x60", "160x120"]),
])
def test_camera_info_or_depth_of_another_size_is_one_line(demo, tmp_path, capfd, what, edit, needles):
    """A CameraInfo for other-sized images, a depth image half the camera's size: one line naming topic and sizes."""
    topic = "/camera/camera_info" if what == "camera_info" else "/camera/depth"
    log = rewrite_log(demo, tmp_path / f"{what}.mcap", lambda t, i, msg: edit(msg) if t == topic else msg)
    rc, _, err = run_cli(["run", log, "--out", tmp_path / "out", *ORB], capfd)
    assert rc == 2, err
    assert_one_line(err, f"{what}.mcap", *needles)
    assert not (tmp_path / "out").exists()


# ---------------------------------------------------------------------------- position-only ground truth


def test_position_only_ground_truth_reports_no_rotation_error_and_no_rpe(euroc, tmp_path, capfd):
    """PointStamped ground truth (EuRoC's Leica): report.json has no rotation figures (null, with the reason) and
    no RPE; report.md and report.html print no rotation row and say "position only"."""
    from slam_lcd.outputs.report_schema import check_report

    log, camchain = euroc
    out = tmp_path / "out"
    rc, _, err = run_cli(["run", log, "--out", out, "--calib", camchain, "--image-topic", "/cam0/image_raw",
                          "--gt-topic", "/leica/position", *ORB], capfd)
    assert rc == 0, err
    report = json.loads((out / "report.json").read_text())
    assert check_report(report) == []
    ev = report["eval"]
    assert ev["gt_position_only"] and ev["rpe"] is None and "no orientation" in ev["not_measured"]
    for side in ("before", "after"):
        assert ev["ate"][side]["rotation_deg"] is None and ev["ate"][side]["translation_m"]["rmse"] > 0
    md, html = (out / "report.md").read_text(), (out / "report.html").read_text()
    for text in (md, html):
        assert "rotation RMSE" not in text and text.count("translation RMSE") == 1  # the ATE's row, no RPE row
        assert "Position only" in text


# ---------------------------------------------------------------------------- weights that are no checkpoint


def test_text_file_as_weights_is_said_to_be_no_checkpoint(demo, tmp_path, capfd):
    """A text file given as --weights: one line saying it is not a checkpoint (not "pickled Python objects")."""
    weights = tmp_path / "weights.txt"
    weights.write_text("conv1a.weight 0.1 0.2 0.3\nthese are notes, not weights\n")
    rc, _, err = run_cli(["run", demo, "--out", tmp_path / "out", "--weights", weights, "--no-progress"], capfd)
    assert rc == 2, err
    line = assert_one_line(err, "weights.txt", "not a PyTorch checkpoint", "text file")
    assert "pickled" not in line
    assert not (tmp_path / "out").exists()
