"""A first run with no SuperPoint weights anywhere and no network.

`slam-lcd demo` still runs the whole job with the ORB baseline, says so at the start and in
its summary, and still corrects the trajectory (ATE after <= 25% of odometry, no false loop);
`slam-lcd run` with the default features keeps failing with the weights message (exit 2):
a user's real run never changes features silently. `slam-lcd weights` shows the search.
"""
from __future__ import annotations

import json
import subprocess
import sys

NOTICE = "SuperPoint weights not available offline"


def test_demo_falls_back_to_orb_and_still_corrects(offline_demo):
    proc, out, log, env = offline_demo
    assert proc.returncode == 0, proc.stderr[-2000:]
    lines = proc.stdout.splitlines()
    assert lines[0].startswith(NOTICE) and "ORB features" in lines[0], lines[:3]
    assert "superpoint_v1.pth at " + env["SLAM_LCD_CACHE_DIR"] in lines[0] and "--weights" in lines[0]
    summary = proc.stdout[proc.stdout.index("slam-lcd demo summary"):]
    assert "features: orb" in summary and NOTICE in summary
    rep = json.loads((out / "report.json").read_text())
    assert rep["eval"]["ate"]["ratio_after_before"] <= 0.25, rep["eval"]["ate"]
    assert rep["loops"]["accepted"] >= 3 and rep["loops"]["false_accepted"] == 0, rep["loops"]
    assert "kind: orb" in (out / "config.yaml").read_text()
    # stderr is not a terminal here: one line per stage, no bar
    assert "\r" not in proc.stderr, proc.stderr[-500:]
    assert "rendering: 470/470 frame in " in proc.stderr and "frames: 470/470 img in " in proc.stderr, proc.stderr
    print(proc.stdout)


def test_run_without_weights_fails_with_the_weights_message(offline_demo, tmp_path):
    _, _, log, env = offline_demo
    assert log is not None and log.is_file()
    proc = subprocess.run([sys.executable, "-m", "slam_lcd", "run", str(log), "--out", str(tmp_path / "out"),
                           "--no-progress"], env=env, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 2, proc.stderr
    err = proc.stderr.strip().splitlines()
    assert len(err) == 1, err
    assert "SuperPoint weights not found locally" in err[0] and env["SLAM_LCD_SUPERPOINT_URL"] in err[0]
    assert "--weights" in err[0] and "--features orb" in err[0]
    assert not (tmp_path / "out" / "corrected.tum").exists()


def test_demo_asked_for_superpoint_does_not_fall_back(offline_demo, tmp_path):
    _, _, _, env = offline_demo
    proc = subprocess.run([sys.executable, "-m", "slam_lcd", "demo", "--features", "superpoint", "--frames", "10",
                           "--out", str(tmp_path / "o")], env=env, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 2 and "SuperPoint weights not found locally" in proc.stderr
    assert NOTICE not in proc.stdout


def test_weights_command_shows_the_search(offline_demo, superpoint_weights):
    _, _, _, env = offline_demo
    proc = subprocess.run([sys.executable, "-m", "slam_lcd", "weights"], env=env, capture_output=True, text=True,
                          timeout=300)
    assert proc.returncode == 1, proc.stderr  # nothing to use: exit 1
    out = proc.stdout
    assert "$SLAM_LCD_SUPERPOINT_WEIGHTS" in out and env["SLAM_LCD_CACHE_DIR"] in out
    assert env["SLAM_LCD_SUPERPOINT_URL"] in out and "used:     none found locally" in out
    # with a file named: which file, its sha256, not the official release, loads as SuperPoint
    proc = subprocess.run([sys.executable, "-m", "slam_lcd", "weights", "--weights", str(superpoint_weights)],
                          env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    from slam_lcd.files.hashing import sha256_of

    assert f"used:     {superpoint_weights}" in proc.stdout
    assert f"sha256:   {sha256_of(superpoint_weights)}" in proc.stdout
    assert "official: no" in proc.stdout and "loads (strict)" in proc.stdout
    # fetch offline: one line naming the URL, exit 2, nothing left in the cache
    proc = subprocess.run([sys.executable, "-m", "slam_lcd", "weights", "fetch"], env=env, capture_output=True,
                          text=True, timeout=300)
    assert proc.returncode == 2 and env["SLAM_LCD_SUPERPOINT_URL"] in proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1
    assert not (__import__("pathlib").Path(env["SLAM_LCD_CACHE_DIR"]) / "superpoint_v1.pth").exists()
