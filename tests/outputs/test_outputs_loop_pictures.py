"""Loop pictures: a JPEG per accepted loop under loops/ (the two keyframe images side
by side, surviving matches and graph edges), the back end's rejections and the closest
detector rejections with their reason, a contact sheet; the keyframe album is gone after
the run; a second run replaces the folder as a whole."""
from __future__ import annotations

import json

import cv2
import numpy as np

from slam_lcd.outputs.loop_pictures import CONTACT_SHEET, LOOPS_DIR, picture_name
from slam_lcd.outputs.output_set import OutputSet


def test_a_picture_per_accepted_loop_and_a_contact_sheet(report_run):
    _, out, _ = report_run
    rep = json.loads((out / "report.json").read_text())
    folder = out / LOOPS_DIR
    assert rep["accepted_loops"]
    for lp in rep["accepted_loops"]:
        img = cv2.imread(str(folder / picture_name(lp["query_id"], lp["match_id"], "accepted")))
        assert img is not None, lp
        assert img.shape[1] == 2 * 320 and img.shape[0] > 240  # two 320x240 frames under a caption band
        # matches drawn: green pixels (surviving matches) well beyond what the grey images hold
        green = (img[..., 1] > 180) & (img[..., 0] < 120) & (img[..., 2] < 120)
        assert green.sum() > 200
    rejected = sorted(folder.glob("*_rejected.jpg"))
    assert 1 <= len(rejected) <= 8 + rep["loops"]["rejected_by_backend"]
    sheet = cv2.imread(str(folder / CONTACT_SHEET))
    assert sheet is not None and sheet.shape[0] > 100
    assert f"{LOOPS_DIR}/" in rep["outputs"]
    assert not [p for p in out.iterdir() if p.name.startswith(".")]  # album and staging removed
    assert not [p for p in out.parent.iterdir() if p.name.startswith(".slam-lcd-staging")]


def test_folder_output_replaced_as_a_whole(tmp_path):
    target = tmp_path / "out"
    (target / LOOPS_DIR).mkdir(parents=True)
    (target / LOOPS_DIR / "old.png").write_bytes(b"x")
    (target / "mine.txt").write_text("the user's")
    s = OutputSet(target, ["report.md", LOOPS_DIR])
    (s.staging / LOOPS_DIR).mkdir()
    (s.staging / LOOPS_DIR / "new.png").write_bytes(b"y")
    (s.staging / ".album").mkdir()
    (s.staging / ".album" / "1.jpg").write_bytes(b"z")
    (s.staging / "report.md").write_text("r")
    assert s.publish() == [LOOPS_DIR, "report.md"]
    assert sorted(p.name for p in (target / LOOPS_DIR).iterdir()) == ["new.png"]
    assert (target / "mine.txt").read_text() == "the user's" and not (target / ".album").exists()
    # a run that wrote no pictures removes an earlier run's folder
    s = OutputSet(target, ["report.md", LOOPS_DIR])
    (s.staging / "report.md").write_text("r2")
    s.publish()
    assert not (target / LOOPS_DIR).exists() and np.array_equal(sorted(p.name for p in target.iterdir()),
                                                                ["mine.txt", "report.md"])


def test_album_keeps_the_loops_the_detector_verified(tmp_path):
    """A loop's picture uses the matches and kept rows the detector handed on, not a recomputation."""
    from types import SimpleNamespace

    import numpy as np

    from slam_lcd.outputs.loop_pictures import KeyframeAlbum

    album = KeyframeAlbum(tmp_path / "album")
    matches = np.array([[0, 3], [1, 4], [2, 5], [7, 9]])
    rec = SimpleNamespace(query_id=12, match_id=3, n_matches=4, graph_matches=matches,
                          graph=SimpleNamespace(kept=np.array([0, 1, 3]), n_nodes=3))
    album.keep_loop(rec)
    m, kept, n, nodes = album.load_loop(12, 3)
    assert np.array_equal(m, matches) and np.array_equal(kept, [0, 1, 3]) and (n, nodes) == (4, 3)
    assert album.load_loop(3, 12) is None
    album.keep_loop(SimpleNamespace(query_id=1, match_id=0, n_matches=0, graph_matches=None, graph=None))
    assert album.load_loop(1, 0) is None


def test_picture_thread_stops_between_pictures_when_the_outputs_are_abandoned(monkeypatch, tmp_path):
    """An error or Ctrl-C while the other outputs are written (or while waiting for the pictures):
    the thread stops after its current picture, the album is removed, no picture is reported."""
    import threading
    from types import SimpleNamespace

    import slam_lcd.outputs.loop_pictures as LP
    from slam_lcd.outputs.write import _PictureThread

    drawn, started = [], threading.Event()

    def slow(out_dir, album, rows, lcd_conf, n_rejected, stop=None, thumbnails=None, thumb_width=240):
        started.set()
        while not stop.is_set():
            drawn.append(1)
            stop.wait(0.01)
        return ["never.png"]

    monkeypatch.setattr(LP, "write_loop_pictures", slow)
    closed = []
    album = SimpleNamespace(close=lambda: closed.append(1))
    cfg = SimpleNamespace(lcd=None, run=SimpleNamespace(loop_pictures_rejected=0))
    t = _PictureThread(tmp_path, album, [], cfg)
    started.wait(5)
    assert t.join(stop=True) == [] and closed == [1] and not t.thread.is_alive()

    closed.clear()
    t = _PictureThread(tmp_path, album, [], cfg)
    started.wait(5)
    real_join = t.thread.join
    calls = []

    def interrupted_join(*a):
        calls.append(1)
        if len(calls) == 1:
            raise KeyboardInterrupt
        return real_join(*a)

    t.thread.join = interrupted_join
    import pytest

    with pytest.raises(KeyboardInterrupt):
        t.join()
    assert t.stop.is_set() and not t.thread.is_alive() and closed == [1]


def test_many_loops_each_get_a_picture_in_order_and_the_contact_sheet_keeps_at_most_its_cap(tmp_path):
    """130 accepted loops: 130 pictures listed in the chosen order (two threads make them), a thumbnail
    each, and a contact sheet of CONTACT_SHEET_MAX (120) evenly spread tiles (4 to a row)."""
    from types import SimpleNamespace

    from slam_lcd.config import load_config
    from slam_lcd.outputs.loop_pictures import CONTACT_SHEET_MAX, KeyframeAlbum, _pictured, write_loop_pictures

    rng = np.random.default_rng(0)
    album = KeyframeAlbum(tmp_path / "album")
    for k in range(131):
        kp = rng.uniform(4, 60, (12, 2)).astype(np.float32)
        feats = SimpleNamespace(keypoints=kp, descriptors=rng.standard_normal((12, 8)).astype(np.float32),
                                image_size=(64, 48))
        album(SimpleNamespace(id=k, image=rng.integers(0, 255, (48, 64), dtype=np.uint8), features=feats))
    rows = []
    for q in range(1, 131):
        album.keep_loop(SimpleNamespace(query_id=q, match_id=q - 1, n_matches=12, graph_matches=np.stack(
            [np.arange(12), np.arange(12)], 1), graph=SimpleNamespace(kept=np.arange(10), n_nodes=10)))
        rows.append(dict(query_id=q, match_id=q - 1, backend_verdict="accepted", backend_reason="ok", reason="ok",
                         rank=0, bow_score="0.5", n_matches=12, graph_nodes=10, pose_inliers=9, gt_distance_m="",
                         err_trans_m="", err_rot_deg=""))
    thumbs: dict = {}
    names = write_loop_pictures(tmp_path, album, rows, load_config("default").lcd, 0, thumbnails=thumbs)
    expected = [picture_name(r["query_id"], r["match_id"], "accepted") for r, _ in _pictured(rows, 0)]
    assert names == expected + [CONTACT_SHEET] and len(expected) == 130
    assert sorted(thumbs) == sorted(expected)
    for n in names[:-1:17]:
        img = cv2.imread(str(tmp_path / LOOPS_DIR / n))
        assert img.shape[1] == 128 and img.shape[0] > 48
    sheet = cv2.imread(str(tmp_path / LOOPS_DIR / CONTACT_SHEET))
    tile_h = round(img.shape[0] * 360 / 128)
    assert sheet.shape[1] == 4 * (360 + 8)
    assert sheet.shape[0] == (CONTACT_SHEET_MAX // 4) * (tile_h + 8)


def test_scaled_pictures_are_the_area_mean_of_the_picture():
    """The contact-sheet tiles are halved first (OpenCV's fast whole-number path): the same picture as one
    area resize, up to the rounding of the halved image."""
    from slam_lcd.outputs.loop_pictures import _scaled

    rng = np.random.default_rng(0)
    pic = cv2.GaussianBlur((rng.random((542, 1280, 3)) * 255).astype(np.uint8), (0, 0), 4)  # a textured scene
    pic = cv2.normalize(pic, None, 0, 255, cv2.NORM_MINMAX)
    pic[100:300, 200:900] = (40, 200, 60)
    cv2.polylines(pic, list(rng.integers(0, 540, (80, 2, 2)).astype(np.int32)), False, (0, 220, 255), 1, cv2.LINE_AA)
    for width, mean_max in ((360, 1.5), (240, 3.0), (700, 0.0), (1280, 0.0)):  # 360: the tiles; >= half: one resize
        ref = cv2.resize(pic, (width, round(542 * width / 1280)), interpolation=cv2.INTER_AREA)
        got = _scaled(pic, width)
        assert got.shape == ref.shape and got.dtype == np.uint8
        diff = np.abs(got.astype(int) - ref)
        assert diff.mean() <= mean_max and np.percentile(diff, 99) <= 16, (width, diff.mean())
