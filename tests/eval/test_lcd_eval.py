"""Ground-truth formats, precision-recall bookkeeping, temporal consistency and the eval-lcd CLI."""
from __future__ import annotations

import csv
import json
import shutil

import numpy as np
import pytest

from slam_lcd.cli.main import main
from slam_lcd.errors import InputError
from slam_lcd.eval.loop_detection import (
    average_precision,
    load_loop_matrix,
    loops_from_poses,
    place_recall,
    precision_recall,
    retrieval_recall,
    revisit_places,
)
from slam_lcd.lcd import CandidateRecord, TemporalConsistency


def test_gt_formats_agree(tmp_path, shared_data):
    names = [f"{i}.jpg" for i in range(1, 85)]
    bmp = load_loop_matrix(shared_data / "rtabmap_corridor" / "samples_GT.bmp", names)
    assert bmp.shape == (84, 84) and bmp.sum() == 2 * 228
    assert bmp[40, 0] and bmp[0, 40]  # frame 41 closes a loop with frame 1
    np.save(tmp_path / "gt.npy", np.tril(bmp))
    assert np.array_equal(load_loop_matrix(tmp_path / "gt.npy", names), bmp)
    i, j = np.nonzero(np.tril(bmp))
    rows = ["query,match"] + [f"{a + 1},{b + 1}" for a, b in zip(i, j, strict=True)]  # file stems
    (tmp_path / "gt.csv").write_text("\n".join(rows))
    assert np.array_equal(load_loop_matrix(tmp_path / "gt.csv", names), bmp)
    with pytest.raises(InputError, match="84x84 but there are 10 images"):
        load_loop_matrix(tmp_path / "gt.npy", names[:10])


def test_loops_from_poses():
    poses = np.repeat(np.eye(4)[None], 4, axis=0)
    poses[1, 0, 3] = 5.0
    poses[2, 0, 3] = 0.3
    poses[3, :3, :3] = np.array([[0, -1, 0], [1, 0, 0], [0, 0, 1.0]])  # same place, turned 90 deg
    gt = loops_from_poses(poses, 1.0, 30.0)
    assert gt[0, 2] and not gt[0, 1] and not gt[0, 3] and not gt[0, 0]


def _rec(q, m, s, ok=True):
    r = CandidateRecord(q, m, 0, s)
    r.reason = "ok" if ok else "x"
    return r


def test_precision_recall_bookkeeping():
    gt = np.zeros((10, 10), bool)
    for q, m in [(6, 1), (7, 2), (8, 3)]:
        gt[q, m] = gt[m, q] = True
    recs = [_rec(6, 1, 0.9), _rec(6, 4, 0.5), _rec(7, 0, 0.8), _rec(7, 2, 0.3), _rec(8, 3, 0.2), _rec(9, 1, 0.1)]
    res = precision_recall(recs, gt, "none", exclude_recent_n=3)
    # per query the best-scoring candidate: 6->1 (TP), 7->0 (FP), 8->3 (TP), 9->1 (FP)
    assert res.n_positives == 3 and res.n_detections == 4 and res.n_true == 2
    assert res.recall_at_100p == pytest.approx(1 / 3)
    assert res.precision_all == pytest.approx(0.5) and res.recall_all == pytest.approx(2 / 3)
    # sorted by score: 6 TP (P 1, R 1/3), 7 FP, 8 TP (P 2/3, R 2/3), 9 FP -> AP = 1/3 * 1 + 1/3 * 2/3
    assert res.auc == pytest.approx(1 / 3 + 2 / 9)
    assert average_precision(np.array([1.0, 1.0]), np.array([0.5, 1.0])) == pytest.approx(1.0)
    assert average_precision(np.zeros(0), np.zeros(0)) == 0.0


def test_retrieval_recall_at_n():
    gt = np.zeros((10, 10), bool)
    for q, m in [(6, 1), (7, 2), (8, 3)]:
        gt[q, m] = gt[m, q] = True
    retrieved = {6: [1, 0], 7: [0, 4, 2], 9: [1]}  # 8 retrieved nothing
    r = retrieval_recall(retrieved, gt, exclude_recent_n=3, ns=(1, 2, 3))
    assert r == {1: pytest.approx(1 / 3), 2: pytest.approx(1 / 3), 3: pytest.approx(2 / 3)}


def test_recall_per_revisit_place():
    # a straight line driven twice: keyframes 0-9 at x = 0..9 m, then 10-19 back at the same x
    n = 20
    pos = np.zeros((n, 3))
    pos[:10, 0] = np.arange(10)
    pos[10:, 0] = np.arange(10)
    gt = np.zeros((n, n), bool)
    for k in range(10):
        gt[10 + k, k] = gt[k, 10 + k] = True
    places = revisit_places(pos, gt, exclude_recent_n=5, place_size_m=2.5)
    assert [p.tolist() for p in places] == [[10, 11, 12], [13, 14, 15], [16, 17, 18], [19]]
    recs = [_rec(11, 1, 0.5), _rec(13, 9, 0.4), _rec(17, 7, 0.3)]  # 13 -> 9 is false
    assert place_recall(recs, gt, "none", places) == (2, 4)


def test_temporal_consistency():
    tc = TemporalConsistency(k=3, window=2)
    assert tc.update(10, 1) == (False, 1)
    assert tc.update(11, 2) == (False, 2)
    assert tc.update(12, 3) == (True, 3)
    assert tc.update(13, 40) == (False, 1)  # jumps elsewhere: start again
    assert tc.update(14, None) == (False, 0)
    assert TemporalConsistency(k=0).update(5, 1)[0]


@pytest.fixture()
def small_corridor(tmp_path, shared_data):
    """Frames 1-6 and 41-46 of the corridor (a revisit) with a CSV ground truth."""
    src = shared_data / "rtabmap_corridor"
    folder = tmp_path / "frames"
    folder.mkdir()
    for i in list(range(1, 7)) + list(range(41, 47)):
        shutil.copy(src / f"{i}.jpg", folder / f"{i}.jpg")
    gt = load_loop_matrix(src / "samples_GT.bmp", [f"{i}.jpg" for i in range(1, 85)])
    rows = ["query,match"]
    for a in range(41, 47):
        for b in range(1, 7):
            if gt[a - 1, b - 1]:
                rows.append(f"{a},{b}")
    (tmp_path / "gt.csv").write_text("\n".join(rows))
    return folder, tmp_path / "gt.csv"


def test_cli_eval_lcd_writes_outputs(small_corridor, tmp_path, capsys):
    folder, gt = small_corridor
    out = tmp_path / "out"
    rc = main(["eval-lcd", str(folder), "--gt", str(gt), "--features", "orb", "--exclude-recent", "5",
               "--no-feature-cache", "--out", str(out)])
    assert rc == 0
    text = capsys.readouterr().out
    assert "BoW+graph+ransac" in text
    for name in ("candidates.csv", "pr.csv", "pr.png", "summary.json", "config.yaml"):
        assert (out / name).is_file(), name
    summary = json.loads((out / "summary.json").read_text())
    assert summary["frames"] == 12 and len(summary["results"]) == 4
    assert "AUC" in text and "R@10" in text
    assert set(summary["retrieval_recall_at"]) == {"1", "5", "10"}
    assert all(0.0 <= r["pr_auc"] <= 1.0 for r in summary["results"])
    with open(out / "candidates.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert rows and {"query", "match", "bow_score", "graph_score", "ransac_inliers", "gt_loop"} <= set(rows[0])
    graph = next(r for r in summary["results"] if r["mode"] == "graph")
    assert graph["true_detections"] >= 4 and graph["precision"] == 1.0


def test_cli_eval_lcd_bad_input(tmp_path, small_corridor, capsys):
    folder, _ = small_corridor
    rc = main(["eval-lcd", str(folder), "--gt", str(tmp_path / "missing.bmp"), "--features", "orb",
               "--out", str(tmp_path / "o")])
    assert rc == 2
    err = capsys.readouterr().err
    assert "missing.bmp" in err and "Traceback" not in err
    (tmp_path / "bad.npy").write_bytes(b"not numpy")
    assert main(["eval-lcd", str(folder), "--gt", str(tmp_path / "bad.npy"), "--out", str(tmp_path / "o")]) == 2


def test_cli_eval_lcd_recall_per_place_with_a_gt_trajectory(tmp_path, capsys):
    """--gt-max-dist: loops from GT poses, and the revisit places found per chain in the table and summary."""
    from slam_lcd.sim import make_demo_log

    make_demo_log(tmp_path / "log", "folder", frames=60, camera_rate=1.0, width=320, height=240)
    out = tmp_path / "eval"
    rc = main(["eval-lcd", str(tmp_path / "log" / "image"), "--gt", str(tmp_path / "log" / "groundtruth.txt"),
               "--gt-max-dist", "1.0", "--features", "orb", "--exclude-recent", "20", "--no-feature-cache",
               "--no-progress", "--out", str(out)])
    assert rc == 0
    assert "places" in capsys.readouterr().out
    places = json.loads((out / "summary.json").read_text())["revisit_places"]
    assert set(places) == {"none", "ransac", "graph", "graph+ransac"}
    n = places["graph"]["places"]
    assert n >= 5 and all(p["places"] == n and 0 <= p["found"] <= n for p in places.values())
    assert places["graph+ransac"]["found"] >= 1
