"""A run through tracking loss: the built-in VO breaks, the run finishes with its segments said everywhere.

The TUM RGB-D layout at 320x240 (no odometry topic: the RGB-D VO is the source) with the lights off
for two seconds: the VO cannot track there, so the odometry breaks and the keyframes after it
start a new segment. Before segments were a design this ended in GTSAM's
IndeterminateSystemException and no output.
"""
from __future__ import annotations

import json

from slam_lcd.outputs.report_schema import check_report

from support.bad_input_files import assert_one_line, run_cli

TUM = ["--config", "tum-rgbd", "--features", "orb", "--set", "features.feature_cache=false", "--no-progress"]


def _log(tmp_path, capfd, *stretch) -> str:
    log = tmp_path / "s1.bag"
    status, _, err = run_cli(["make-demo-log", str(log), "--session", "1", "--layout", "tum", "--size", "320x240",
                              "--rate", "10", "--frames", "120", *stretch], capfd)
    assert status == 0, err
    return str(log)


def test_a_break_in_the_odometry_gives_segments_in_every_output(tmp_path, capfd):
    log = _log(tmp_path, capfd, "--dark", "5:2")
    out = tmp_path / "out"
    status, stdout, err = run_cli(["run", log, "-o", str(out), *TUM], capfd)
    assert status == 0, err
    assert "Traceback" not in err
    assert "lost tracking" in err
    rep = json.loads((out / "report.json").read_text())
    assert check_report(rep) == []
    seg = rep["segments"]
    assert seg["count"] >= 2 and len(seg["segments"]) == seg["count"]
    assert sum(r["keyframes"] for r in seg["segments"]) == rep["keyframes"]
    assert (out / "segments.csv").read_text().splitlines()[0].startswith("segment,component,keyframes")
    notes = [ln for ln in (out / "corrected.tum").read_text().splitlines()[1:] if ln.startswith("#")]
    assert len(notes) == seg["count"] - 1 and notes[0].startswith("# segment 1 (component ")
    assert "segments: " in stdout and "tracking lost" in stdout
    if len(seg["components"]) > 1:  # a segment no loop joined: ATE per component, said in the alignment
        assert seg["ate"] == "per component, each aligned on its own" and "per component" in stdout
        assert all("ate_after_m" in c for c in seg["components"])


def test_a_log_with_no_usable_image_is_one_line_and_exit_2(tmp_path, capfd):
    log = _log(tmp_path, capfd, "--dark", "0:1000")
    status, _, err = run_cli(["run", log, "-o", str(tmp_path / "out"), *TUM], capfd)
    assert status == 2
    errors = "\n".join(ln for ln in err.splitlines() if not ln.startswith("WARNING: "))  # the VO's note stays
    assert_one_line(errors, "s1.bag", "tracked none of the 120 frames", "unusable")
    assert not (tmp_path / "out").exists()
