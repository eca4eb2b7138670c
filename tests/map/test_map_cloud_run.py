"""The map cloud of a run (the short RGB-D demo log, ORB): map.ply / map_odometry.ply, their figures
against the demo world's true surfaces, corrected.mcap's PointCloud2, report.html's top views,
export-map (the same cloud again; bad input), and a forced false loop that the figures notice."""
from __future__ import annotations

import json
import re
import shutil
import subprocess

import numpy as np
import pytest

from slam_lcd.cloud import read_cloud
from slam_lcd.outputs.report_schema import check_report


@pytest.fixture(scope="module")
def cloud_run(report_run):
    rc, out, log = report_run
    assert rc == 0
    return out, log, json.loads((out / "report.json").read_text())


def test_both_maps_written_and_the_correction_sharpens_and_corrects_them(cloud_run):
    out, _, rep = cloud_run
    assert check_report(rep) == []
    mc = rep["map_cloud"]
    assert mc["built"] and mc["keyframes_used"] == rep["keyframes"] and not mc["keyframes_skipped"]
    for name, key in (("map.ply", "corrected"), ("map_odometry.ply", "odometry")):
        c = read_cloud(out / name)
        assert len(c) == mc["points"][key] > 10000
        assert np.ptp(c.colours) > 50  # intensity from the grey image, not one flat colour
    s, t = mc["sharpness"], mc["truth"]
    assert t["ratio_after_before"] <= 0.35, t  # distance to the true surfaces: after <= 35 % of before
    assert s["corrected"]["mme"] < s["odometry"]["mme"], s
    assert s["corrected"]["plane_variance_m2"] < s["odometry"]["plane_variance_m2"], s
    md = (out / "report.md").read_text()
    assert "## Map cloud" in md and "mean map entropy" in md and "true surfaces" in md


def test_corrected_mcap_carries_the_map_as_one_pointcloud2(cloud_run):
    from rosbags.highlevel import AnyReader

    out, _, rep = cloud_run
    n = len(read_cloud(out / "map.ply"))
    with AnyReader([out / "corrected.mcap"]) as r:
        clouds = [r.deserialize(raw, c.msgtype) for c, _, raw in r.messages()
                  if c.msgtype == "sensor_msgs/msg/PointCloud2"]
        path_frame = next(r.deserialize(raw, c.msgtype).header.frame_id for c, _, raw in r.messages()
                          if c.topic == "/slam_lcd/corrected/path")
    assert len(clouds) == 1
    m = clouds[0]
    assert m.width * m.height == n and m.header.frame_id == path_frame  # the corrected trajectory's frame
    xyz = np.frombuffer(bytes(m.data), np.float32).reshape(-1, 4)[:, :3]
    np.testing.assert_array_equal(xyz, read_cloud(out / "map.ply").points)


def test_report_html_shows_both_top_views_in_headless_chromium(cloud_run, tmp_path):
    out, _, _ = cloud_run
    page = (out / "report.html").read_text()
    assert "id='map-top-odometry'" in page and "id='map-top-corrected'" in page
    from support.browser import find_browser

    browser = find_browser()
    if browser is None:
        pytest.skip("no headless browser: install Debian's chromium package (apt-get install chromium) to run this")
    script = ("<script>addEventListener('load',()=>{const r=['map-top-odometry','map-top-corrected'].map(i=>"
              "{const e=document.getElementById(i);return e.complete&&e.naturalWidth>100&&e.getBoundingClientRect()"
              ".width>50?e.naturalWidth+'x'+e.naturalHeight:'no'});document.body.dataset.tops=r.join(',')})</script>")
    page_path = tmp_path / "report.html"  # the page with a probe that reports whether both images decoded
    page_path.write_text(page.replace("script-src 'unsafe-inline'", "script-src 'unsafe-inline'").replace(
        "</body>", script + "</body>"))
    args = [browser, "--headless", "--no-sandbox", "--disable-gpu", "--no-first-run", "--disable-extensions",
            f"--user-data-dir={tmp_path / 'profile'}", "--virtual-time-budget=5000", "--window-size=1400,2400"]
    dom = subprocess.run([*args, "--dump-dom", page_path.as_uri()], capture_output=True, text=True, timeout=180)
    assert dom.returncode == 0, dom.stderr[-2000:]
    tops = re.search(r'data-tops="([^"]*)"', dom.stdout)
    assert tops and "no" not in tops.group(1).split(","), dom.stdout[:300]
    a, b = tops.group(1).split(",")
    assert a == b  # same bounds and scale: the same size


def test_export_map_rebuilds_the_runs_cloud_and_takes_other_settings(cloud_run, tmp_path, capsys):
    from slam_lcd.cli.main import main

    out, _, rep = cloud_run
    assert main(["export-map", str(out), str(tmp_path / "same.ply")]) == 0
    a, b = read_cloud(out / "map.ply"), read_cloud(tmp_path / "same.ply")
    assert len(a) == len(b)
    np.testing.assert_allclose(a.points, b.points, atol=1e-5)
    assert main(["export-map", str(out), str(tmp_path / "coarse.pcd"), "--voxel", "0.2", "--max-depth", "3"]) == 0
    coarse = read_cloud(tmp_path / "coarse.pcd")
    assert 0 < len(coarse) < len(a) / 4
    assert main(["export-map", str(out), str(tmp_path / "odo.ply"), "--odometry"]) == 0
    # odometry.tum interpolated at the keyframes (the run had the poses themselves): the same map to 1 %
    assert len(read_cloud(tmp_path / "odo.ply")) == pytest.approx(rep["map_cloud"]["points"]["odometry"], rel=0.01)


def test_export_map_bad_input_is_one_line_exit_2_nothing_written(cloud_run, tmp_path, capsys):
    from slam_lcd.cli.main import main

    out, log, _ = cloud_run
    run_copy = tmp_path / "run"
    run_copy.mkdir()
    for f in ("report.json", "keyframes_corrected.tum", "odometry.tum"):
        shutil.copy(out / f, run_copy / f)
    rep = json.loads((run_copy / "report.json").read_text())
    rep["input"]["log"] = str(tmp_path / "gone.mcap")
    (run_copy / "report.json").write_text(json.dumps(rep))
    cases = [([str(tmp_path), str(tmp_path / "a.ply")], "not a slam-lcd run folder"),
             ([str(run_copy), str(tmp_path / "b.ply")], "is gone"),
             ([str(out), str(tmp_path / "c.xyz")], ".ply or .pcd"),
             ([str(out), str(tmp_path / "d.ply"), "--voxel", "0"], "out of range")]
    for argv, words in cases:
        assert main(["export-map", *argv]) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and words in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]


def test_a_forced_false_loop_makes_the_ground_truth_free_figures_worse(cloud_run, tmp_path_factory, monkeypatch):
    """The back end told to take everything (no gate, no GNC, no robust kernel) and one false loop handed
    in: the query keyframe claimed to stand where a keyframe on the other side of the block stood."""
    from slam_lcd.config import load_config
    from slam_lcd.lcd.detector import LoopDetector
    from slam_lcd.run import OutputOptions, run_log
    from slam_lcd.types import LoopClosure

    out, log, rep = cloud_run
    n = rep["keyframes"]
    query, match = int(0.8 * n), int(0.3 * n)
    added = []
    real_add = LoopDetector.add

    def add(self, kf, **kw):
        closures = real_add(self, kf, **kw)
        if kf.id == query:
            added.append(LoopClosure(query, match, np.eye(4), np.eye(6) * 1e4, {"forced": True}))
            closures = [*closures, added[-1]]
        return closures

    monkeypatch.setattr(LoopDetector, "add", add)
    cfg = load_config("orb", ["features.feature_cache=false", "run.plots=false", "run.loop_pictures=false",
                              "backend.outlier_rejection=none", "backend.loop_kernel=none"])
    bad_out = tmp_path_factory.mktemp("false_loop") / "out"
    res = run_log(log, bad_out, cfg, output=OutputOptions(progress=False, write_mcap=False))
    assert added and res.map_cloud["built"]
    good, bad = rep["map_cloud"]["sharpness"]["corrected"], res.map_cloud["sharpness"]["corrected"]
    assert bad["mme"] > good["mme"] and bad["plane_variance_m2"] > good["plane_variance_m2"], (good, bad)
    assert res.ate_after > 2 * rep["eval"]["ate"]["after"]["translation_m"]["rmse"]  # it is a bad correction
