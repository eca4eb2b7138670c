"""`slam-lcd view` and `run --rerun`: recordings read back with Rerun's own reader.

The counts come from the folders' own files (keyframes_corrected.tum, loops.csv, map.ply, the map's
graph), so a recording that drops or invents a keyframe, a loop or a point fails here.
"""
from __future__ import annotations

import ast
import csv
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("rerun", reason="the viewer extra (rerun-sdk) is not installed")

from support.bad_input_files import assert_one_line, leftovers, run_cli, sha256_tree
from support.paths import REPO

ORB = ["--features", "orb", "--no-feature-cache", "--no-progress"]


def read_rrd(path: Path) -> dict[str, list]:
    """Entity path -> its chunks' record batches (Rerun's reader; the first recording store)."""
    from rerun.chunk import RrdReader

    out: dict[str, list] = {}
    for c in RrdReader(path).stream().to_chunks():
        out.setdefault(c.entity_path, []).append(c.to_record_batch())
    return out


def rows(batches, column: str) -> list:
    return [v for b in batches if column in b.schema.names for v in b.column(column).to_pylist()]


def last(batches, column: str) -> list:
    """The value of an entity's last row (a static entity's one row: a list of points, ids ...)."""
    return rows(batches, column)[-1]


def strips(batches) -> int:
    """Line strips of an entity's last row (the loops are logged once, static)."""
    return len(last(batches, "LineStrips3D:strips"))


@pytest.fixture(scope="module")
def run_rrd(report_run, tmp_path_factory):
    rc, out, _ = report_run
    assert rc == 0
    rrd = tmp_path_factory.mktemp("view_run") / "run.rrd"
    from slam_lcd.cli.main import main

    assert main(["view", str(out), "--save", str(rrd)]) == 0
    return out, rrd, read_rrd(rrd)


def test_run_recording_holds_every_keyframe_loop_and_point(run_rrd):
    from slam_lcd.cloud.files import read_cloud
    from slam_lcd.io.trajectory_files import read_tum

    out, rrd, ents = run_rrd
    for path in ("/world/odometry", "/world/corrected", "/world/keyframes", "/world/keyframes/camera",
                 "/world/map/corrected", "/world/map/odometry", "/loops/table", "/ate/corrected", "/ate/odometry"):
        assert path in ents, sorted(ents)
    kf = read_tum(out / "keyframes_corrected.tum")
    cams = ents["/world/keyframes/camera"]
    assert len(rows(cams, "Transform3D:translation")) == len(kf)
    assert len(rows(cams, "Pinhole:image_from_camera")) == len(kf)
    # on the log's timeline: each keyframe at its own stamp
    stamps = sorted(int(s.value) if hasattr(s, "value") else int(s.timestamp() * 1e9) for s in rows(cams, "stamp"))
    assert np.abs(np.array(stamps) - kf.stamps).max() < 1000
    with open(out / "loops.csv", newline="") as fh:
        loops = list(csv.DictReader(fh))
    acc = sum(r["backend_verdict"] == "accepted" for r in loops)
    assert acc > 0 and len(loops) - acc > 0, "the demo run should have loops of both verdicts"
    assert strips(ents["/world/loops/accepted"]) == acc
    assert strips(ents["/world/loops/rejected"]) == len(loops) - acc
    assert sorted(last(ents["/world/loops/accepted"], "query_id")) == sorted(
        int(r["query_id"]) for r in loops if r["backend_verdict"] == "accepted")
    assert len(rows(ents["/loops/events"], "TextLog:text")) == len(loops)
    assert len(last(ents["/world/map/corrected"], "Points3D:positions")) == len(read_cloud(out / "map.ply"))
    assert len(last(ents["/world/map/odometry"], "Points3D:positions")) == len(read_cloud(out / "map_odometry.ply"))
    assert len(rows(ents["/ate/corrected"], "Scalars:scalars")) > len(kf)


def test_run_recording_shows_each_keyframes_image_read_from_the_log(run_rrd, report_run):
    """One thumbnail per keyframe, at the keyframe's stamp, and it is the log's image at that stamp."""
    import cv2

    from slam_lcd.io import open_log
    from slam_lcd.io.trajectory_files import read_tum
    from slam_lcd.sensors.messages import decode_any_image
    from slam_lcd.viewer.images import thumbnail

    out, _, ents = run_rrd
    kf = read_tum(out / "keyframes_corrected.tum")
    blobs = rows(ents["/world/keyframes/camera"], "EncodedImage:blob")
    assert len([b for b in blobs if b]) == len(kf)
    first = cv2.imdecode(np.asarray(blobs[0][0], np.uint8), cv2.IMREAD_UNCHANGED)  # a row: [the JPEG's bytes]
    with open_log(report_run[2]) as reader:
        m = next(m for m in reader.messages(["/camera/image_raw"]) if abs(m.stamp - int(kf.stamps[0])) < 1_000_000)
        want = thumbnail(decode_any_image(m))[0]
    want = cv2.cvtColor(want, cv2.COLOR_RGB2BGR) if want.ndim == 3 else want
    assert first.shape == want.shape and np.abs(first.astype(float) - want).mean() < 8


def test_run_recording_shows_the_keypoints_the_run_kept_on_each_image(run_rrd, tmp_path):
    """keyframe_keypoints.npz: one set of keypoints per keyframe, at the thumbnail's scale; a run folder
    without the file shows its images without keypoints."""
    import shutil

    from slam_lcd.io.trajectory_files import read_tum
    from slam_lcd.outputs.keypoints import KEYPOINTS_FILE, read_keyframe_keypoints
    from slam_lcd.viewer.images import IMAGE_WIDTH

    out, _, ents = run_rrd
    kf = read_tum(out / "keyframes_corrected.tum")
    kept = read_keyframe_keypoints(out / KEYPOINTS_FILE)
    assert len(kept) == len(kf) and min(len(v) for v in kept.values()) > 50
    shown = rows(ents["/world/keyframes/camera/keypoints"], "Points2D:positions")
    assert len(shown) == len(kf)
    first = np.array(shown[0], np.float32)
    want = kept[min(kept)]
    width = float(json_report(out)["map_cloud"]["sensor"]["camera"]["width"])
    np.testing.assert_allclose(first, want * min(1.0, IMAGE_WIDTH / width), atol=1e-3)

    bare = tmp_path / "run"
    shutil.copytree(out, bare)
    (bare / KEYPOINTS_FILE).unlink()
    from slam_lcd.cli.main import main

    assert main(["view", str(bare), "--save", str(tmp_path / "bare.rrd")]) == 0
    again = read_rrd(tmp_path / "bare.rrd")
    assert len([b for b in rows(again["/world/keyframes/camera"], "EncodedImage:blob") if b]) == len(kf)
    assert "/world/keyframes/camera/keypoints" not in again


def json_report(out: Path) -> dict:
    import json

    return json.loads((out / "report.json").read_text(encoding="utf-8"))


def test_a_moved_log_is_one_line_and_the_rest_is_drawn(run_rrd, report_run, tmp_path, capfd):
    import json
    import shutil

    from slam_lcd.io.trajectory_files import read_tum

    out = tmp_path / "run"
    shutil.copytree(run_rrd[0], out)
    doc = json.loads((out / "report.json").read_text(encoding="utf-8"))
    gone = tmp_path / "moved" / "demo.mcap"
    doc["input"]["log"] = str(gone)
    (out / "report.json").write_text(json.dumps(doc), encoding="utf-8")
    n = len(read_tum(out / "keyframes_corrected.tum"))

    rc, stdout, err = run_cli(["view", str(out), "--save", str(tmp_path / "a.rrd")], capfd)
    assert rc == 0, err
    assert assert_one_line(err) == (f"WARNING: {gone}: the run's log is not there (moved?): its keyframe images and "
                                    "the ATE over time are not shown; give its place with --log PATH")
    ents = read_rrd(tmp_path / "a.rrd")
    assert len(rows(ents["/world/keyframes/camera"], "Transform3D:translation")) == n
    assert not [b for b in rows(ents["/world/keyframes/camera"], "EncodedImage:blob") if b]
    assert "/world/corrected" in ents and "/world/loops/accepted" in ents

    rc, stdout, err = run_cli(["view", str(out), "--save", str(tmp_path / "b.rrd"), "--log", str(report_run[2])], capfd)
    assert rc == 0 and err.strip() == "", err
    ents = read_rrd(tmp_path / "b.rrd")
    assert len([b for b in rows(ents["/world/keyframes/camera"], "EncodedImage:blob") if b]) == n
    assert "/ate/corrected" in ents

    rc, _, err = run_cli(["view", str(out), "--save", str(tmp_path / "c.rrd"), "--log", str(gone)], capfd)
    assert rc == 2
    assert assert_one_line(err) == f"slam-lcd view: error: {gone}: no such log (--log)"


def test_recording_carries_the_projects_layout(run_rrd):
    from rerun.chunk import RrdReader

    _, rrd, _ = run_rrd
    reader = RrdReader(rrd)
    assert reader.blueprints(), "no default blueprint in the recording"
    bp = reader.stream(store=reader.blueprints()[0]).to_chunks()
    classes = {n for c in bp for n in c.to_record_batch().schema.names}
    assert any("ViewClass" in n or "class_identifier" in n for n in classes) or len(bp) > 3, classes


@pytest.fixture(scope="module")
def three_session_map(tmp_path_factory, visit_logs):
    """Sessions s1, s2 (a second visit of s1's route) and s4 (another world) in one map."""
    from slam_lcd.cli.main import main


    root = tmp_path_factory.mktemp("view_map")
    logs = visit_logs
    for k in (1, 2, 4):
        assert main(["run", str(logs[k]), "--map", str(root / "map"), "--out", str(root / f"r{k}"), *ORB]) == 0
    return root


def test_map_recording_holds_every_session_and_loop(three_session_map, tmp_path):
    from slam_lcd.cli.main import main
    from slam_lcd.map.session_map import Map

    m = three_session_map / "map"
    rrd = tmp_path / "map.rrd"
    assert main(["view", str(m), "--save", str(rrd)]) == 0
    ents = read_rrd(rrd)
    with Map.open(m) as the_map:
        names = the_map.session_names
        sizes = {n: len(s) for n, s in zip(names, the_map.sessions, strict=True)}
        accepted = int(np.sum(the_map.graph.loop_accepted))
        total = len(the_map.graph.loop_accepted)
    assert len(names) == 3
    for n in names:
        assert len(last(ents[f"/world/sessions/{n}/keyframes"], "Points3D:positions")) == sizes[n]
        assert f"/world/sessions/{n}/trajectory" in ents
        assert len(rows(ents[f"/world/sessions/{n}/pose"], "stamp")) == sizes[n]
    got = sum(strips(ents[f"/world/loops/{v}"]) for v in ("accepted", "rejected") if f"/world/loops/{v}" in ents)
    assert got == total
    assert (strips(ents["/world/loops/accepted"]) if "/world/loops/accepted" in ents else 0) == accepted
    assert any(last(ents["/world/loops/accepted"], "inter_session")), "no accepted loop between sessions"


def test_run_rerun_logs_keyframe_images_while_it_goes(small_log, tmp_path):
    from slam_lcd.cli.main import main
    from slam_lcd.io.trajectory_files import read_tum

    rrd = tmp_path / "live.rrd"
    assert main(["run", str(small_log), "--out", str(tmp_path / "out"), *ORB, "--rerun", str(rrd)]) == 0
    assert not leftovers(tmp_path)
    ents = read_rrd(rrd)
    n = len(read_tum(tmp_path / "out" / "keyframes_corrected.tum"))
    live = ents["/world/live/camera"]
    assert len(rows(live, "EncodedImage:blob")) == n
    kps = rows(ents["/world/live/camera/keypoints"], "Points2D:positions")
    assert len(kps) == n and all(len(k) > 0 for k in kps)
    assert len(rows(ents["/world/keyframes/camera"], "Transform3D:translation")) == n  # the run folder, at the end
    assert "/world/map/corrected" in ents


@pytest.mark.parametrize("case", ["neither", "missing", "inside", "suffix", "localization-with-run"])
def test_bad_input_is_one_line_and_nothing_written(case, run_rrd, tmp_path, capfd):
    import shutil

    out, _, _ = run_rrd
    target = tmp_path / "x.rrd"
    folder = out
    extra: list[str] = []
    if case == "neither":
        folder = tmp_path / "empty"
        folder.mkdir()
        needle = "neither a slam-lcd run folder"
    elif case == "missing":
        folder = tmp_path / "run"
        shutil.copytree(out, folder)
        (folder / "loops.csv").unlink()
        needle = "no loops.csv"
    elif case == "inside":
        target = out / "view.rrd"
        needle = "inside the input folder"
    elif case == "suffix":
        target = tmp_path / "x.mcap"
        needle = ".rrd"
    else:
        extra = ["--localization", str(out)]
        needle = "--localization goes with a map folder"
    before = sha256_tree(out)
    rc, _, err = run_cli(["view", str(folder), "--save", str(target), *extra], capfd)
    assert rc == 2, err
    assert_one_line(err, needle, str(target if case in ("inside", "suffix") else folder))
    assert not target.exists() and not leftovers(tmp_path, out)
    assert sha256_tree(out) == before


def test_without_rerun_view_and_run_rerun_say_how_to_install(run_rrd, small_log, tmp_path, capfd, monkeypatch):
    import sys

    out, _, _ = run_rrd
    monkeypatch.setitem(sys.modules, "rerun", None)  # `import rerun` raises ImportError, as when it is absent
    for argv in (["view", str(out), "--save", str(tmp_path / "a.rrd")],
                 ["run", str(small_log), "--out", str(tmp_path / "o"), *ORB, "--rerun", str(tmp_path / "b.rrd")]):
        rc, _, err = run_cli(argv, capfd)
        assert rc == 2, err
        assert_one_line(err, "pip install 'slam-lcd[viewer]'")
    assert not list(tmp_path.iterdir())


def test_no_module_outside_the_viewer_imports_rerun():
    """rerun is optional: only slam_lcd/viewer imports it, and only inside functions (lazily)."""
    pkg = REPO / "slam_lcd"
    found = []
    for p in pkg.rglob("*.py"):
        tree = ast.parse(p.read_text())
        top = {id(n) for n in tree.body}
        for n in ast.walk(tree):
            names = ([a.name for a in n.names] if isinstance(n, ast.Import) else
                     [n.module or ""] if isinstance(n, ast.ImportFrom) and not n.level else [])
            if any(x == "rerun" or x.startswith("rerun.") for x in names):
                rel = p.relative_to(pkg).as_posix()
                if not rel.startswith("viewer/") or id(n) in top:
                    found.append(f"{rel}:{n.lineno}")
    assert not found, f"rerun imported outside slam_lcd/viewer or at module level: {found}"


def test_web_viewer_serves_on_loopback_and_draws_the_3d_view(three_session_map, tmp_path):
    """`view MAP --web`: the page answers on loopback and headless Chromium draws the sessions' colours."""
    import os
    import subprocess
    import sys
    import urllib.request

    from support.browser import find_browser, screenshot_when
    from support.offline import free_port

    browser = find_browser()
    if browser is None:
        pytest.skip("no headless browser: install Debian's chromium package to run this")
    port = free_port()
    env = dict(os.environ, PYTHONPATH=str(REPO))
    proc = subprocess.Popen([sys.executable, "-m", "slam_lcd", "view", str(three_session_map / "map"), "--web",
                             "--port", str(port)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    try:
        line = ""
        while "web viewer:" not in line:
            line = proc.stdout.readline()
            assert line or proc.poll() is None, proc.stderr.read()
        url = line.split()[2]
        assert url.startswith(f"http://127.0.0.1:{port}/") and "127.0.0.1" in url.split("url=")[1]
        assert urllib.request.urlopen(f"http://127.0.0.1:{port}/", timeout=10).status == 200
        png = screenshot_when(browser, url, free_port(), _draws_sessions)
    finally:
        proc.terminate()
        proc.wait(timeout=30)
    if png is None:
        pytest.skip("headless Chromium could not be driven here (no DevTools page)")
    assert _draws_sessions(png), "the 3-D view never drew the three sessions' colours (90 s)"


def _session_pixels(png: bytes) -> list[int]:
    """Pixels near each of the first three session colours in the left 60 % of the picture (the 3-D view)."""
    import cv2

    from slam_lcd.viewer.record import SESSION_RGB

    img = cv2.cvtColor(cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)
    img = img[:, : int(0.6 * img.shape[1])].astype(int)
    return [int((np.abs(img - np.array(rgb)).sum(axis=2) < 40).sum()) for rgb in SESSION_RGB[:3]]


def _draws_sessions(png: bytes) -> bool:
    return min(_session_pixels(png)) > 20
