"""sphere2500 (GTSAM example graph) solved in batch and by iSAM2 fed pose by pose."""
from __future__ import annotations

import numpy as np
import pytest

from slam_lcd.backend.config import BackendConfig
from slam_lcd.backend.g2o import chain_initial_estimate, read_g2o

from support.solve import batch_graph, from_values, isam2_edge_by_edge, solve_lm, to_values, translation_rmse


@pytest.fixture(scope="module")
def sphere(shared_data):
    d = shared_data / "posegraphs"
    _, edges = read_g2o(d / "sphere2500.txt", edge3_matrix="sqrt_information")
    _, gt_edges = read_g2o(d / "sphere2500_groundtruth.txt", edge3_matrix="sqrt_information")
    return edges, chain_initial_estimate(gt_edges)


def test_sphere2500_batch_reaches_ground_truth(sphere):
    edges, gt = sphere
    init = chain_initial_estimate(edges)
    rmse0 = translation_rmse(init, gt)
    graph = batch_graph(edges, 0, np.eye(4))
    values, secs = solve_lm(graph, to_values(init))
    rmse = translation_rmse(from_values(values), gt)
    dof = 6 * len(edges) - 6 * (len(init) - 1)
    print(f"\nsphere2500 batch LM: translation RMSE {rmse:.3f} m (initial {rmse0:.2f} m), {secs:.2f} s, "
          f"chi2/dof {2 * graph.error(values) / dof:.2f}")
    assert rmse0 > 30.0
    assert rmse < 1.5 and rmse < 0.05 * rmse0
    # the file's weights are right: the optimum's chi2 per degree of freedom is ~1
    assert 0.8 < 2 * graph.error(values) / dof < 1.2


def test_sphere2500_isam2_prefix_matches_batch(sphere):
    """iSAM2 one pose at a time over the first 400 poses (full graph: tools/bench_backend.py)."""
    edges, gt = sphere
    n = 400
    sub = [e for e in edges if max(e.i, e.j) < n]
    init = chain_initial_estimate(sub)
    lm = from_values(solve_lm(batch_graph(sub, 0, np.eye(4)), to_values(init))[0])
    est, times = isam2_edge_by_edge(edges, BackendConfig(), n_poses=n)
    assert sorted(est) == list(range(n))
    rmse_gt, rmse_lm, rmse0 = translation_rmse(est, gt), translation_rmse(est, lm), translation_rmse(init, gt)
    print(f"\nsphere2500[:{n}] iSAM2: RMSE vs GT {rmse_gt:.3f} m, vs batch {rmse_lm:.4f} m (initial {rmse0:.2f} m), "
          f"median update {1e3 * np.median(times):.2f} ms")
    assert rmse_lm < 0.05
    assert rmse_gt < 1.0 and rmse_gt < 0.1 * rmse0
