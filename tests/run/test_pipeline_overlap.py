"""Background feature extraction (run.extract_ahead) changes when loops are reported, never which."""
from __future__ import annotations

import numpy as np
import pytest

from slam_lcd.config import load_config
from slam_lcd.io.trajectory_files import read_tum


@pytest.fixture(scope="module")
def runs(demo_log_mcap, report_run, tmp_path_factory):
    """{extract_ahead: (keyframes, accepted loops, out dir)}: 0 run here; 2 (the default) is the
    session's report run of the same log and features (conftest), whose other options (plots,
    corrected.mcap, the RPE delta) change what is written beside, not the loops or the trajectory."""
    import json

    from slam_lcd.run import OutputOptions, run_log

    rc, report_dir, log = report_run
    assert rc == 0 and log == demo_log_mcap
    rep = json.loads((report_dir / "report.json").read_text())
    assert rep["config"]["run"]["extract_ahead"] == 2 and rep["config"]["features"]["kind"] == "orb"
    cfg = load_config("default", ["features.kind=orb", "features.feature_cache=false", "run.extract_ahead=0",
                                  "run.plots=false", "run.write_mcap=false"])
    d = tmp_path_factory.mktemp("ahead0")
    res = run_log(demo_log_mcap, d, cfg, output=OutputOptions(progress=False))
    return {0: (res.n_keyframes, res.loops_accepted, d),
            2: (rep["keyframes"], rep["loops"]["accepted"], report_dir)}


def test_same_keyframes_loops_and_trajectory_whatever_the_lookahead(runs):
    ref_kf, ref_loops_accepted, ref_dir = runs[0]
    ref = read_tum(ref_dir / "corrected.tum")
    ref_loops = (ref_dir / "loops.csv").read_text()
    assert ref_loops_accepted >= 1
    for ahead, (n_kf, _, d) in runs.items():
        assert n_kf == ref_kf, ahead
        assert (d / "loops.csv").read_text() == ref_loops, ahead
        t = read_tum(d / "corrected.tum")
        assert np.array_equal(t.stamps, ref.stamps) and np.allclose(t.poses, ref.poses, atol=1e-12), ahead


def test_plugin_reports_every_loop_once_with_lookahead():
    """add_keyframe may return a keyframe's loops on a later call; flush() returns the rest."""
    sim = pytest.importorskip("slam_lcd.sim")
    from slam_lcd.features import load_extractor
    from slam_lcd.run.pipeline import Pipeline
    from slam_lcd.types import Keyframe

    world = sim.build_world(0)
    traj = sim.make_trajectory("laps", laps=1.3, rate_hz=1.0)
    cam = sim.demo_camera(320, 240)
    T_bc = sim.T_body_camera()
    frames = [sim.render(world, cam, traj.poses[k] @ T_bc) for k in range(len(traj))]
    counts = {}
    for ahead in (0, 2):
        cfg = load_config("default", ["features.kind=orb", f"run.extract_ahead={ahead}"])
        seen = []
        pipe = Pipeline(cfg, camera=cam, T_body_camera=T_bc, extractor=load_extractor(cfg.features),
                        on_loop=lambda c, r, seen=seen: seen.append(c))
        returned = []
        for k, (img, depth) in enumerate(frames):
            cov = np.diag([1e-4] * 3 + [1e-3] * 3) if k else None
            returned += pipe.add_keyframe(Keyframe(0, int(traj.stamps[k]), traj.poses[k], image=img, depth=depth,
                                                   covariance_since_last=cov))
            assert len(pipe.keyframes) == max(0, k + 1 - ahead)  # at most `ahead` keyframes wait
        returned += pipe.flush()
        pipe.finalize()
        assert [(c.query_id, c.match_id) for c in returned] == [(c.query_id, c.match_id) for c in seen]
        assert [k.id for k in pipe.keyframes] == list(range(len(frames)))
        assert len(pipe.graph) == len(frames)
        counts[ahead] = [(c.query_id, c.match_id) for c in seen]
    assert counts[0] == counts[2] and counts[0]


def test_parallel_extraction_workers_give_the_same_run(demo_log_mcap, tmp_path, superpoint_weights):
    """run.extract_workers=2: two SuperPoint keyframes at once, each forward on one thread; the
    same keyframes, loops and trajectory as one worker, and torch's thread count is restored."""
    import torch

    from slam_lcd.run import OutputOptions, run_log

    before = torch.get_num_threads()
    out = {}
    for workers in (1, 2):
        cfg = load_config("default", [f"features.weights={superpoint_weights}", "features.feature_cache=false",
                                      "features.device=cpu", "run.extract_ahead=2", f"run.extract_workers={workers}",
                                      "run.plots=false", "run.write_mcap=false", "run.loop_pictures=false"])
        d = tmp_path / f"w{workers}"
        out[workers] = (run_log(demo_log_mcap, d, cfg, output=OutputOptions(progress=False)), d)
        assert torch.get_num_threads() == before
    (r1, d1), (r2, d2) = out[1], out[2]
    assert r2.n_keyframes == r1.n_keyframes and r2.loops_accepted == r1.loops_accepted
    assert r1.loops_accepted >= 1
    t1, t2 = read_tum(d1 / "corrected.tum"), read_tum(d2 / "corrected.tum")
    assert np.array_equal(t1.stamps, t2.stamps) and np.allclose(t1.poses, t2.poses, atol=1e-6)
