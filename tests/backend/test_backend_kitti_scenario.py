"""KITTI-00 scenario: drifting odometry, true loops, 20 % / 50 % false loops (acceptance).

The third false-loop case pairs places only 8-30 m apart (harder than random pairs).

Every fourth ground-truth pose is a keyframe (1136 keyframes) and one loop query every
five keyframes, to keep the suite fast; tools/bench_backend.py runs all 4541.
"""
from __future__ import annotations

import pytest

from slam_lcd.backend.config import BackendConfig
from slam_lcd.backend.pose_graph import values_to_array

from support.scenario import ScenarioConfig, ate_rmse, make_scenario, run_scenario
from support.solve import solve_lm

STRIDE = 4


def _scenario(shared_data, false_fraction, hard=False):
    d = shared_data / "trajectories"
    conf = ScenarioConfig(stride=STRIDE, false_fraction=false_fraction, seed=1)
    if hard:  # false loops between places only 8-30 m apart on the ground
        conf.false_min_dist, conf.false_max_dist = 8.0, 30.0
    return make_scenario(d / "KITTI_00_gt.txt", conf, d / "KITTI_00_gt_times.txt")


@pytest.fixture(scope="module")
def true_only(shared_data):
    sc = _scenario(shared_data, 0.0)
    g, res = run_scenario(sc, BackendConfig())
    print("\n" + res.line("true loops only"))
    return sc, g, res


def test_true_loops_only_cut_the_error(true_only):
    sc, g, res = true_only
    assert len(sc.stamps) == 1136 and sc.n_true > 30
    assert res.ate_odometry > 5.0  # the odometry really drifts
    assert res.ate < 0.25 * res.ate_odometry
    assert res.true_kept_frac >= 0.9
    # every record explains itself
    for r in g.loop_records:
        assert r.verdict in ("accepted", "rejected") and r.reason and r.chi2_gate is not None


@pytest.mark.parametrize("false_fraction,hard", [(0.2, False), (0.5, False), (0.5, True)])
def test_false_loops_are_rejected(shared_data, true_only, false_fraction, hard):
    _, _, ref = true_only
    sc = _scenario(shared_data, false_fraction, hard)
    assert sc.n_false >= 0.9 * false_fraction / (1 - false_fraction) * sc.n_true
    g, res = run_scenario(sc, BackendConfig())
    # without outlier handling: the same graph with every loop, plain least squares
    graph, _ = g.batch_graph("all")
    plain = values_to_array(solve_lm(graph, g.odometry_values())[0], len(sc.stamps))
    ate_plain = ate_rmse(sc.gt, plain)
    name = f"{int(100 * false_fraction)}% {'near ' if hard else ''}false loops, robust"
    print(
        f"\n{res.line(name)}"
        f"\n  true-only ATE {ref.ate:.2f} m; no outlier handling (all loops, LM): ATE {ate_plain:.2f} m"
    )
    assert res.ate <= 1.10 * ref.ate
    assert res.false_rejected_frac >= 0.95
    assert res.true_kept_frac >= 0.90
    assert ate_plain > 3.0 * res.ate
    reasons = [r.reason for r, t in zip(g.loop_records, sc.is_true, strict=True) if not t]
    assert all(reasons)
