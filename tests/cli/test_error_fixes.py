"""An error whose fix is known names it: the flag, the preset or the command that supplies what is missing.

Each case runs the command line and compares the whole line (exit status 2), so a message that
loses its fix fails here.
"""
from __future__ import annotations

import shutil

import pytest

from support.bad_input_files import message_lines, run_cli

EUROC_TOPICS = "/cam0/image_raw, /cam1/image_raw, /leica/position"
DEMO_TOPICS = "/camera/camera_info, /camera/depth, /camera/image_raw, /ground_truth/pose, /odom, /tf_static"
ORB = ["--set", "features.kind=orb", "--set", "features.feature_cache=false", "--no-progress"]
CALIB_FIX = ("the log has no CameraInfo for /cam0/image_raw: give the camera calibration with --calib FILE "
             "(a Kalibr camchain.yaml, or EuRoC's cam0/sensor.yaml then cam1/sensor.yaml)")


@pytest.fixture(scope="module")
def euroc_log(tmp_path_factory):
    """A 30-frame EuRoC-layout bag (no CameraInfo) with its Kalibr camchain beside it."""
    from slam_lcd.cli.main import main

    path = tmp_path_factory.mktemp("euroc") / "e.bag"
    assert main(["make-demo-log", str(path), "--layout", "euroc", "--frames", "30", "--size", "320x240"]) == 0
    assert (path.parent / "camchain-e.yaml").is_file()
    return path


@pytest.fixture(scope="module")
def demo(tmp_path_factory):
    from slam_lcd.sim import make_demo_log

    path = tmp_path_factory.mktemp("demo") / "d.mcap"
    make_demo_log(path, "mcap", frames=10, seed=3, width=160, height=120)
    return path


def line_of(argv, capfd) -> str:
    """The error line of a command that fails with exit status 2 (warnings before it are the run's own)."""
    rc, _, err = run_cli(argv, capfd)
    assert rc == 2, err
    assert "Traceback" not in err, err
    lines = message_lines(err)
    assert [ln for ln in lines if " error: " in ln] == lines[-1:], lines
    return lines[-1]


def test_euroc_without_calib_names_the_flag_and_the_camchain_beside_the_log(euroc_log, tmp_path, capfd):
    line = line_of(["run", euroc_log, "-o", tmp_path / "o", "--config", "euroc"], capfd)
    assert line == (f"slam-lcd run: error: {euroc_log}: topic '/cam0/camera_info' not found; available topics: "
                    f"{EUROC_TOPICS}; {CALIB_FIX}; beside the log: --calib {euroc_log.parent / 'camchain-e.yaml'}")
    assert not (tmp_path / "o").exists()


def test_euroc_without_calib_and_no_calibration_beside_names_the_flag(euroc_log, tmp_path, capfd):
    alone = tmp_path / "e.bag"
    shutil.copy(euroc_log, alone)
    line = line_of(["run", alone, "-o", tmp_path / "o", "--config", "euroc"], capfd)
    assert line == (f"slam-lcd run: error: {alone}: topic '/cam0/camera_info' not found; available topics: "
                    f"{EUROC_TOPICS}; {CALIB_FIX}")


def test_the_named_camchain_is_the_fix(euroc_log, tmp_path, capfd):
    """The line's fix works: with --calib from the line the run gets past the calibration."""
    rc, _, err = run_cli(["run", euroc_log, "-o", tmp_path / "o", "--config", "euroc", *ORB,
                          "--calib", euroc_log.parent / "camchain-e.yaml"], capfd)
    assert rc == 0, err
    assert "camera_info" not in err


@pytest.mark.parametrize("flag", ["--image-topic", "--odom-topic", "--depth-topic", "--gt-topic"])
def test_a_topic_flag_naming_no_topic_of_the_log_is_named(flag, demo, tmp_path, capfd):
    line = line_of(["run", demo, "-o", tmp_path / "o", *ORB, flag, "/nope"], capfd)
    assert line == (f"slam-lcd run: error: {demo}: topic '/nope' ({flag}) not found; available topics: "
                    f"{DEMO_TOPICS}")


def test_right_topic_naming_no_topic_of_the_log_is_named(euroc_log, tmp_path, capfd):
    line = line_of(["run", euroc_log, "-o", tmp_path / "o", *ORB, "--config", "euroc", "--calib",
                    euroc_log.parent / "camchain-e.yaml", "--right-topic", "/nope"], capfd)
    assert line == (f"slam-lcd run: error: {euroc_log}: topic '/nope' (--right-topic) not found; available topics: "
                    f"{EUROC_TOPICS}")


def test_eval_lcd_camera_info_topic_not_found_says_it_may_be_left_out(demo, tmp_path, capfd):
    import numpy as np

    gt = tmp_path / "gt.npy"
    np.save(gt, np.zeros((10, 10), bool))
    line = line_of(["eval-lcd", demo, "--image-topic", "/camera/image_raw", "--camera-info-topic", "/nope",
                    "--gt", gt, "-o", tmp_path / "o"], capfd)
    assert line == (f"slam-lcd eval-lcd: error: {demo}: topic '/nope' (--camera-info-topic) not found; available "
                    f"topics: {DEMO_TOPICS}; leave --camera-info-topic out to take the intrinsics from --focal-factor")


def test_files_not_found_name_their_fix(demo, tmp_path, capfd, monkeypatch):
    from slam_lcd.config import preset_names

    nope = tmp_path / "nope"
    cases = [
        (["run", demo, "-o", tmp_path / "o", "--config", f"{nope}.yaml"],
         f"slam-lcd run: error: {nope}.yaml: configuration file not found (--config): give a YAML file or a preset "
         f"name ({', '.join(preset_names())})"),
        (["vocab", "info", f"{nope}.npz"],
         f"slam-lcd vocab: error: {nope}.npz: vocabulary file not found: train one with `slam-lcd vocab train`, or "
         "leave --vocab out for the online vocabulary"),
        (["batch", demo, "-o", tmp_path / "b", "--vocab", f"{nope}.npz"],
         f"slam-lcd batch: error: {nope}.npz: vocabulary file not found (--vocab): train one with `slam-lcd vocab "
         "train`, or leave --vocab out for the online vocabulary"),
        (["run", demo, "-o", tmp_path / "o", "--weights", f"{nope}.pt"],
         f"slam-lcd run: error: {nope}.pt: SuperPoint weights file not found (given with --weights / "
         "features.weights): leave them out for the cached or downloaded weights, or use the ORB baseline: "
         "--features orb"),
        (["ate", f"{nope}.txt", f"{demo}:/odom"],
         f"slam-lcd ate: error: {nope}.txt: trajectory file not found (give a trajectory file or LOG:TOPIC)"),
        (["eval-lcd", demo, "--image-topic", "/camera/image_raw", "--gt", f"{nope}.npy", "-o", tmp_path / "e"],
         f"slam-lcd eval-lcd: error: {nope}.npy: ground-truth file not found (--gt)"),
    ]
    for argv, want in cases:
        assert line_of(argv, capfd) == want, argv
    monkeypatch.setenv("SLAM_LCD_SUPERPOINT_WEIGHTS", f"{nope}.pt")
    assert line_of(["run", demo, "-o", tmp_path / "o"], capfd) == (
        f"slam-lcd run: error: {nope}.pt: SuperPoint weights file named by $SLAM_LCD_SUPERPOINT_WEIGHTS not found: "
        "unset it for the cached or downloaded weights, or use the ORB baseline: --features orb")
