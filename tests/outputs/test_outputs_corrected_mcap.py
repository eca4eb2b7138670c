"""corrected.mcap ready for Foxglove, read back with rosbags: one TF tree joins the
corrected body frame, the odometry frame and the ground-truth frame; the Path grows once per
keyframe; one loop marker per accepted loop. Both ways of adding the correction are checked:
``map -> odom`` (REP 105) when the log leaves the odometry frame without a parent, and a
``<body>_corrected`` child of it when the log already gives it one (the demo's world -> odom)."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from slam_lcd.outputs.corrected_log import LOOPS_TOPIC, PATH_TOPIC, plan_frames, write_corrected_log


def _read(path: Path) -> dict:
    """{topic: [(log_time, msg)]} of every message, decoded by rosbags."""
    from rosbags.highlevel import AnyReader

    out: dict = {}
    with AnyReader([path]) as r:
        for conn, t, raw in r.messages():
            out.setdefault(conn.topic, []).append((t, r.deserialize(raw, conn.msgtype)))
    return out


def _tree(msgs: dict) -> dict[str, str]:
    """{child: parent} of /tf and /tf_static; a frame with two parents fails the test."""
    parents: dict[str, str] = {}
    for topic in ("/tf", "/tf_static"):
        for _, m in msgs.get(topic, []):
            for ts in m.transforms:
                old = parents.setdefault(ts.child_frame_id, ts.header.frame_id)
                assert old == ts.header.frame_id, f"{ts.child_frame_id} has parents {old} and {ts.header.frame_id}"
    return parents


def _root(frame, parents):
    while frame in parents:
        frame = parents[frame]
    return frame


def _check_path_and_markers(msgs, n_keyframes, n_accepted):
    paths = msgs[PATH_TOPIC]
    assert len(paths) > 1 and len(paths) == min(n_keyframes, 200)
    lengths = [len(m.poses) for _, m in paths]
    assert lengths == sorted(lengths) and lengths[0] == 1 and lengths[-1] == n_keyframes
    markers = [mk for _, arr in msgs.get(LOOPS_TOPIC, []) for mk in arr.markers]
    assert len(markers) == n_accepted
    assert len({mk.id for mk in markers}) == n_accepted and all(len(mk.points) == 2 for mk in markers)


def test_corrected_mcap_one_tf_tree_growing_path_loop_markers(report_run):
    rc, out, _ = report_run
    rep = json.loads((out / "report.json").read_text())
    msgs = _read(out / "corrected.mcap")
    parents = _tree(msgs)
    odom = msgs["/odom"][0][1]
    gt_frame = msgs["/ground_truth/pose"][0][1].header.frame_id
    body, odom_frame = odom.child_frame_id, odom.header.frame_id
    corrected_body = f"{body}_corrected"  # the demo log gives odom a parent (static world -> odom)
    assert parents[odom_frame] == "world" and parents[corrected_body] == odom_frame and parents[body] == odom_frame
    assert _root(corrected_body, parents) == _root(odom_frame, parents) == _root(gt_frame, parents)
    assert msgs["/slam_lcd/corrected"][0][1].header.frame_id == odom_frame
    _check_path_and_markers(msgs, rep["keyframes"], rep["loops"]["accepted"])


def test_map_to_odom_correction_when_odom_has_no_parent(report_run, tmp_path):
    """The same run written without the log's /tf_static: SLAM-node style map -> odom on /tf,
    the ground-truth frame tied to map by the ATE alignment, images copied on request."""
    from slam_lcd.config import load_config
    from slam_lcd.eval import ate
    from slam_lcd.io.trajectory_files import read_tum

    _, out, log = report_run
    rep = json.loads((out / "report.json").read_text())
    odom, corr, kf = (read_tum(out / n) for n in ("odometry.tum", "corrected.tum", "keyframes_corrected.tum"))
    gt_msgs = _read(log)["/ground_truth/pose"]
    from slam_lcd.types import Trajectory

    gt = Trajectory(np.array([t for t, _ in gt_msgs], np.int64),
                    np.array([_pose(m.pose) for _, m in gt_msgs]))
    align = ate(gt, corr, "se3", t_max_diff=0.02).alignment
    loops = [(lp["query_id"], lp["match_id"], lp["query_stamp_ns"]) for lp in rep["accepted_loops"]]
    cfg = load_config("default")
    frames = {"odom": "odom", "body": "base_link", "gt": "world"}
    plan = write_corrected_log(tmp_path / "c.mcap", odom=odom, corrected=corr, kf_ids=list(range(len(kf))),
                               kf_corrected=kf, loops=loops, log_frame_ids=frames, run_conf=cfg.run, copy_from=log,
                               copy_topics=["/odom", "/ground_truth/pose", "/camera/image_raw"],
                               gt_alignment=align)
    assert plan.publish_map_odom and plan.link_gt
    msgs = _read(tmp_path / "c.mcap")
    parents = _tree(msgs)
    assert parents["odom"] == "map" and parents["base_link"] == "odom" and parents["map"] == "world"
    assert _root("base_link", parents) == _root("world", parents) == "world"
    assert len(msgs["/camera/image_raw"]) == len(_read(log)["/camera/image_raw"])
    _check_path_and_markers(msgs, len(kf), len(loops))
    # map -> odom -> base_link reproduces the corrected pose at every corrected stamp
    tf = {t: m.transforms[0] for t, m in msgs["/tf"] if m.transforms[0].child_frame_id == "odom"}
    i = len(corr) // 2
    T_map_odom = _transform(tf[int(corr.stamps[i])].transform)
    assert np.allclose(T_map_odom @ odom.poses[i], corr.poses[i], atol=1e-6)


def test_ground_truth_file_tied_under_an_odom_that_has_a_parent(report_run, tmp_path):
    """--gt FILE: the ground truth is written into the MCAP (frame ground_truth) and, as the
    demo's odom has a parent (world), tied to the tree as a child of odom."""
    from slam_lcd.config import load_config
    from slam_lcd.eval import ate
    from slam_lcd.io.trajectory_files import read_tum
    from slam_lcd.outputs.corrected_log import GT_FILE_FRAME, GT_TOPIC
    from slam_lcd.types import Trajectory

    _, out, log = report_run
    odom, corr, kf = (read_tum(out / n) for n in ("odometry.tum", "corrected.tum", "keyframes_corrected.tum"))
    gt_msgs = _read(log)["/ground_truth/pose"]
    gt = Trajectory(np.array([t for t, _ in gt_msgs], np.int64), np.array([_pose(m.pose) for _, m in gt_msgs]))
    align = ate(gt, corr, "se3", t_max_diff=0.02).alignment
    plan = write_corrected_log(tmp_path / "c.mcap", odom=odom, corrected=corr, kf_ids=list(range(len(kf))),
                               kf_corrected=kf, loops=[], log_frame_ids={"odom": "odom", "body": "base_link",
                                                                     "gt": GT_FILE_FRAME},
                               run_conf=load_config("default").run, copy_from=log,
                               copy_topics=["/tf_static", "/odom"], gt_alignment=align, gt_poses=gt)
    assert not plan.publish_map_odom and plan.link_gt
    msgs = _read(tmp_path / "c.mcap")
    parents = _tree(msgs)
    assert parents[GT_FILE_FRAME] == "odom" and _root(GT_FILE_FRAME, parents) == _root("base_link_corrected", parents)
    assert len(msgs[GT_TOPIC]) == len(gt) and msgs[GT_TOPIC][0][1].header.frame_id == GT_FILE_FRAME
    # the ground truth seen from odom lands on the corrected trajectory (within the corrected ATE)
    static = [ts for _, m in msgs["/tf_static"] for ts in m.transforms if ts.child_frame_id == GT_FILE_FRAME][0]
    T_odom_gt = _transform(static.transform)
    p = (T_odom_gt @ gt.poses[len(gt) // 2])[:3, 3]
    assert np.min(np.linalg.norm(corr.positions - p, axis=1)) < 0.5


def test_frame_plan_names_a_clash_and_takes_overrides():
    from slam_lcd.config import load_config

    cfg = load_config("default", ["run.mcap_body_frame=camera_link"])
    plan = plan_frames(cfg.run, {"odom": "odom", "body": "base_link"}, {"base_link": "map"})
    assert plan.map_frame == "map_slam_lcd" and plan.body_frame == "camera_link" and plan.publish_map_odom
    assert any("already a frame" in n for n in plan.notes)


def _tq(t, q):
    from slam_lcd.geometry import quat_to_rot

    T = np.eye(4)
    T[:3, :3], T[:3, 3] = quat_to_rot(np.array([q.x, q.y, q.z, q.w])), [t.x, t.y, t.z]
    return T


def _pose(p):
    return _tq(p.position, p.orientation)


def _transform(t):
    return _tq(t.translation, t.rotation)
