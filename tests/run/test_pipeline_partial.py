"""Runs that are not the happy path: Ctrl-C mid-log leaves a consistent partial result, and a
log without odometry is corrected on top of the built-in RGB-D visual odometry."""
from __future__ import annotations

import json

import numpy as np
import pytest

from slam_lcd.config import load_config
from slam_lcd.io.trajectory_files import read_tum


@pytest.fixture(scope="module")
def small_log(tmp_path_factory):
    from slam_lcd.sim import make_demo_log

    p = tmp_path_factory.mktemp("small") / "small.mcap"
    make_demo_log(p, "mcap", frames=80, seed=2, depth=True, width=320, height=240)
    return p


def _orb_config(*extra):
    return load_config("default", ["features.kind=orb", "features.feature_cache=false", *extra])


@pytest.fixture
def read_ahead_from_the_start(monkeypatch):
    """The log read in a thread from its first message on (the runner's judgement bypassed)."""
    import slam_lcd.run.runner as runner

    monkeypatch.setattr(runner._ReadAheadJudge, "pays", lambda self: True)


@pytest.mark.parametrize("reading", ["inline", "thread"])
def test_interrupt_writes_consistent_partial_result(small_log, tmp_path, monkeypatch, request, reading):
    """Ctrl-C mid-log; with ``thread`` the log is read ahead from its first message on, and the
    interrupt also stops the reading thread (not left running)."""
    import threading

    from slam_lcd.run import OutputOptions, run_log
    from slam_lcd.run.pipeline import Pipeline

    if reading == "thread":
        request.getfixturevalue("read_ahead_from_the_start")

    calls = {"n": 0}
    real = Pipeline.add_image

    def interrupted(self, *a, **k):
        calls["n"] += 1
        if calls["n"] == 40:
            raise KeyboardInterrupt
        return real(self, *a, **k)

    monkeypatch.setattr(Pipeline, "add_image", interrupted)
    res = run_log(small_log, tmp_path, _orb_config(), output=OutputOptions(progress=False))
    assert res.interrupted and res.n_frames == 39
    rep = json.loads((tmp_path / "report.json").read_text())
    assert rep["interrupted"] is True
    odo, cor = read_tum(tmp_path / "odometry.tum"), read_tum(tmp_path / "corrected.tum")
    assert len(odo) == len(cor) > 0 and np.array_equal(odo.stamps, cor.stamps)
    assert odo.stamps[-1] < 1_700_000_000_000_000_000 + 5_000_000_000  # stopped early (80 frames = 8 s)
    assert not [t for t in threading.enumerate() if t.name == "slam-lcd-reader"]


def test_log_without_odometry_uses_visual_odometry(small_log, tmp_path):
    from slam_lcd.io import open_log
    from slam_lcd.io.writers import copy_topics, open_writer
    from slam_lcd.run import OutputOptions, run_log

    no_odom = tmp_path / "no_odom.mcap"
    with open_log(small_log) as r, open_writer(no_odom, "mcap") as w:
        copy_topics(r, w, [t for t in r.topics if t != "/odom"])
    res = run_log(no_odom, tmp_path / "out", _orb_config(), output=OutputOptions(progress=False))
    odo = read_tum(tmp_path / "out" / "odometry.tum")
    assert len(odo) >= 70  # one VO pose per tracked frame
    # VO on the rendered RGB-D frames is accurate: a few cm over ~9 m
    assert res.ate_before is not None and res.ate_before < 0.1


def test_odometry_break_becomes_large_noise_link_not_a_jump():
    """A flagged odometry break (tracking lost) gives the next keyframe a large-noise link."""
    from slam_lcd.geometry import make_T
    from slam_lcd.run.pipeline import Pipeline

    rng = np.random.default_rng(0)
    cfg = _orb_config()
    pipe = Pipeline(cfg)
    t0 = 1_000_000_000
    for k in range(40):
        stamp = t0 + k * 100_000_000
        x = 0.1 * k + (5.0 if k >= 20 else 0.0)  # the odometry jumps 5 m at the break
        pipe.add_odometry(stamp, make_T(np.eye(3), [x, 0, 0]), segment_start=(k == 20))
        pipe.add_image(stamp, (rng.random((120, 160)) * 255).astype(np.uint8))
    pipe.finalize()
    kf = [k for k in pipe.keyframes if k.stamp == t0 + 20 * 100_000_000]
    assert len(kf) == 1, "the frame at the break is a keyframe"
    sigma_t = np.sqrt(np.diag(kf[0].covariance_since_last)[3:])
    assert sigma_t.min() >= 5.0
    before = [k for k in pipe.keyframes if k.stamp == t0 + 19 * 100_000_000]
    assert len(before) == 1, "the frame before the break is promoted to a keyframe"
    assert len(pipe.graph) == len(pipe.keyframes)


def test_reading_ahead_in_a_thread_changes_nothing_in_the_outputs(small_log, tmp_path, monkeypatch,
                                                                  read_ahead_from_the_start):
    """run.read_ahead (the log read in a thread of its own, here from the first message on) against
    reading in the main thread."""
    from slam_lcd.io.prefetch import Prefetched
    from slam_lcd.run import OutputOptions, run_log

    started = []
    real_start = Prefetched.start
    monkeypatch.setattr(Prefetched, "start", lambda self: (started.append(1), real_start(self)))
    outs = {}
    for ahead in (0, 3):
        out = tmp_path / f"ahead{ahead}"
        res = run_log(small_log, out, _orb_config(f"run.read_ahead={ahead}"), output=OutputOptions(progress=False))
        outs[ahead] = (res.n_frames, res.n_keyframes, (out / "corrected.tum").read_text(),
                       (out / "loops.csv").read_text(), (out / "keyframes_corrected.tum").read_text())
    assert len(started) == 1  # only the run with read_ahead > 0 read in a thread
    assert outs[0] == outs[3]
    assert outs[0][0] == 80


def test_damage_found_by_the_reading_thread_is_the_same_typed_error(small_log, tmp_path, read_ahead_from_the_start):
    from slam_lcd.errors import CorruptLogError
    from slam_lcd.run import OutputOptions, run_log

    from support.bad_input_files import damage_zstd_chunk

    bad = damage_zstd_chunk(small_log, tmp_path / "late_damage.mcap", which=-1)  # found mid-run, by the thread
    with pytest.raises(CorruptLogError, match="damaged data") as e:
        run_log(bad, tmp_path / "out", _orb_config(), output=OutputOptions(progress=False))
    assert "late_damage.mcap" in str(e.value)
