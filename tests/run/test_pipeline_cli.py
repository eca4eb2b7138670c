"""`slam-lcd run` input handling on real logs (no images / missing topics)."""
from slam_lcd.cli.main import main


def test_run_on_odometry_only_log_names_missing_image_topic(shared_data, tmp_path, capsys):
    log = shared_data / "bags" / "nav2_turtlebot.mcap"
    rc = main(["run", str(log), "--out", str(tmp_path / "out"), "--no-progress"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2
    assert len(err) == 1, err
    assert "nav2_turtlebot.mcap" in err[0] and "image topic" in err[0]


def test_run_with_unknown_image_topic_lists_available(shared_data, tmp_path, capsys):
    log = shared_data / "bags" / "nav2_turtlebot.mcap"
    rc = main(["run", str(log), "--out", str(tmp_path / "out"), "--image-topic", "/camera/image_raw"])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and "/camera/image_raw" in err and "/odom" in err and "\n" not in err


def test_run_missing_log(tmp_path, capsys):
    rc = main(["run", str(tmp_path / "nope.mcap"), "--out", str(tmp_path / "out")])
    assert rc == 2 and "nope.mcap" in capsys.readouterr().err
