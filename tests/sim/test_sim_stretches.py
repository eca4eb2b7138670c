"""make-demo-log's bad stretches (--blur, --dark, --drop-frames, --freeze, --stamp-jump,
--odom-dropout, --odom-zero-covariance): each changes what it says and nothing else, in every
layout; bad values are one-line usage errors; a stretch past the log's end leaves the plain bytes."""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from slam_lcd.cli.main import main
from slam_lcd.io import open_log
from slam_lcd.io.decode import decode_image, decode_pose
from slam_lcd.sim import gt_loop_pairs, make_demo_log
from slam_lcd.sim.demo_log import session_scenario
from slam_lcd.sim.stretch_spec import Stretch, Stretches
from slam_lcd.sim.stretches import image_motion_angle, motion_blur, motion_kernel

SMALL = dict(frames=30, width=160, height=120, stereo=True, seed=1)
S = 1_000_000_000
JUMP_AT, JUMP = 2.5, 100.0
STRETCHES = Stretches(blur=(Stretch(0.5, 0.4, 30.0),), dark=(Stretch(1.0, 0.4),), drop_frames=(Stretch(1.5, 0.4),),
                      freeze=(Stretch(2.0, 0.4),), stamp_jump=(Stretch(JUMP_AT, JUMP),),
                      odom_dropout=(Stretch(0.3, 0.4),), odom_zero_covariance=True)
# frames at 0.0, 0.1 ... 2.9 s: blur 5-8, dark 10-13, dropped 15-18, frozen 20-23 (repeat 20), jump from 25
BLUR, DARK, DROP, FROZEN = range(5, 9), range(10, 14), range(15, 19), range(20, 24)


def _read(path: Path) -> dict[str, list]:
    """topic -> [(stamp, log_time, msg)] in log order."""
    out: dict[str, list] = {}
    with open_log(path) as r:
        for m in r.messages():
            out.setdefault(m.topic, []).append((m.stamp, m.log_time, m.msg))
    return out


@pytest.fixture(scope="module")
def logs(tmp_path_factory):
    root = tmp_path_factory.mktemp("stretches")
    plain = make_demo_log(root / "plain.mcap", **SMALL)
    bad = make_demo_log(root / "bad.mcap", stretches=STRETCHES, **SMALL)
    return plain, bad, _read(plain.path), _read(bad.path)


def _t0(msgs) -> int:
    return msgs["/camera/image_raw"][0][0]


def _world_stamp(stamp: int, t0: int) -> int:
    """A bad log's stamp on the world clock (the jump taken off)."""
    return stamp - int(JUMP * S) if stamp - t0 >= JUMP_AT * S + JUMP * S else stamp


def _by_world_stamp(msgs, topic, t0):
    return {_world_stamp(s, t0): m for s, _, m in msgs[topic]}


def _frame(plain_msgs, topic, k):
    return decode_image(plain_msgs[topic][k][2])


def test_frames_outside_every_stretch_are_the_plain_frames(logs):
    _, _, pm, bm = logs
    t0 = _t0(pm)
    bad = _by_world_stamp(bm, "/camera/image_raw", t0)
    for k in [*range(0, 5), 9, 14, 19, *range(24, 30)]:
        s = pm["/camera/image_raw"][k][0]
        assert np.array_equal(decode_image(bad[s]), _frame(pm, "/camera/image_raw", k)), k


def test_dark_frames_are_near_black_but_noisy_and_depth_is_unchanged(logs):
    _, _, pm, bm = logs
    t0 = _t0(pm)
    for topic in ("/camera/image_raw", "/camera/right/image_raw"):
        bad = _by_world_stamp(bm, topic, t0)
        for k in DARK:
            s = pm[topic][k][0]
            dark, clean = decode_image(bad[s]), _frame(pm, topic, k)
            assert dark.mean() < 0.1 * clean.mean() and dark.mean() < 8, (topic, k, dark.mean(), clean.mean())
            assert dark.std() > 0.3  # the sensor noise stays
    depth = _by_world_stamp(bm, "/camera/depth", t0)
    for k in DARK:
        assert np.array_equal(decode_image(depth[pm["/camera/depth"][k][0]]), _frame(pm, "/camera/depth", k))


def test_blurred_frames_lose_their_edges_and_depth_is_unchanged(logs):
    _, _, pm, bm = logs
    scenario = session_scenario(None, frames=30, width=160, height=120, seed=1)  # the poses, nothing rendered
    t0 = _t0(pm)
    bad = _by_world_stamp(bm, "/camera/image_raw", t0)
    depth = _by_world_stamp(bm, "/camera/depth", t0)
    for k in BLUR:
        s = pm["/camera/image_raw"][k][0]
        blurred, clean = decode_image(bad[s]).astype(np.float32), _frame(pm, "/camera/image_raw", k).astype(np.float32)
        smooth = [cv2.GaussianBlur(x, (3, 3), 0) for x in (blurred, clean)]  # the sensor noise's edges off
        sharp = [np.hypot(cv2.Sobel(x, cv2.CV_32F, 1, 0), cv2.Sobel(x, cv2.CV_32F, 0, 1)).mean() for x in smooth]
        assert sharp[0] < 0.75 * sharp[1], (k, sharp)
        # the clean frame smeared by a 30 * 160 / 640 = 7.5 px line along the image motion, plus sensor noise
        want = motion_blur(clean.astype(np.uint8), 7.5, image_motion_angle(scenario, k)).astype(np.float32)
        fit, off = np.abs(blurred - want).mean(), np.abs(blurred - clean).mean()
        assert fit < 2.0 and off > 2 * fit, (k, fit, off)
        assert abs(blurred.mean() - clean.mean()) < 3  # the same light, smeared
        assert np.array_equal(decode_image(depth[s]), _frame(pm, "/camera/depth", k))


def test_motion_kernel_is_a_line_along_its_angle():
    k = motion_kernel(7, 0)
    assert k.shape == (9, 9) and k.sum() == pytest.approx(1.0) and np.count_nonzero(k[4]) == 7 and not k[:4].any()
    v = motion_kernel(7, 90)
    assert np.allclose(v, k.T, atol=1e-6)
    d = motion_kernel(7, 45)
    assert d[6, 6] > 0.05 and d[2, 6] < 1e-3  # down-right (image y down), not up-right
    assert motion_kernel(7.5, 0).sum() == pytest.approx(1.0)


def test_dropped_frames_have_no_camera_messages_and_odometry_goes_on(logs):
    plain, bad, pm, bm = logs
    t0 = _t0(pm)
    lo, hi = t0 + 15 * S // 10, t0 + 19 * S // 10
    for topic in ("/camera/image_raw", "/camera/depth", "/camera/camera_info", "/camera/right/image_raw",
                  "/camera/right/camera_info"):
        assert len(bm[topic]) == 30 - len(DROP), topic
        assert not [s for s, _, _ in bm[topic] if lo <= s < hi], topic
    for topic in ("/ground_truth/pose", "/odom"):
        assert sum(lo <= s < hi for s, _, _ in bm[topic]) == 20, topic  # 50 Hz through the gap
    assert bad.frames == 30 - len(DROP) and plain.frames == 30


def test_frozen_frames_repeat_the_first_image_with_new_stamps(logs):
    _, _, pm, bm = logs
    t0 = _t0(pm)
    stamps = [pm["/camera/image_raw"][k][0] for k in FROZEN]
    for topic in ("/camera/image_raw", "/camera/depth", "/camera/right/image_raw"):
        bad = _by_world_stamp(bm, topic, t0)
        first = _frame(pm, topic, FROZEN[0])
        for s in stamps:
            assert np.array_equal(decode_image(bad[s]), first), topic
        assert not np.array_equal(_frame(pm, topic, FROZEN[-1]), first)  # the world did move
    got = [s for s, _, _ in bm["/camera/image_raw"] if stamps[0] <= s <= stamps[-1]]
    assert got == stamps and np.all(np.diff(got) > 0)


def test_stamp_jump_shifts_every_topic_and_the_motion_is_continuous(logs):
    _, _, pm, bm = logs
    t0, at = _t0(pm), _t0(pm) + int(JUMP_AT * S)
    for topic, plain_msgs in pm.items():
        if topic in ("/camera/image_raw", "/camera/depth", "/camera/camera_info", "/camera/right/image_raw",
                     "/camera/right/camera_info", "/odom"):
            continue  # frames dropped, odometry gaps: compared below by stamp
        want = [s + int(JUMP * S) if s >= at else s for s, _, _ in plain_msgs]
        assert [s for s, _, _ in bm[topic]] == want, topic
    for topic, msgs in bm.items():
        assert all(s == lt for s, lt, _ in msgs), topic  # header stamp = log time
        after = [s for s, _, _ in msgs if s >= at]
        assert not after or min(after) >= at + JUMP * S, topic  # nothing stamped inside the jump
    plain_img = {s for s, _, _ in pm["/camera/image_raw"] if s >= at}
    bad_img = {s - int(JUMP * S) for s, _, _ in bm["/camera/image_raw"] if s >= at}
    assert bad_img == plain_img and len(bad_img) == 5
    gt_plain = {s: decode_pose(m)[0] for s, _, m in pm["/ground_truth/pose"]}
    for s, _, m in bm["/ground_truth/pose"]:
        assert np.allclose(decode_pose(m)[0], gt_plain[_world_stamp(s, t0)])  # same poses, later stamps


def test_odometry_dropout_and_zero_covariances(logs):
    _, _, pm, bm = logs
    t0 = _t0(pm)
    lo, hi = t0 + 3 * S // 10, t0 + 7 * S // 10
    odo = {_world_stamp(s, t0): m for s, _, m in bm["/odom"]}
    assert not [s for s in odo if lo <= s < hi]
    assert len(odo) == len(pm["/odom"]) - 20
    for s, _, m in pm["/odom"]:  # the same drifting poses on either side of the gap: no reset
        if not lo <= s < hi:
            assert np.allclose(decode_pose(odo[s])[0], decode_pose(m)[0])
    for m in odo.values():
        assert not np.any(m.pose.covariance) and not np.any(m.twist.covariance)
    assert np.any(pm["/odom"][-1][2].pose.covariance)


def test_info_and_summary_name_the_stretches(logs):
    plain, bad, _, _ = logs
    assert bad.stretches == ["--blur 0.5:0.4:30", "--dark 1:0.4", "--drop-frames 1.5:0.4", "--freeze 2:0.4",
                             "--stamp-jump 2.5:100", "--odom-dropout 0.3:0.4", "--odom-zero-covariance"]
    assert "bad stretches: --blur 0.5:0.4:30" in bad.summary()
    assert plain.stretches == [] and "bad stretches" not in plain.summary()


def test_a_stretch_after_the_last_frame_leaves_the_plain_bytes(tmp_path, logs):
    plain = logs[0]
    late = Stretch(3.5, 1.0)
    after = Stretches(blur=(Stretch(3.5, 1.0, 15.0),), dark=(late,), drop_frames=(late,), freeze=(late,),
                      stamp_jump=(Stretch(3.5, 5.0),), odom_dropout=(late,), odom_zero_covariance=False)
    info = make_demo_log(tmp_path / "late.mcap", stretches=after, **SMALL)
    assert info.path.read_bytes() == plain.path.read_bytes()
    assert info.loop_pairs_path.read_bytes() == plain.loop_pairs_path.read_bytes()


def test_loop_pairs_leave_out_dropped_and_frozen_frames(tmp_path):
    """A log long enough to close a loop (2 Hz, 100 frames: one lap and more): the pairs file's
    indices are the log's image sequence, its stamps the log's, and no dropped or frozen frame is in it."""
    kw = dict(frames=100, width=64, height=48, camera_rate=2.0)
    world = session_scenario(None, **kw)  # the plain log's frames, nothing rendered
    p_pairs = gt_loop_pairs(world.gt_cam, T_body_camera=world.T_bc)
    st = Stretches(drop_frames=(Stretch(44.0, 2.0),), freeze=(Stretch(5.0, 3.0),), stamp_jump=(Stretch(30.0, 7.0),))
    bad = make_demo_log(tmp_path / "b.mcap", stretches=st, depth=False, **kw)
    assert len(p_pairs) > 20 and bad.frames == 96
    with open_log(bad.path) as r:
        stamps = [m.stamp for m in r.messages(topics=["/camera/image_raw"])]
    rows = [ln.split(",") for ln in bad.loop_pairs_path.read_text().splitlines()[1:]]
    assert rows
    t0, jump = stamps[0], 7 * S
    frozen = {t0 + k * S // 2 for k in range(11, 16)}  # 5.5-7.5 s: frames repeating 5.0 s
    for q, m, qs, ms, *_ in rows:
        assert stamps[int(q)] == int(qs) and stamps[int(m)] == int(ms)
        for s in (int(qs), int(ms)):
            w = s - jump if s - t0 >= 30 * S + jump else s
            assert w not in frozen and not (t0 + 44 * S <= w < t0 + 46 * S)
    # the plain pairs of frames kept, renumbered: all there
    assert world.cam_stamps[0] == t0 and np.all(np.diff(world.cam_stamps) == S // 2)
    clock = [t0 + k * S // 2 for k in range(100)]
    written = [k for k, s in enumerate(clock) if not (t0 + 44 * S <= s < t0 + 46 * S)]
    kept = [k for k in written if clock[k] not in frozen]
    want = {(written.index(q), written.index(m)) for q, m in p_pairs.tolist() if q in kept and m in kept}
    assert {(int(r[0]), int(r[1])) for r in rows} == want


@pytest.mark.parametrize("layout,fmt,name,image_topics", [
    ("tum", "mcap", "t.mcap", ["/camera/rgb/image_color", "/camera/depth_registered/image_raw"]),
    ("euroc", "rosbag1", "e.bag", ["/cam0/image_raw", "/cam1/image_raw"]),
    ("kitti", "rosbag2", "k_bag", ["/kitti/camera_gray_left/image_raw", "/kitti/camera_gray_right/image_raw"]),
])
def test_stretches_in_the_dataset_layouts(tmp_path, layout, fmt, name, image_topics):
    # frames at the layout's rate: 0.0, 0.05 ... (EuRoC 20 Hz), stretches in seconds
    st = Stretches(dark=(Stretch(0.2, 0.2),), drop_frames=(Stretch(0.5, 0.2),), stamp_jump=(Stretch(0.8, 10.0),))
    info = make_demo_log(tmp_path / name, fmt=fmt, frames=30, width=96, height=72, layout=layout, stretches=st)
    msgs = _read(info.path)
    t0 = msgs[image_topics[0]][0][0]
    for topic in image_topics:
        rel = [(s - t0) / S for s, _, _ in msgs[topic]]
        assert not [t for t in rel if 0.5 - 1e-9 <= t < 0.7 - 1e-9], topic
        assert all(t >= 10.8 - 1e-9 for t in rel if t > 0.8), topic
        if "depth" not in topic:
            dark = [decode_image(m).mean() for s, _, m in msgs[topic] if 0.2 - 1e-9 <= (s - t0) / S < 0.4 - 1e-9]
            clean = [decode_image(m).mean() for s, _, m in msgs[topic] if (s - t0) / S < 0.2 - 1e-9]
            assert dark and max(dark) < 0.1 * min(clean), topic
    later = [s for topic in msgs for s, _, _ in msgs[topic] if (s - t0) / S > 0.8]
    assert later and min(later) - t0 >= 10.8 * S - 1


def test_folder_format_drops_odometry_lines_and_lists_the_stretches(tmp_path):
    import yaml

    from slam_lcd.io.trajectory_files import read_tum

    st = Stretches(odom_dropout=(Stretch(0.2, 0.2),), freeze=(Stretch(0.3, 0.3),), stamp_jump=(Stretch(0.7, 3.0),))
    info = make_demo_log(tmp_path / "seq", fmt="folder", frames=10, width=64, height=48, stretches=st)
    od, gt = read_tum(info.path / "odometry.txt"), read_tum(info.path / "groundtruth.txt")
    assert len(gt) == 46 and len(od) == 36
    rel = np.diff(gt.stamps)
    assert rel.max() == 3 * S + S // 50 and (rel == S // 50).sum() == 44  # one jump of 3 s at 0.7 s
    assert np.diff(od.stamps).max() == 3 * S + S // 50 and od.stamps[0] == gt.stamps[0]
    meta = yaml.safe_load((info.path / "camera.yaml").read_text())
    assert meta["stretches"] == ["--freeze 0.3:0.3", "--stamp-jump 0.7:3", "--odom-dropout 0.2:0.2"]
    assert meta["frame_rate_hz"] == 10.0
    names = [ln.split()[1] for ln in (info.path / "image.txt").read_text().splitlines() if not ln.startswith("#")]
    imgs = [cv2.imread(str(info.path / n), cv2.IMREAD_UNCHANGED) for n in names[3:6]]
    assert np.array_equal(imgs[0], imgs[1]) and np.array_equal(imgs[0], imgs[2])


@pytest.mark.parametrize("argv, says", [
    (["--blur=-1:2"], "argument --blur: START must be"),
    (["--blur", "-1:2"], "argument --blur: expected one argument"),  # argparse: an option, unless --blur=-1:2
    (["--blur", "1:2:0"], "argument --blur: PX must be"),
    (["--blur", "1:2:3:4"], "argument --blur: expected START:SECONDS[:PX]"),
    (["--dark", "1:0"], "argument --dark: SECONDS must be"),
    (["--dark", "1:2:3"], "argument --dark: expected START:SECONDS"),
    (["--drop-frames", "x:1"], "argument --drop-frames: expected START:SECONDS"),
    (["--freeze", "nan:1"], "argument --freeze: START must be"),
    (["--stamp-jump", "1"], "argument --stamp-jump: expected AT:SECONDS"),
    (["--stamp-jump", "1:-5"], "argument --stamp-jump: SECONDS must be"),
    (["--odom-dropout", "1:inf"], "argument --odom-dropout: SECONDS must be"),
    (["--layout", "tum", "--odom-dropout", "1:1"], "--odom-dropout: layout tum writes no odometry"),
    (["--layout", "kitti", "--odom-zero-covariance"], "--odom-zero-covariance: layout kitti writes no odometry"),
    (["--format", "folder", "--odom-zero-covariance"], "--odom-zero-covariance: the folder format"),
    (["--drop-frames", "0:1", "--drop-frames", "0.3:5"], "--drop-frames drops all 5 camera frames"),
])
def test_bad_values_are_one_line_errors(tmp_path, capsys, argv, says):
    out = tmp_path / ("d" if "folder" in argv else "d.mcap")
    assert main(["make-demo-log", str(out), "--frames", "5", "--size", "64x48", *argv]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and says in err, err
    assert not out.exists()


def test_cli_repeats_and_records_the_stretches(tmp_path, capsys):
    out = tmp_path / "c.mcap"
    assert main(["make-demo-log", str(out), "--frames", "12", "--size", "64x48", "--no-depth", "--dark", "0.2:0.1",
                 "--dark", "0.6:0.2", "--blur", "0.4:0.1", "--odom-zero-covariance", "--no-progress"]) == 0
    text = capsys.readouterr().out
    assert "bad stretches: --blur 0.4:0.1:15, --dark 0.2:0.1, --dark 0.6:0.2, --odom-zero-covariance" in text
    means = [decode_image(m).mean() for _, _, m in _read(out)["/camera/image_raw"]]
    dark = [k for k, v in enumerate(means) if v < 0.1 * max(means)]
    assert dark == [2, 6, 7]
