"""The plugin on demo-world keyframes: the examples run, loop information is honest (NEES)."""
from __future__ import annotations

import gtsam
import numpy as np
import pytest

from slam_lcd.backend.g2o import read_g2o

from support.module_files import load_module
from support.paths import REPO

EXAMPLES = REPO / "examples"


def _example(name):
    return load_module(EXAMPLES / f"{name}.py", f"example_{name}")


@pytest.fixture(scope="module")
def user_run(demo_keyframes_rgbd, superpoint_cpu):
    ex = _example("user_isam2")
    return ex, ex.run(demo_keyframes_rgbd, extractor=superpoint_cpu)


def test_example_user_isam2(user_run, capsys):
    """A user's iSAM2 (Symbol keys, GPS-like priors) with our loops: ATE <= 25% of odometry, no false loop."""
    ex, r = user_run
    recs = r.graph.loop_records
    acc = [x for x in recs if x.verdict == "accepted"]
    ate_odom, ate_after = ex.ate(r.gt, r.odometry), ex.ate(r.gt, r.estimate())
    with capsys.disabled():
        print(f"\n[example user_isam2] keyframes {len(r.keys)}, loops offered {len(recs)}, accepted {len(acc)}, "
              f"false accepted {r.false_accepted}; ATE {ate_odom:.3f} m -> {ate_after:.3f} m "
              f"({100 * ate_after / ate_odom:.1f}% of odometry)")
    assert ate_odom > 1.0  # the user's odometry really drifts
    assert ate_after <= 0.25 * ate_odom
    assert r.false_accepted == 0 and len(acc) >= 20
    assert all(gtsam.Symbol(x.query_id).chr() == ord("x") for x in recs)  # ids are the user's keys
    assert r.graph.gnc_times  # the GNC re-check ran on the user's graph ...
    # ... and left every factor the user made where it was, the same object, unchanged
    fs = r.isam.getFactorsUnsafe()
    ours = set(r.graph.loop_factor_indices())
    assert len(ours) == len(acc) and ours.isdisjoint(s for s, _ in r.user_factors)
    assert all(fs.at(s) is f for s, f in r.user_factors)
    assert sum(fs.at(i) is not None for i in range(fs.size())) == len(r.user_factors) + len(ours)
    n_gps = sum(isinstance(f, gtsam.PriorFactorPose3) for _, f in r.user_factors)
    assert n_gps == 1 + (len(r.keys) - 1) // ex.GPS_EVERY
    v = r.isam.calculateEstimate()
    assert all(fs.at(s).error(v) == f.error(v) for s, f in r.user_factors)


def test_example_loops_to_g2o(user_run, tmp_path):
    """Loops + odometry as g2o: the file reads back, and an offline LM solve of it beats the odometry."""
    ex_a, r = user_run
    ex = _example("loops_to_g2o")
    info = np.diag(1.0 / ex_a.ODOM_SIGMAS ** 2)
    ids = list(range(len(r.keys)))
    index = {k: i for i, k in enumerate(r.keys)}
    accepted = {(x.query_id, x.match_id) for x in r.graph.loop_records if x.verdict == "accepted"}
    from slam_lcd.types import LoopClosure

    loops = [LoopClosure(index[c.query_id], index[c.match_id], c.T_match_query, c.information)
             for c in r.closures if (c.query_id, c.match_id) in accepted]
    out = tmp_path / "loops.g2o"
    n = ex.write_loops_g2o(out, ids, r.odometry, info, loops)
    poses, edges = read_g2o(out)
    assert len(poses) == len(ids) and n == len(edges) == len(ids) - 1 + len(loops)
    back = {(e.j, e.i): e for e in edges}
    for c in loops:  # loops come back as written (pose and information)
        e = back[(c.query_id, c.match_id)]
        assert np.allclose(e.T_i_j, c.T_match_query, atol=1e-8)
        assert np.allclose(e.information, c.information, rtol=1e-6, atol=1e-6 * np.abs(c.information).max())
    graph, initial = gtsam.readG2o(str(out), True)  # a user's offline solver
    graph.add(gtsam.PriorFactorPose3(0, initial.atPose3(0), gtsam.noiseModel.Isotropic.Sigma(6, 1e-4)))
    sol = gtsam.LevenbergMarquardtOptimizer(graph, initial).optimize()
    est = np.array([sol.atPose3(k).matrix() for k in ids])
    assert ex_a.ate(r.gt, est) < 0.5 * ex_a.ate(r.gt, r.odometry)


@pytest.fixture(scope="module")
def rgbd_detector(demo_keyframes_rgbd, superpoint_cpu):
    from slam_lcd.eval.nees import run_detector

    return run_detector(demo_keyframes_rgbd, superpoint_cpu)


@pytest.mark.parametrize("sensor", ["rgbd", "stereo"])
def test_loop_information_nees_on_the_demo_world(sensor, rgbd_detector, demo_keyframes_rgbd, superpoint_cpu, capsys):
    """NEES = err^T Info err of the detector's loops vs exact ground truth: median in [3, 12], <= 5% above chi2 99%.

    Stereo: the same left images (cached features) with a rendered right image, 3-D points
    from SGBM disparity instead of the depth image.
    """
    from slam_lcd.eval.nees import CHI2_6_99, detector_nees
    from slam_lcd.sim.keyframes import demo_keyframes, demo_loop_nees

    if sensor == "rgbd":
        rep = detector_nees(rgbd_detector, demo_keyframes_rgbd)
    else:
        rep = demo_loop_nees(superpoint_cpu, frames=demo_keyframes(superpoint_cpu, sensor="stereo"))
    with capsys.disabled():
        print(f"\n[loop NEES, demo {sensor}] {rep.summary()}")
        for line in rep.detail_lines():
            print("   " + line)
    assert len(rep.nees) >= 20 and rep.n_false == 0
    assert 3.0 <= rep.median <= 12.0
    assert rep.frac_above_99 <= 0.05
    assert CHI2_6_99 == pytest.approx(16.81, abs=0.01)


def test_detector_takes_user_keyframes_with_their_own_ids(user_run, rgbd_detector, demo_keyframes_rgbd):
    """Minimal user keyframes with their own ids (GTSAM keys; example (a)) give the same loops as ids 0..N-1."""
    from dataclasses import replace

    from slam_lcd.errors import InputError
    from slam_lcd.lcd import LoopDetector

    _, r = user_run
    index = {k: i for i, k in enumerate(r.keys)}
    plain = [(c.query_id, c.match_id) for c in rgbd_detector.closures]
    own = [(index[c.query_id], index[c.match_id]) for c in r.closures]
    assert own == plain and len(own) >= 20
    assert all(np.allclose(x.T_match_query, y.T_match_query) and np.allclose(x.information, y.information)
               for x, y in zip(rgbd_detector.closures, r.closures, strict=True))
    kf = demo_keyframes_rgbd.keyframes[0]
    det = LoopDetector()
    with pytest.raises(InputError, match="not an integer"):
        det.add(replace(kf, id="x3"))
    with pytest.raises(InputError, match="landmarks"):
        det.add(replace(kf, id=1, landmarks=np.zeros((3, 3))))
