"""g2o import/export: formats, information order, round trip (real GTSAM example graphs)."""
from __future__ import annotations

import gtsam
import numpy as np
import pytest

from slam_lcd.backend.g2o import G2oEdge, chain_initial_estimate, read_g2o, write_g2o
from slam_lcd.errors import FileMissingError, TrajectoryFormatError, UnsupportedFormatError


def test_sphere2500_edge3_records(shared_data):
    poses, edges = read_g2o(shared_data / "posegraphs" / "sphere2500.txt", edge3_matrix="sqrt_information")
    assert poses == {}  # the file has no vertices
    assert len(edges) == 4949
    assert sum(e.j == e.i + 1 for e in edges) == 2499
    init = chain_initial_estimate(edges)
    assert sorted(init) == list(range(2500))
    # sqrt-information diag [10 10 10 100 100 25] in [t, r] -> information [r, t] order
    np.testing.assert_allclose(np.diag(edges[0].information), [1e4, 1e4, 625, 100, 100, 100])
    for e in edges[:50]:
        R = e.T_i_j[:3, :3]
        np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-9)


def test_sphere2500_noise_matches_sqrt_information(shared_data):
    """Residuals of the noisy edges against ground truth have std = 1/sqrt-information."""
    _, edges = read_g2o(shared_data / "posegraphs" / "sphere2500.txt", edge3_matrix="sqrt_information")
    _, gt_edges = read_g2o(shared_data / "posegraphs" / "sphere2500_groundtruth.txt", edge3_matrix="sqrt_information")
    gt = chain_initial_estimate(gt_edges)
    res = np.array(
        [gtsam.Pose3.Logmap(gtsam.Pose3(np.linalg.inv(e.T_i_j) @ np.linalg.inv(gt[e.i]) @ gt[e.j])) for e in edges]
    )
    expected = 1.0 / np.sqrt(np.diag(edges[0].information))
    np.testing.assert_allclose(res.std(0), expected, rtol=0.1)


def test_pose3example_matches_gtsam_reader(shared_data, tmp_path):
    path = shared_data / "posegraphs" / "pose3example.txt"
    poses, edges = read_g2o(path)
    assert len(poses) == 5 and len(edges) == 6
    graph, _ = gtsam.readG2o(str(path), True)
    for k, e in enumerate(edges):
        f = graph.at(k)
        np.testing.assert_allclose(f.measured().matrix(), e.T_i_j, atol=1e-6)
        R = f.noiseModel().R()  # sqrt information, GTSAM order
        np.testing.assert_allclose(R.T @ R, e.information, rtol=1e-6)
    # round trip through our writer
    out = tmp_path / "rt.g2o"
    write_g2o(out, poses, edges)
    poses2, edges2 = read_g2o(out)
    for k in poses:
        np.testing.assert_allclose(poses2[k], poses[k], atol=1e-8)
    for a, b in zip(edges, edges2, strict=True):
        np.testing.assert_allclose(b.T_i_j, a.T_i_j, atol=1e-8)
        np.testing.assert_allclose(b.information, a.information, rtol=1e-8)


def test_writer_swaps_information_blocks(tmp_path):
    """A rotation-only information entry lands in g2o's rotation block ([t, r] order)."""
    info = np.diag([1.0, 2.0, 3.0, 4.0, 5.0, 6.0])  # GTSAM [r, t]
    info[0, 3] = info[3, 0] = 0.5  # rx-tx coupling
    T = np.eye(4)
    T[:3, 3] = [1, 2, 3]
    out = tmp_path / "one.g2o"
    write_g2o(out, {0: np.eye(4), 1: T}, [G2oEdge(0, 1, T, info)])
    line = [ln for ln in out.read_text().splitlines() if ln.startswith("EDGE")][0].split()
    upper = np.array([float(x) for x in line[10:]])
    M = np.zeros((6, 6))
    M[np.triu_indices(6)] = upper
    np.testing.assert_allclose(np.diag(M), [4, 5, 6, 1, 2, 3])  # [t, r] in the file
    assert M[0, 3] == 0.5
    _, edges = read_g2o(out)
    np.testing.assert_allclose(edges[0].information, info)


def test_bad_inputs(tmp_path):
    with pytest.raises(FileMissingError):
        read_g2o(tmp_path / "missing.g2o")
    p = tmp_path / "bad.g2o"
    p.write_text("EDGE_SE3:QUAT 0 1 1 2 3\n")
    with pytest.raises(TrajectoryFormatError):
        read_g2o(p)
    p.write_text("VERTEX_SE2 0 0 0 0\n")
    with pytest.raises(UnsupportedFormatError):
        read_g2o(p)
