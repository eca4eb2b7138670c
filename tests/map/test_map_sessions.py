"""Multi-session maps: joining sessions (PCM sets, anchors), localisation, the database's sessions, the example.

The full acceptance figures (three demo sessions at 640x480 with SuperPoint, another world,
localisation of a fifth session, load time at 5,000 keyframes) come from
``tools/bench_map.py``; these tests pin the mechanics on small synthetic graphs and small logs.
"""
from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from slam_lcd.geometry import inv, make_T, so3_exp
from slam_lcd.map.config import MapConfig
from slam_lcd.map.joint_graph import JointLoop, SessionPoses, solve
from slam_lcd.map.localize import localise
from slam_lcd.types import LoopClosure

from support.paths import REPO

INFO = np.diag([1e4] * 3 + [1e4] * 3)  # loops good to 1 cm / 0.6 deg


def _route(n: int, seed: int) -> np.ndarray:
    """Ground-truth body poses along a square-ish planar route, 0.5 m apart."""
    rng = np.random.default_rng(seed)
    T = [np.eye(4)]
    for i in range(1, n):
        turn = np.pi / 2 if i % 12 == 0 else rng.normal(0, 0.01)
        T.append(T[-1] @ make_T(so3_exp(np.array([0, 0, turn])), np.array([0.5, 0, 0])))
    return np.array(T)


def _drifting(T_gt: np.ndarray, seed: int, scale: float = 1.03) -> np.ndarray:
    """Odometry in its own frame (identity at the start), with a scale and heading bias."""
    rng = np.random.default_rng(seed)
    out = [np.eye(4)]
    for i in range(1, len(T_gt)):
        step = inv(T_gt[i - 1]) @ T_gt[i]
        step = make_T(step[:3, :3] @ so3_exp(np.array([0, 0, 0.004 + rng.normal(0, 0.001)])), step[:3, 3] * scale)
        out.append(out[-1] @ step)
    return np.array(out)


def _session(name: str, gt: np.ndarray, first_id: int, seed: int) -> SessionPoses:
    odo = _drifting(gt, seed)
    return SessionPoses(name, np.arange(first_id, first_id + len(gt)), odo,
                        np.repeat(np.diag([1e-4] * 3 + [1e-3] * 3)[None], len(gt), axis=0), odo.copy())


def _true_loop(gt_a, gt_b, ia: int, ib: int, id_a: int, id_b: int) -> JointLoop:
    return JointLoop(id_b + ib, id_a + ia, inv(gt_a[ia]) @ gt_b[ib], INFO, True)


@pytest.fixture(scope="module")
def two_routes():
    gt = _route(48, 1)
    return gt, gt.copy()  # the second session drives the same route on another day


def test_three_consistent_loops_join_two_sessions_and_the_map_recovers_their_relation(two_routes):
    gt_a, gt_b = two_routes
    a, b = _session("a", gt_a, 0, 1), _session("b", gt_b, 100, 2)
    loops = [_true_loop(gt_a, gt_b, i, i, 0, 100) for i in (5, 17, 29, 41)]
    res = solve([a, b], loops)
    assert res.component == {"a": 0, "b": 0}
    assert all(lp.accepted for lp in loops)
    # b's first keyframe lands where a's does (same place), though b's odometry started at its own origin
    assert np.linalg.norm(res.poses[100][:3, 3] - res.poses[0][:3, 3]) < 0.05


def test_fewer_loops_than_min_join_loops_leave_sessions_apart(two_routes):
    gt_a, gt_b = two_routes
    a, b = _session("a", gt_a, 0, 1), _session("b", gt_b, 100, 2)
    loops = [_true_loop(gt_a, gt_b, i, i, 0, 100) for i in (5, 17)]
    res = solve([a, b], loops, MapConfig(min_join_loops=3))
    assert res.component == {"a": 0, "b": 1}
    assert not any(lp.accepted for lp in loops)
    assert all("needed to join" in lp.reason for lp in loops)


def test_pcm_keeps_the_consistent_set_and_rejects_look_alike_loops(two_routes):
    gt_a, gt_b = two_routes
    a, b = _session("a", gt_a, 0, 1), _session("b", gt_b, 100, 2)
    good = [_true_loop(gt_a, gt_b, i, i, 0, 100) for i in (3, 11, 19, 27, 35)]
    # look-alike places: verified relative poses that put b somewhere else entirely
    bad = [JointLoop(100 + j, i, make_T(so3_exp(np.array([0, 0, 1.5])), np.array([0.3, 0.2, 0])), INFO, True)
           for i, j in ((8, 40), (30, 2))]
    res = solve([a, b], good + bad)
    assert all(lp.accepted for lp in good)
    assert not any(lp.accepted for lp in bad)
    assert all(lp.reason.startswith("pcm: inconsistent") for lp in bad)
    assert res.component["b"] == 0


def test_a_session_that_meets_no_other_keeps_its_own_frame(two_routes):
    gt_a, gt_b = two_routes
    a, b, c = _session("a", gt_a, 0, 1), _session("b", gt_b, 100, 2), _session("c", _route(20, 9), 200, 3)
    loops = [_true_loop(gt_a, gt_b, i, i, 0, 100) for i in (5, 17, 29)]
    res = solve([a, b, c], loops)
    assert res.component == {"a": 0, "b": 0, "c": 1}
    # c's own frame: its first keyframe stays at its odometry origin
    assert np.allclose(res.poses[200], np.eye(4), atol=1e-6)


def _closure(q: int, m: int, T: np.ndarray, inliers: int = 80) -> LoopClosure:
    return LoopClosure(q, m, T, INFO, {"inliers": inliers})


def test_localise_keeps_fixes_its_odometry_confirms_and_drops_a_look_alike():
    gt = _route(30, 4)
    odo = _drifting(gt, 5)
    map_poses = {1000 + i: gt[i] for i in range(30)}  # the map: the same route, exact
    fixes = [_closure(i, 1000 + i, np.eye(4)) for i in range(0, 30, 2)]
    fixes[5] = _closure(10, 1000 + 25, np.eye(4))  # keyframe 10 matched a place 7.5 m further on
    loc = localise(map_poses, {k: "m" for k in map_poses}, {k: 0 for k in map_poses}, list(range(30)),
                   list(range(30)), odo, [None] * 30, fixes)
    by_id = {k.kf_id: k for k in loc.keyframes}
    assert not by_id[10].localised
    assert "not confirmed" in by_id[10].reason or "GNC" in by_id[10].reason, by_id[10].reason
    assert sum(k.localised for k in loc.keyframes) == len(fixes) - 1
    err = [np.linalg.norm(k.T_map[:3, 3] - gt[k.kf_id][:3, 3]) for k in loc.keyframes]
    assert max(err) < 0.1


def test_localise_without_any_match_says_why_for_every_keyframe():
    gt = _route(10, 4)
    loc = localise({}, {}, {}, list(range(10)), list(range(10)), gt, [None] * 10, [])
    assert loc.share_localised == 0.0 and len(loc.keyframes) == 10 and len(loc.trajectory) == 0
    assert all(k.reason == "no verified match in the map" for k in loc.keyframes)
    assert "no keyframe of the log was matched" in loc.notes[0]


def test_recent_keyframes_are_excluded_within_the_current_session_only():
    from slam_lcd.vocab import BowDatabase
    from slam_lcd.vocab.config import VocabConfig

    rng = np.random.default_rng(0)
    words = rng.normal(size=(40, 32)).astype(np.float32)
    words /= np.linalg.norm(words, axis=1, keepdims=True)
    db = BowDatabase(None, VocabConfig())

    def image(i):
        d = words[(np.arange(20) + 2 * i) % 40] + rng.normal(0, 0.02, size=(20, 32)).astype(np.float32)
        return d / np.linalg.norm(d, axis=1, keepdims=True)

    for i in range(6):  # an earlier session, recorded later in time than the next one
        db.add(i, 10_000 + i, image(i))
    db.begin_session()
    db.add(6, 5, image(5))  # an older stamp is fine in a new session
    found = db.query(image(5), top_k=10, exclude_recent_n=3, query_id=99, stamp_ns=6)
    ids = {c.match_id for c in found}
    assert 5 in ids  # the earlier session's last keyframes are not "recent"
    assert 6 not in ids  # the current session's own are


@pytest.fixture(scope="module")
def example_map(tmp_path_factory):
    work = tmp_path_factory.mktemp("map_example")
    out = subprocess.run([sys.executable, str(REPO / "examples" / "multisession_map.py"), "--work", str(work)],
                         capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr[-3000:]
    return work, out.stdout


def test_example_builds_a_two_session_map_queries_it_and_feeds_a_users_isam2(example_map):
    work, text = example_map
    lines = {ln.split(":")[0]: ln for ln in text.splitlines()}
    second = lines["session5"]
    n_loops = int(second.split("matches to earlier sessions, ")[1].split(" loops")[0])
    assert n_loops >= 3, text
    assert "[['session1', 'session5']]" in second, text
    assert "matched map keyframe" in lines["query frame"], text
    diff = float(lines["user iSAM2"].split("poses ")[-1].split(" m")[0])
    assert diff < 1e-3, text


def test_map_info_and_export_read_the_map_without_changing_it(example_map, tmp_path):
    work, _ = example_map
    root = work / "map"
    before = {p: p.read_bytes() for p in root.rglob("*") if p.is_file()}
    info = subprocess.run([sys.executable, "-m", "slam_lcd", "map", "info", str(root), "--json"],
                          capture_output=True, text=True, timeout=300)
    assert info.returncode == 0, info.stderr
    s = json.loads(info.stdout)
    assert [x["name"] for x in s["sessions"]] == ["session1", "session5"]
    assert s["inter_session_accepted"] >= 3 and len(s["components"]) == 1
    for fmt, suffix in (("tum", ".tum"), ("kitti", ".txt")):
        out = tmp_path / fmt
        r = subprocess.run([sys.executable, "-m", "slam_lcd", "map", "export", str(root), "--to", fmt, str(out)],
                           capture_output=True, text=True, timeout=300)
        assert r.returncode == 0, r.stderr
        assert sorted(p.name for p in out.iterdir()) == [f"session1{suffix}", f"session5{suffix}"]
    mcap = tmp_path / "all.mcap"
    r = subprocess.run([sys.executable, "-m", "slam_lcd", "map", "export", str(root), "--to", "mcap", str(mcap)],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    from slam_lcd.io import open_log

    with open_log(mcap) as reader:
        assert set(reader.topics) == {"/map/session1/pose", "/map/session5/pose"}
    # an export into the map folder is refused (an output inside an input)
    r = subprocess.run([sys.executable, "-m", "slam_lcd", "map", "export", str(root), "--to", "tum",
                        str(root / "exported")], capture_output=True, text=True, timeout=300)
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert {p: p.read_bytes() for p in root.rglob("*") if p.is_file()} == before


def _noisy(T: np.ndarray, rng, sigma_t: float = 0.005, sigma_r: float = 0.0012) -> np.ndarray:
    return T @ make_T(so3_exp(rng.normal(0, sigma_r, 3)), rng.normal(0, sigma_t, 3))


def test_a_consistent_set_survives_the_gnc_recheck_when_visual_links_bend_the_sessions():
    """Each session's own estimate (odometry with its biases) is far from what its tight visual links say:
    the loops of the consistent set must still be inliers of the joint graph."""
    rng = np.random.default_rng(7)
    gt_a = _route(120, 3)
    gt_b = gt_a.copy()
    a, b = _session("a", gt_a, 0, 1), _session("b", gt_b, 1000, 2)
    for s in (a, b):  # strongly biased own estimates
        s.T_init = _drifting(gt_a, 11, scale=1.06)
    info_link = np.linalg.inv(np.diag([0.0012 ** 2] * 3 + [0.005 ** 2] * 3))
    links = [JointLoop(s0 + i, s0 + i - 1, _noisy(inv(gt[i - 1]) @ gt[i], rng), info_link, False, True, "link")
             for s0, gt in ((0, gt_a), (1000, gt_b)) for i in range(1, len(gt))]
    inter = [JointLoop(1000 + i, i, _noisy(inv(gt_a[i]) @ gt_b[i], rng), info_link, True) for i in range(2, 118, 3)]
    res = solve([a, b], links + inter)
    ok = [lp.accepted for lp in inter]
    assert sum(ok) >= 0.9 * len(inter), [lp.reason for lp in inter if not lp.accepted][:3]
    assert res.component["b"] == 0


def test_batch_appends_its_logs_to_one_map_in_name_order(example_map, tmp_path):
    work, _ = example_map
    logs = tmp_path / "logs"
    logs.mkdir()
    for name in ("session5", "session1"):  # discovery order must not matter
        (logs / f"{name}.mcap").symlink_to(work / f"{name}.mcap")
    r = subprocess.run([sys.executable, "-m", "slam_lcd", "batch", str(logs / "*.mcap"), "--out", str(tmp_path / "res"),
                        "--map", str(tmp_path / "map"), "--features", "orb", "--workers", "1", "--no-progress",
                        "--set", "run.plots=false", "--set", "run.loop_pictures=false"],
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-2000:]
    assert r.stdout.index("appended session1") < r.stdout.index("appended session5"), r.stdout
    from slam_lcd.map import Map
    from slam_lcd.map.summary import map_summary

    s = map_summary(Map.open(tmp_path / "map"))
    assert [x["name"] for x in s["sessions"]] == ["session1", "session5"]
    assert len(s["components"]) == 1 and s["inter_session_accepted"] >= 3, s["inter_session_loops"][:3]
    # the pair's verdict is recorded with its later session, and each session keeps its own estimate
    saved = Map.open(tmp_path / "map")
    (rec,) = saved.manifest.sessions[1]["pairs"]
    assert rec["sessions"] == ["session1", "session5"] and rec["decision"] == "joined" and rec["rule"]
    assert "pairs" not in saved.manifest.sessions[0]
    assert all(x.T_own is not None and x.T_own.shape == x.T_odom.shape for x in saved.sessions)
    assert (tmp_path / "res" / "map_sessions" / "session5" / "map" / "sessions.csv").is_file()
    # loops.csv of the second session: its candidates into session 1 carry the joint graph's verdicts
    import csv

    rows = list(csv.DictReader(open(tmp_path / "res" / "map_sessions" / "session5" / "loops.csv")))
    inter = [r for r in rows if r["match_session"]]
    assert inter and {r["match_session"] for r in inter} == {"session1"}
    accepted = [r for r in inter if r["backend_verdict"] == "accepted"]
    assert len(accepted) == s["inter_session_accepted"], (accepted[:2], s["inter_session_loops"][:2])
    assert all(r["backend_reason"] for r in inter if r["verdict"] == "accepted")
    assert all(r["match_stamp_ns"] and float(r["gt_distance_m"]) < 3.0 for r in accepted)
    # corrected.mcap: one TF tree with a frame per session, the log in the map frame, the loops between sessions
    from rosbags.highlevel import AnyReader

    from slam_lcd.io.trajectory_files import read_tum

    res = tmp_path / "res" / "map_sessions" / "session5"
    seen: dict = {}
    with AnyReader([res / "corrected.mcap"]) as reader:
        for conn, _, raw in reader.messages():
            seen.setdefault(conn.topic, []).append(reader.deserialize(raw, conn.msgtype))
    statics = {t.child_frame_id: t.header.frame_id for m in seen["/tf_static"] for t in m.transforms}
    assert statics["session_session1"] == statics["session_session5"] == "map", statics
    assert [len(m.poses) for m in seen["/slam_lcd/map/session1/path"]] == [s["sessions"][0]["keyframes"]]
    assert len(seen["/slam_lcd/map/loops"][0].markers[0].points) == 2 * s["inter_session_accepted"]
    full = read_tum(res / "map" / "session5_full_rate.tum")
    shown = np.array([[p.pose.position.x, p.pose.position.y, p.pose.position.z] for p in seen["/slam_lcd/corrected"]])
    np.testing.assert_allclose(shown, full.poses[:, :3, 3], atol=1e-6)


def test_int4_descriptors_keep_the_matches_of_the_full_rows():
    """The map's int4 form: half the bytes of int8, the rows restored to unit length, the same mutual matches."""
    from slam_lcd.features.matching import mutual_nn_match_symmetric
    from slam_lcd.map.session_map import compact_for_map
    from slam_lcd.map.store import SessionKeyframes

    rng = np.random.default_rng(3)
    a = rng.normal(size=(300, 256)).astype(np.float32)
    a /= np.linalg.norm(a, axis=1, keepdims=True)
    b = a + rng.normal(scale=0.03, size=a.shape).astype(np.float32)  # the same points seen again
    b /= np.linalg.norm(b, axis=1, keepdims=True)
    q, scales = compact_for_map(b, "int4")
    assert q.dtype == np.uint8 and q.shape == (300, 128) and scales.shape == (300,)
    s = SessionKeyframes(np.array([0]), np.array([0]), np.eye(4)[None], np.full((1, 6, 6), np.nan),
                         np.full((1, 4, 4), np.nan), np.array([0, 300]), np.zeros((300, 2), np.float32), q, scales,
                         np.zeros((300, 3), np.float32), np.array(["none"]))
    back = s.descriptors_of(0)
    np.testing.assert_allclose(np.linalg.norm(back, axis=1), 1.0, atol=1e-5)
    assert np.min(np.sum(back * b, axis=1)) > 0.97  # cosine to the full row
    full, _, _ = mutual_nn_match_symmetric(a, b, max_distance=0.8)
    small, _, _ = mutual_nn_match_symmetric(a, back, max_distance=0.8)
    assert len({tuple(m) for m in full} & {tuple(m) for m in small}) >= 0.98 * len(full)
    odd = np.ones((2, 3), np.float32)
    with pytest.raises(ValueError, match="even"):
        compact_for_map(odd, "int4")
