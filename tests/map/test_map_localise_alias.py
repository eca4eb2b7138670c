"""Localisation against a map with a look-alike place: fixes that agree with each other but not with the truth.

A look-alike place passes every appearance check, and the log's neighbouring keyframes that
see it agree with each other through the odometry: they are one wrong fix seen several
times. These synthetic cases pin what localisation does with them: a fix needs a fix to a
distinct place to confirm it, and two groups of fixes that each agree internally but not
with each other, neither clearly larger, are ambiguous.
"""
from __future__ import annotations

import numpy as np
from test_map_sessions import _closure, _drifting, _route

from slam_lcd.geometry import make_T
from slam_lcd.map.localize import localise

ALIAS_SHIFT = make_T(np.eye(3), np.array([8.0, 0.0, 0.0]))  # the look-alike stands 8 m east of the true place
N = 30
# the odometry covariance of one keyframe step in a demo log ([rx ry rz tx ty tz]: 2.5 deg of yaw, 0.1 m):
# loose enough that the joint solve bends the odometry between two groups of fixes to fit both
LOG_STEP_COV = np.diag([0.001, 0.001, 0.045, 0.1, 0.1, 0.002]) ** 2


def _map(gt: np.ndarray) -> tuple[dict, dict, dict]:
    """The map: the route's true places (ids 1000+i) and a look-alike copy of them 8 m away (2000+i)."""
    poses = {1000 + i: gt[i] for i in range(len(gt))}
    poses.update({2000 + i: ALIAS_SHIFT @ gt[i] for i in range(len(gt))})
    return poses, {k: "m" for k in poses}, {k: 0 for k in poses}


def _localise(true_at, alias_at, seed: int = 4, n: int = N, step_cov=None):
    """Localise a route whose keyframes ``true_at`` match their own place and ``alias_at`` the look-alike."""
    gt = _route(n, seed)
    odo = _drifting(gt, seed + 1)
    poses, session_of, component_of = _map(gt)
    fixes = [_closure(i, 1000 + i, np.eye(4)) for i in true_at]
    fixes += [_closure(i, 2000 + i, np.eye(4)) for i in alias_at]  # the same view: the look-alike's map keyframe
    loc = localise(poses, session_of, component_of, list(range(n)), list(range(n)), odo, [step_cov] * n, fixes)
    return gt, {k.kf_id: k for k in loc.keyframes}, loc


def _wrongly_localised(gt, by_id) -> list[int]:
    return [k for k, f in by_id.items() if f.localised and np.linalg.norm(f.T_map[:3, 3] - gt[k][:3, 3]) > 1.0]


def test_three_consecutive_fixes_to_a_look_alike_do_not_confirm_each_other():
    # 1 m along one wall, looking one way (the route turns 90 degrees at keyframe 12, and views of two directions
    # are two places: a look-alike seen across that turn is a look-alike of two places)
    gt, by_id, loc = _localise([], [9, 10, 11])
    assert not any(f.localised for f in by_id.values())
    assert len(loc.trajectory) == 0 and loc.notes
    assert all("not confirmed" in by_id[k].reason for k in (9, 10, 11)), [by_id[k].reason for k in (9, 10, 11)]


def test_seven_fixes_to_a_look_alike_against_five_true_ones_are_ambiguous():
    gt, by_id, loc = _localise(range(0, 13, 3), range(14, 28, 2))
    assert _wrongly_localised(gt, by_id) == []
    assert loc.ambiguous == 12
    assert by_id[14].reason == "ambiguous: 7 fixes agree on one place, 5 on another", by_id[14].reason
    assert by_id[0].reason == "ambiguous: 5 fixes agree on one place, 7 on another", by_id[0].reason
    assert len(loc.trajectory) == 0 and "ambiguous" in loc.notes[0]


def test_a_clearly_larger_true_group_wins_over_a_look_alike():
    true_at = [*range(0, 10, 3), *range(20, 30, 3)]
    gt, by_id, loc = _localise(true_at, range(12, 20, 2), step_cov=LOG_STEP_COV)
    assert _wrongly_localised(gt, by_id) == []
    assert all(by_id[k].localised for k in true_at)
    assert not any(by_id[k].localised for k in range(12, 20, 2))
    assert loc.ambiguous == 0
    assert "larger group" in by_id[12].reason, by_id[12].reason


def test_a_look_alike_group_far_along_the_log_from_the_true_one_still_loses():
    """The odometry between two groups 16 m apart bends to fit both in the joint solve; the groups' disagreement
    where the odometry between them is shortest still tells them apart."""
    gt, by_id, loc = _localise(range(46, 60), range(0, 14, 2), n=60, step_cov=LOG_STEP_COV)
    assert _wrongly_localised(gt, by_id) == []
    assert all(by_id[k].localised for k in range(46, 60))
    assert "larger group" in by_id[0].reason, by_id[0].reason


def test_a_long_run_of_look_alike_fixes_does_not_win_over_true_fixes_too_few_to_confirm_themselves():
    """Eight consecutive keyframes see the look-alike: 3.5 m along it, so the four at its ends (3 m apart)
    confirm each other. Five see the true place over 2 m, too short to confirm themselves, yet they are a
    rival: the look-alike must not win."""
    true_at, alias_at = range(1, 6), range(14, 22)
    gt, by_id, loc = _localise(true_at, alias_at, step_cov=LOG_STEP_COV)
    assert _wrongly_localised(gt, by_id) == []
    assert not any(by_id[k].localised for k in alias_at)
    assert by_id[14].reason == "ambiguous: 4 fixes agree on one place, 5 on another", by_id[14].reason
    assert all("not confirmed" in by_id[k].reason for k in true_at)
