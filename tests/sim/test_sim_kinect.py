"""The Kinect v1 depth-error model of the TUM layout (``slam_lcd.sim.kinect``) and its exact-depth option.

The model's statistics are checked against the published formulas it is made of (axial
sigma of Nguyen et al. 2012, the 1/8-pixel disparity step of Khoshelham & Elberink 2012,
the working range), and the TUM layout's depth images against the model, frame by frame.
"""
from __future__ import annotations

import numpy as np
import pytest

from slam_lcd.io import open_log
from slam_lcd.io.decode import decode_image
from slam_lcd.sim import make_demo_log
from slam_lcd.sim.kinect import KINECT_V1, KinectDepthModel, depth_mm

DEPTH_TOPIC = "/camera/depth_registered/image_raw"


def test_published_constants():
    assert KINECT_V1 == KinectDepthModel(0.0012, 0.0019, 0.4, 2.85e-3, 0.5, 4.5)
    assert KINECT_V1.sigma_z(0.4) == pytest.approx(0.0012)
    assert KINECT_V1.sigma_z(3.0) == pytest.approx(0.0012 + 0.0019 * 2.6**2)


@pytest.mark.parametrize("z", [0.8, 1.5, 2.5, 4.0])
def test_noise_and_disparity_steps(z):
    rng = np.random.default_rng(7)
    m = KINECT_V1.measure(np.full(100_000, z), rng)
    assert (m > 0).all()
    step = KINECT_V1.inverse_depth_step_per_m
    k = 1.0 / (m * step)  # every reading is on the disparity grid
    assert np.abs(k - np.round(k)).max() < 1e-6
    # a Gaussian of the published sigma, then the quantiser (uniform error of one step in 1/z)
    expect = np.hypot(KINECT_V1.sigma_z(z), step * z**2 / np.sqrt(12))
    assert np.std(m - z) == pytest.approx(expect, rel=0.15)
    assert abs(np.mean(m - z)) < 0.1 * expect + 1e-4
    assert len(np.unique(m)) > 3  # noise wider than a step: no constant reading


def test_out_of_range_and_missing_is_zero():
    z = np.array([0.2, 0.45, 4.8, 9.0, np.nan, np.inf, 0.0, 2.0])
    m = KINECT_V1.measure(z, np.random.default_rng(0))
    assert (m[:7] == 0).all() and m[7] > 0
    assert depth_mm(np.array([np.nan, 1.2344, 0.0])).tolist() == [0, 1234, 0]


def _depths(path):
    with open_log(path) as r:
        return [decode_image(m.msg) for m in r.messages() if m.topic == DEPTH_TOPIC]


@pytest.fixture(scope="module")
def tum_logs(tmp_path_factory):
    root = tmp_path_factory.mktemp("tum_depth")
    kw = dict(frames=6, width=160, height=120, layout="tum", workers=0)
    return {name: make_demo_log(root / f"{name}.mcap", "mcap", depth_noise=name != "exact", **kw)
            for name in ("noisy", "noisy_again", "exact")}


def test_tum_layout_depth_is_the_kinect_model(tum_logs):
    noisy, again, exact = (_depths(tum_logs[k].path) for k in ("noisy", "noisy_again", "exact"))
    assert tum_logs["noisy"].depth_model == KINECT_V1 and tum_logs["exact"].depth_model is None
    assert "Kinect v1" in tum_logs["noisy"].summary()
    assert len(noisy) == len(exact) == 6
    assert all(a.dtype == np.uint16 and np.array_equal(a, b) for a, b in zip(noisy, again, strict=True))  # seeded
    assert not np.array_equal(noisy[0], noisy[1])  # the noise differs from frame to frame
    zt = np.concatenate([e.ravel() for e in exact]).astype(np.float64) / 1000.0
    zn = np.concatenate([n.ravel() for n in noisy]).astype(np.float64) / 1000.0
    far, near = zt > 5.0, (zt > 0.6) & (zt < 4.3)
    assert far.any() and near.sum() > 1000
    assert (zn[far] == 0).all() and (zn[near] > 0).mean() > 0.99
    err = (zn - zt)[near]
    assert np.std(err / KINECT_V1.sigma_z(zt[near])) == pytest.approx(1.0, abs=0.35)
    assert np.mean(np.abs(err) > 0.0005) > 0.5  # exact depth: only millimetre rounding


def test_exact_depth_flag(tmp_path, capsys):
    from slam_lcd.cli.main import main

    out = tmp_path / "tum.mcap"
    assert main(["make-demo-log", str(out), "--layout", "tum", "--frames", "3", "--size", "160x120",
                 "--exact-depth", "--no-progress"]) == 0
    assert "Kinect" not in capsys.readouterr().out
    from slam_lcd.sim.demo_log import _scenario
    from slam_lcd.sim.layouts import rates
    from slam_lcd.sim.renderer import render  # exact: the rendered depth in millimetres

    sc = _scenario(3, 0, "laps", 2.0, 160, 120, *rates("tum"), False)
    _, dep = render(sc.world, sc.camera, sc.gt_cam.poses[0] @ sc.T_bc, epoch=float(sc.laps[0]), color=True)
    assert np.array_equal(_depths(out)[0], depth_mm(dep))
