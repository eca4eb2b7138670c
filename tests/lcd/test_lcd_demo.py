"""Loop detection on the rendered demo world (repeated textures, RGB-D): precision, recall, pose accuracy."""
from __future__ import annotations

import numpy as np
import pytest

from support.demo_world_loops import detect_on_rendered_keyframes, relative_error


@pytest.fixture(scope="module")
def demo_run(superpoint_weights):
    pytest.importorskip("slam_lcd.sim")
    return detect_on_rendered_keyframes(superpoint_weights, "laps", 1.3)


def test_demo_world_loops(demo_run, capsys):
    det, traj, pairs, T_bc = demo_run
    cams = traj.poses @ T_bc
    assert len(pairs) > 0
    queries = np.unique(pairs[:, 0])
    found = set()
    errs = []
    for c in det.closures:
        # a true loop: the cameras are close with overlapping views (looser than the GT list's 1 m / 20 deg),
        # and the metric relative pose below agrees with ground truth
        t_cam, a_cam = relative_error(cams[c.match_id], cams[c.query_id])
        assert t_cam < 2.0 and a_cam < 45.0, (c.query_id, c.match_id, t_cam, a_cam)
        T_gt = np.linalg.inv(traj.poses[c.match_id]) @ traj.poses[c.query_id]
        errs.append(relative_error(c.T_match_query, T_gt))
        assert np.all(np.linalg.eigvalsh(c.information) > 0)
        if c.query_id in set(queries.tolist()):
            found.add(c.query_id)
    recall = len(found) / len(queries)
    errs = np.array(errs)
    with capsys.disabled():
        print(f"\n[lcd demo world] keyframes {len(traj)}, GT revisit keyframes {len(queries)}, "
              f"accepted loops {len(det.closures)}, revisit keyframes with a loop {len(found)} ({recall:.0%}), "
              f"pose error max {errs[:, 0].max() * 100:.2f} cm / {errs[:, 1].max():.3f} deg")
    assert recall >= 0.8
    assert errs[:, 0].max() < 0.05 and errs[:, 1].max() < 1.0


def test_every_candidate_recorded(demo_run):
    det, *_ = demo_run
    assert len(det.records) >= len(det.closures)
    accepted = [r for r in det.records if r.accepted]
    assert len(accepted) == len(det.closures)
    for r in det.records:
        assert r.reason == "ok" if r.accepted else r.reason != "ok"
        row = r.row()
        assert {"bow_score", "n_matches", "graph_score", "ransac_inliers", "reason"} <= set(row)


def test_demo_pairs_same_verdict_when_query_and_match_swap(demo_run):
    """Every candidate pair of the demo run: graph, RANSAC and graph+RANSAC verdicts do not depend on the roles."""
    from slam_lcd.lcd.pair import check_pair

    det, *_ = demo_run
    c = det.conf
    kw = dict(graph=True, ransac=True, graph_ransac=True, match=det._match)
    pairs = sorted({(r.query_id, r.match_id) for r in det.records})
    assert len(pairs) > 30
    for q, m in pairs:
        eq, em = det._entries[q], det._entries[m]
        dq, dm = det._store.get(q), det._store.get(m)
        ab = check_pair(eq.features, em.features, dq, dm, eq.camera, em.camera, c, **kw)
        ba = check_pair(em.features, eq.features, dm, dq, em.camera, eq.camera, c, **kw)
        for x, y in ((ab.graph, ba.graph), (ab.ransac, ba.ransac), (ab.ransac_on_graph, ba.ransac_on_graph)):
            assert (x.accepted, x.reason) == (y.accepted, y.reason), (q, m)
        assert ab.graph.n_nodes == ba.graph.n_nodes and ab.ransac_on_graph.inliers == ba.ransac_on_graph.inliers
