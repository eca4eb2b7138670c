"""`slam-lcd run` on logs laid out like the bags users have: a calibration file instead of (or over)
CameraInfo, ground truth of every message type (and as a TF chain), no odometry.

One tiny demo log (30 frames, 320x240: the VO tracks from that size on, RGB-D + stereo) and variants of it copied
with topics dropped or ground truth rewritten; ORB features keep each run at a few seconds.
"""
from __future__ import annotations

import logging

import numpy as np
import pytest

from slam_lcd.config import load_config
from slam_lcd.io import open_log
from slam_lcd.io.writers import copy_topics, open_writer
from slam_lcd.run import OutputOptions, Sources, run_log

QUIET = OutputOptions(progress=False, write_mcap=False)  # no progress bar, no corrected.mcap


@pytest.fixture(scope="module")
def tiny_log(tmp_path_factory):
    from slam_lcd.sim import make_demo_log

    p = tmp_path_factory.mktemp("tiny") / "tiny.mcap"
    make_demo_log(p, "mcap", frames=30, seed=0, depth=True, stereo=True, width=320, height=240, workers=0)
    return p


def _orb_config(*extra):
    return load_config("default", ["features.kind=orb", "features.feature_cache=false", "run.plots=false", *extra])


def _variant(src, dst, drop=(), write=None):
    """A copy of ``src`` without the topics ``drop``; ``write(reader, writer)`` adds messages."""
    with open_log(src) as r, open_writer(dst, "mcap") as w:
        copy_topics(r, w, [t for t in r.topics if t not in drop])
        if write is not None:
            write(r, w)
    return dst


def _log_camera_and_mounting(log):
    from slam_lcd.io.tf import TfBuffer
    from slam_lcd.sensors.messages import camera_from_camera_info

    with open_log(log) as r:
        m = next(iter(r.messages(["/camera/camera_info"])))
        cam = camera_from_camera_info(m.msg)
        tf = TfBuffer.from_log(r, tf_topics=())
        T_bc = tf.lookup("base_link", m.msg.header.frame_id, 0)
    return cam, T_bc


def euroc_sensor_yaml(path, cam, T_body_camera, cx_shift=0.0):
    """An EuRoC cam0/sensor.yaml of the demo camera (``cx_shift``: tell it apart from the CameraInfo)."""
    data = ", ".join(f"{v:.15g}" for v in np.asarray(T_body_camera).reshape(-1))
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(f"""# General sensor definitions.
sensor_type: camera
comment: demo camera
T_BS:
  cols: 4
  rows: 4
  data: [{data}]
rate_hz: 10
resolution: [{cam.width}, {cam.height}]
camera_model: pinhole
intrinsics: [{cam.fx}, {cam.fy}, {cam.cx + cx_shift}, {cam.cy}]
distortion_model: radial-tangential
distortion_coefficients: [0.0, 0.0, 0.0, 0.0]
""")
    return path


@pytest.fixture
def camera_spy(monkeypatch):
    from slam_lcd.run.pipeline import Pipeline

    seen = []
    real = Pipeline.set_camera

    def spy(self, camera, T_body_camera=None):
        seen.append((camera, None if T_body_camera is None else np.array(T_body_camera)))
        return real(self, camera, T_body_camera)

    monkeypatch.setattr(Pipeline, "set_camera", spy)
    return seen


def test_calib_wins_over_camera_info(tiny_log, tmp_path, camera_spy, caplog):
    cam, T_bc = _log_camera_and_mounting(tiny_log)
    calib = euroc_sensor_yaml(tmp_path / "cam0" / "sensor.yaml", cam, T_bc, cx_shift=0.5)
    with caplog.at_level(logging.WARNING, logger="slam_lcd"):
        res = run_log(tiny_log, tmp_path / "out", _orb_config(), sources=Sources(calib=[calib]), output=QUIET)
    assert res.n_keyframes > 0
    assert len(camera_spy) == 1  # the calibration's camera only: the CameraInfo is not read
    used, T_used = camera_spy[0]
    assert used.cx == pytest.approx(cam.cx + 0.5) and used.fx == pytest.approx(cam.fx)
    assert np.allclose(T_used, T_bc, atol=1e-9)
    assert any("--calib wins" in r.getMessage() and "/camera/camera_info" in r.getMessage() for r in caplog.records)


def test_calib_gives_the_camera_of_a_log_without_camera_info(tiny_log, tmp_path, camera_spy):
    """No odometry, no CameraInfo (an EuRoC-like log with depth): the RGB-D VO runs on the calibrated camera."""
    cam, T_bc = _log_camera_and_mounting(tiny_log)
    log = _variant(tiny_log, tmp_path / "bare.mcap",
                   drop=("/odom", "/camera/camera_info", "/camera/right/camera_info", "/tf_static"))
    calib = euroc_sensor_yaml(tmp_path / "cam0" / "sensor.yaml", cam, T_bc)
    res = run_log(log, tmp_path / "out", _orb_config(), sources=Sources(gt_topic="/ground_truth/pose", calib=[calib]),
                  output=QUIET)
    used, T_used = camera_spy[0]
    assert used.fx == pytest.approx(cam.fx) and np.allclose(T_used, T_bc, atol=1e-9)
    # the VO is metric and mounted right: ATE of a few cm over the 2 m of this log
    assert res.ate_before is not None and res.ate_before < 0.05, res.ate_before


# ---------------------------------------------------------------------------- ground truth
def _gt_of(log):
    from slam_lcd.io import read_trajectory_from_log

    return read_trajectory_from_log(log, "/ground_truth/pose")


T_WORLD_MOCAP = np.array([[0.0, -1.0, 0.0, 2.0], [1.0, 0.0, 0.0, -1.0], [0.0, 0.0, 1.0, 0.5], [0, 0, 0, 1.0]])


def _writer_of(kind, gt):
    """``write(reader, writer)`` putting the ground truth ``gt`` as message type ``kind``."""
    from slam_lcd.geometry import inv
    from slam_lcd.io import message_builders as M

    def write(_r, w):
        if kind == "tf":
            w.write("/tf_static", M.tf_message([(T_WORLD_MOCAP, int(gt.stamps[0]), "world", "mocap")]),
                    int(gt.stamps[0]))
        for s, T in zip(gt.stamps.tolist(), gt.poses, strict=True):
            if kind == "PoseWithCovarianceStamped":
                msg, topic = M.pose_with_covariance_stamped_msg(T, np.eye(6) * 1e-4, s, "world"), "/gt"
            elif kind == "Odometry":
                msg, topic = M.odometry_msg(T, np.eye(6) * 1e-4, s, "world", "gt_body"), "/gt"
            elif kind == "TransformStamped":
                msg, topic = M.transform_stamped_msg(T, s, "world", "gt_body"), "/vicon/body/body"
            elif kind == "PointStamped":
                msg, topic = M.point_stamped_msg(T[:3, 3], s, "world"), "/leica/position"
            else:  # tf: world -> mocap (static) -> gt_body (dynamic, on /tf)
                msg, topic = M.tf_message([(inv(T_WORLD_MOCAP) @ T, s, "mocap", "gt_body")]), "/tf"
            w.write(topic, msg, s)
    return write


GT_KINDS = {"PoseWithCovarianceStamped": "/gt", "Odometry": "/gt", "TransformStamped": "/vicon/body/body",
            "PointStamped": "/leica/position", "tf": "/tf:world:gt_body"}


@pytest.fixture(scope="module")
def baseline_run(tiny_log, tmp_path_factory):
    out = tmp_path_factory.mktemp("baseline") / "out"
    return run_log(tiny_log, out, _orb_config(), sources=Sources(gt_topic="/ground_truth/pose"), output=QUIET)


@pytest.mark.parametrize("kind", sorted(GT_KINDS))
def test_ground_truth_of_every_message_type(kind, tiny_log, baseline_run, tmp_path):
    import json

    assert baseline_run.ate_before is not None
    log = _variant(tiny_log, tmp_path / f"{kind}.mcap", drop=("/ground_truth/pose",),
                   write=_writer_of(kind, _gt_of(tiny_log)))
    res = run_log(log, tmp_path / "out", _orb_config(), sources=Sources(gt_topic=GT_KINDS[kind]), output=QUIET)
    # the same positions over the same stamps: the same ATE (translation; the alignment takes the world offset)
    assert res.ate_before == pytest.approx(baseline_run.ate_before, rel=1e-6, abs=1e-9)
    assert res.ate_after == pytest.approx(baseline_run.ate_after, rel=1e-6, abs=1e-9)
    rep = json.loads((tmp_path / "out" / "report.json").read_text())
    assert rep["eval"]["gt_position_only"] == (kind == "PointStamped")


@pytest.mark.parametrize("spec, expected", [("/tf", "name the frames as /tf:PARENT:CHILD"),
                                             ("/tf:world:nowhere", "'nowhere' is not in the TF tree"),
                                             ("/camera/image_raw", "not a pose or a position")])
def test_bad_ground_truth_topic_is_one_line(spec, expected, tiny_log, tmp_path, capsys):
    from slam_lcd.cli.main import main

    log = _variant(tiny_log, tmp_path / "tf.mcap", write=_writer_of("tf", _gt_of(tiny_log)))
    rc = main(["run", str(log), "--out", str(tmp_path / "out"), "--gt-topic", spec, "--features", "orb",
               "--no-progress"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and "tf.mcap" in err[0] and expected in err[0], err


def test_tf_chain_ground_truth_goes_through_static_transforms(tiny_log, tmp_path):
    from slam_lcd.sensors.ground_truth import ground_truth_from_tf
    from slam_lcd.sensors.topics import static_tf_topics

    gt = _gt_of(tiny_log)
    log = _variant(tiny_log, tmp_path / "tf.mcap", drop=("/ground_truth/pose",), write=_writer_of("tf", gt))
    with open_log(log) as r:
        got = ground_truth_from_tf(r, "/tf", "world", "gt_body", static_tf_topics(r))
    assert np.array_equal(got.stamps, gt.stamps)
    assert np.allclose(got.poses, gt.poses, atol=1e-9)  # world -> mocap (static) -> gt_body composed


# ---------------------------------------------------------------------------- no odometry
def test_stereo_log_without_odometry_or_depth_uses_stereo_vo(tiny_log, tmp_path, caplog):
    log = _variant(tiny_log, tmp_path / "stereo.mcap", drop=("/odom", "/camera/depth"))
    with caplog.at_level(logging.WARNING, logger="slam_lcd"):
        res = run_log(log, tmp_path / "out", _orb_config(), sources=Sources(gt_topic="/ground_truth/pose"),
                      output=QUIET)
    assert any("stereo visual odometry on /camera/image_raw + /camera/right/image_raw" in r.getMessage()
               for r in caplog.records)
    assert res.n_keyframes > 0
    # metric stereo VO on the rendered pair: a few cm over the 2 m of this log
    assert res.ate_before is not None and res.ate_before < 0.05, res.ate_before


def test_monocular_log_without_odometry_says_what_is_missing(tiny_log, tmp_path, capsys):
    from slam_lcd.cli.main import main

    log = _variant(tiny_log, tmp_path / "mono.mcap",
                   drop=("/odom", "/camera/depth", "/camera/right/image_raw", "/camera/right/camera_info"))
    rc = main(["run", str(log), "--out", str(tmp_path / "out"), "--features", "orb", "--no-progress"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1, err
    for needed in ("mono.mcap", "no odometry", "/camera/image_raw", "--odom-topic", "--depth-topic", "--right-topic"):
        assert needed in err[0], (needed, err[0])
    assert not (tmp_path / "out").exists()


def _rot(axis, deg):
    import cv2

    return cv2.Rodrigues(np.radians(deg) * np.eye(3)[axis])[0]


def _raw_stereo(tiny_log, tmp_path):
    """The demo pair made raw (as EuRoC's cameras): each camera turned away from the rectified frame
    (2 deg about y, 1.5 deg about x) and given radtan distortion; a Kalibr camchain.yaml that says so."""
    import cv2

    from slam_lcd.geometry import inv, make_T
    from slam_lcd.io import message_builders as M
    from slam_lcd.sensors.messages import decode_gray

    cam, T_b_rect0 = _log_camera_and_mounting(tiny_log)
    with open_log(tiny_log) as r:
        baseline = next(iter(r.messages(["/camera/right/camera_info"]))).msg.p[3] / -cam.fx
    T_b_rect1 = T_b_rect0 @ make_T(np.eye(3), [baseline, 0, 0])
    rigs = {"/camera/image_raw": (_rot(1, 2.0), np.array([-0.05, 0.01, 0.001, -0.0005])),
            "/camera/right/image_raw": (_rot(0, -1.5), np.array([-0.04, 0.008, 0.0, 0.0003]))}
    T_b_raw = {"/camera/image_raw": T_b_rect0 @ make_T(rigs["/camera/image_raw"][0], np.zeros(3)),
               "/camera/right/image_raw": T_b_rect1 @ make_T(rigs["/camera/right/image_raw"][0], np.zeros(3))}
    u, v = np.meshgrid(np.arange(cam.width, dtype=np.float64), np.arange(cam.height, dtype=np.float64))
    grid = np.stack([u.ravel(), v.ravel()], 1).reshape(-1, 1, 2)
    maps = {}
    for topic, (R, D) in rigs.items():  # raw pixel -> rectified pixel: X_rect = R X_raw
        m = cv2.undistortPoints(grid, cam.K, D, R=R, P=cam.K).reshape(cam.height, cam.width, 2).astype(np.float32)
        maps[topic] = (m[..., 0], m[..., 1])

    def write(r, w):
        for msg in r.messages(list(rigs)):
            raw = cv2.remap(np.ascontiguousarray(decode_gray(msg)), *maps[msg.topic], cv2.INTER_LINEAR)
            w.write(msg.topic, M.image_msg(raw, msg.stamp, msg.msg.header.frame_id), msg.stamp)

    log = _variant(tiny_log, tmp_path / "raw.mcap", write=write,
                   drop=("/odom", "/camera/depth", "/camera/camera_info", "/camera/right/camera_info", *rigs))

    def block(T):
        return "\n".join("  - [" + ", ".join(f"{x:.12f}" for x in row) + "]" for row in T)

    cams = []
    for k, (topic, (_R, D)) in enumerate(rigs.items()):
        cams.append(f"""cam{k}:
  T_cam_imu:
{block(inv(T_b_raw[topic]))}
""" + (f"""  T_cn_cnm1:
{block(inv(T_b_raw[topic]) @ T_b_raw["/camera/image_raw"])}
""" if k else "") + f"""  camera_model: pinhole
  distortion_coeffs: [{", ".join(map(str, D))}]
  distortion_model: radtan
  intrinsics: [{cam.fx}, {cam.fy}, {cam.cx}, {cam.cy}]
  resolution: [{cam.width}, {cam.height}]
  rostopic: {topic}
""")
    calib = tmp_path / "camchain.yaml"
    calib.write_text("".join(cams))
    return log, calib, T_b_raw["/camera/image_raw"]


def test_raw_calibrated_stereo_pair_is_rectified_for_the_vo(tiny_log, tmp_path, camera_spy, caplog):
    log, calib, T_b_raw0 = _raw_stereo(tiny_log, tmp_path)
    with caplog.at_level(logging.WARNING, logger="slam_lcd"):
        res = run_log(log, tmp_path / "out", _orb_config(),
                      sources=Sources(gt_topic="/ground_truth/pose", calib=[calib]), output=QUIET)
    assert any("not a rectified pair: the stereo VO rectifies them" in r.getMessage() for r in caplog.records)
    # the main pass sees the pair rectified (its loop poses take stereo points): the rectified cam0, mounted
    # as the file says turned by the rectification
    from slam_lcd.sensors.calibration import load_calibration
    from slam_lcd.sensors.rectify import stereo_rectifier

    c = load_calibration([calib])
    c0 = c.camera_for("/camera/image_raw")
    c1, T_c1_c0 = c.stereo_partner(c0)
    rect = stereo_rectifier(c0.camera, c1.camera, T_c1_c0)
    used, T_used = camera_spy[0]
    assert used.distortion_model == "none" and used.baseline and abs(used.fx - rect.camera.fx) < 1e-9
    assert np.allclose(T_used, T_b_raw0 @ rect.T_cam0_rect, atol=1e-6)
    assert res.ate_before is not None and res.ate_before < 0.05, res.ate_before


def test_raw_pair_without_rectification_tracks_worse(tiny_log, tmp_path):
    """The same raw pair given as if rectified (CameraInfo-style): the check that rectification matters."""
    from slam_lcd.eval.metrics import ate
    from slam_lcd.sensors.calibration import load_calibration
    from slam_lcd.sensors.log_vo import visual_odometry_from_log
    from slam_lcd.sensors.rectify import stereo_rectifier

    log, calib_path, T_b_raw0 = _raw_stereo(tiny_log, tmp_path)
    calib = load_calibration(calib_path)
    c0, (c1, T_c1_c0) = calib.cameras[0], calib.stereo_partner(calib.cameras[0])
    gt = _gt_of(tiny_log)
    kw = dict(image_topic="/camera/image_raw", right_topic="/camera/right/image_raw", camera=c0.camera,
              T_body_camera=T_b_raw0)
    good = visual_odometry_from_log(log, rectifier=stereo_rectifier(c0.camera, c1.camera, T_c1_c0), **kw)
    bad = visual_odometry_from_log(log, **kw)
    err_good = ate(gt, good.result.trajectory(), "se3").rmse
    assert err_good < 0.05, err_good
    unrectified = bad.result.trajectory()  # rows do not match: tracking fails, or drifts far more
    assert len(unrectified) < len(good.result.trajectory()) / 2 or ate(gt, unrectified, "se3").rmse > 2 * err_good


def test_stereo_log_with_odometry_gives_the_loop_detector_the_pair(tiny_log, tmp_path, monkeypatch):
    """Odometry, a rectified CameraInfo pair, no depth: each keyframe's pair reaches loop detection
    (SGBM once per keyframe) and the camera carries the right CameraInfo's baseline."""
    import slam_lcd.lcd.geometry as lcd_geometry

    log = _variant(tiny_log, tmp_path / "stereo_odom.mcap", drop=("/camera/depth",))
    calls = []
    real = lcd_geometry.dense_disparity
    monkeypatch.setattr(lcd_geometry, "dense_disparity",
                        lambda left, right: calls.append(right.shape) or real(left, right))
    res = run_log(log, tmp_path / "out", _orb_config(), output=QUIET)
    assert res.topics["odom"] == "/odom" and res.topics["right"] == "/camera/right/image_raw"
    assert len(calls) == res.n_keyframes >= 2
