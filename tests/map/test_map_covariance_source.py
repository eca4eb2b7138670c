"""Where a session's odometry covariances come from (given by the log, or modelled by the front end),
what PCM makes of each, and maps that did not record it.

The Monte Carlo drives the project's odometry simulator (scale and heading biases, white noise)
twice along one open route and offers a true loop every metre between the two drives; PCM must
pass the true loop pairs whatever the source of the covariances.
"""
from __future__ import annotations

import numpy as np
import pytest

from slam_lcd.geometry import inv, se3_exp
from slam_lcd.map.config import MapConfig
from slam_lcd.map.contents import MapManifest, SessionKeyframes
from slam_lcd.map.joint_types import JointLoop
from slam_lcd.map.pcm import FLOOR, SessionChains, allowance, pair_statistics, pcm_threshold, step_covariances
from slam_lcd.map.reader import read_session
from slam_lcd.map.session_graph import session_poses
from slam_lcd.map.store import _write_npz

from support.odometry_routes import drive, open_route, session_of, true_poses

SEPARATIONS = (2, 10, 25, 50)  # metres between the two loops of a pair (within 1 m)
LOOP_COV = np.diag([1e-4] * 6)


def _rejections(covariances: str, seeds=(0, 1)) -> dict[int, tuple[int, int]]:
    """{separation: (true pairs rejected, pairs)} over ``seeds`` pairs of drives."""
    out = {d: [0, 0] for d in SEPARATIONS}
    rng = np.random.default_rng(5)
    L = np.linalg.cholesky(LOOP_COV)
    for seed in seeds:
        gt_a, gt_b = open_route(10.0), open_route(10.0, lateral=0.3)
        ka, kb = drive(gt_a, 2 * seed, covariances), drive(gt_b, 2 * seed + 1, covariances)
        a, b = session_of("a", ka, 0), session_of("b", kb, 10000)
        ga, gb = true_poses(gt_a, ka), true_poses(gt_b, kb)
        loops, where = [], []
        for i in range(0, len(ga), 2):
            j = int(np.argmin(np.linalg.norm(gb[:, :3, 3] - ga[i, :3, 3], axis=1)))
            Z = inv(ga[i]) @ gb[j] @ se3_exp(L @ rng.normal(size=6))
            loops.append(JointLoop(int(b.ids[j]), int(a.ids[i]), Z, np.linalg.inv(LOOP_COV), True))
            where.append(ga[i, :3, 3])
        X = pair_statistics(loops, SessionChains([a, b], MapConfig()))
        D = np.linalg.norm(np.array(where)[:, None] - np.array(where)[None], axis=2)
        for d in SEPARATIONS:
            near = np.abs(D - d) < 1.0
            out[d][0] += int((X[near] > pcm_threshold(MapConfig())).sum())
            out[d][1] += int(near.sum())
    return {d: (r, n) for d, (r, n) in out.items()}


@pytest.mark.parametrize("covariances", ["given", "zero", "model"])
def test_true_loop_pairs_pass_pcm_whatever_the_source_of_the_odometry_covariance(covariances):
    got = _rejections(covariances)
    print(f"\n{covariances:6s} true pairs rejected: "
          + "  ".join(f"{d} m {100 * r / n:.1f} % of {n}" for d, (r, n) in got.items()))
    for d, (r, n) in got.items():
        assert n > 50
        assert r <= 0.02 * n, f"{r} of {n} true loop pairs {d} m apart rejected ({covariances} covariances)"


def test_all_zero_covariances_are_marked_modelled_and_replaced_by_the_allowance():
    gt = open_route(10.0)
    kfs = drive(gt, 0, "zero")
    assert {k.covariance_source for k in kfs[1:]} == {"model"}
    assert {k.covariance_source for k in drive(gt, 0, "given")[1:]} == {"given"}
    s = session_of("a", kfs, 0)
    s.cov[1:] *= 1e-4  # what the map stored does not matter for a modelled step: the allowance replaces it
    steps = step_covariances(s, MapConfig())
    for i in (1, 20, 60):
        T = inv(s.T_odom[i - 1]) @ s.T_odom[i]
        np.testing.assert_allclose(steps[i], allowance(T, MapConfig()))
    s.cov_modelled = None  # read as given: the stored covariance is used as it is
    np.testing.assert_allclose(step_covariances(s, MapConfig())[20], s.cov[20])


def test_the_allowance_is_a_random_walk_in_distance_and_angle_plus_the_floor():
    conf = MapConfig()
    T = np.eye(4)
    T[:3, :3] = se3_exp(np.array([0, 0, 0.3, 0, 0, 0]))[:3, :3]
    T[:3, 3] = [2.0, 0, 0]
    v_r = conf.pcm_sigma_rot_per_m ** 2 * 2.0 + conf.pcm_sigma_rot_per_rad ** 2 * 0.3
    np.testing.assert_allclose(allowance(T, conf), np.diag([v_r] * 3 + [conf.pcm_sigma_trans_per_m ** 2 * 2.0] * 3
                                                           + FLOOR))


def _arrays(n: int, with_source: bool) -> dict[str, np.ndarray]:
    s = SessionKeyframes(np.arange(n, dtype=np.int64), np.arange(n, dtype=np.int64), np.repeat(np.eye(4)[None], n, 0),
                         np.repeat(np.eye(6)[None] * 1e-4, n, 0), np.full((n, 4, 4), np.nan),
                         np.zeros(n + 1, np.int64), np.zeros((0, 2), np.float32), np.zeros((0, 32), np.uint8),
                         np.zeros(0, np.float32), np.zeros((0, 3), np.float32), np.array(["none"] * n, "<U10"),
                         np.array(["model"] * n, "<U5") if with_source else None)
    return s.arrays()


@pytest.mark.parametrize("with_source", [False, True], ids=["map-without-cov_source", "map-with-it"])
def test_a_session_file_without_cov_source_still_opens_and_reads_as_given(tmp_path, with_source):
    arrays = _arrays(4, with_source)
    assert ("cov_source" in arrays) == with_source
    entry = _write_npz(tmp_path / "s.npz", arrays)
    manifest = MapManifest(features={}, sessions=[{"name": "s", "file": "s.npz", "component": 0}],
                           files={"s.npz": entry})
    s = read_session(tmp_path, manifest, 0)
    assert s.cov_modelled().tolist() == [with_source] * 4
    sp = session_poses(manifest.sessions, [s], {})[0]
    steps = step_covariances(sp, MapConfig())
    if with_source:  # modelled: the allowance for a step that did not move is the floor
        np.testing.assert_allclose(steps[2], np.diag(FLOOR))
    else:
        np.testing.assert_allclose(steps[2], np.eye(6) * 1e-4)
