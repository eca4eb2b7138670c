"""Verification does not depend on which keyframe is the query (issue: ORB pairs flipped between
accepted and ``low_node_ratio`` when the roles swapped, because the ratio test was one-sided)."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from slam_lcd.features.matching import mutual_nn_match_symmetric
from slam_lcd.lcd import LcdConfig, LoopDetector
from slam_lcd.lcd.pair import check_pair
from slam_lcd.lcd.store import compact_descriptors
from slam_lcd.types import Keyframe
from slam_lcd.vision.camera import default_camera

from support.lcd_corridor_cache import corridor_features


@pytest.mark.parametrize("binary", [False, True])
def test_symmetric_matching_gives_the_same_pairs_and_ratios_both_ways(binary):
    rng = np.random.default_rng(3)
    if binary:
        d1 = rng.integers(0, 256, (300, 32), dtype=np.uint8)
        d2 = d1[rng.permutation(300)[:250]].copy()
        flips = rng.integers(0, 256, d2.shape, dtype=np.uint8) & rng.integers(0, 256, d2.shape, dtype=np.uint8) \
            & rng.integers(0, 256, d2.shape, dtype=np.uint8)  # ~1/8 of the bits
        d2 ^= flips
    else:
        d1 = rng.normal(size=(300, 256)).astype(np.float32)
        d2 = d1[rng.permutation(300)[:250]] + 0.6 * rng.normal(size=(250, 256)).astype(np.float32)
        d1 /= np.linalg.norm(d1, axis=1, keepdims=True)
        d2 /= np.linalg.norm(d2, axis=1, keepdims=True)
    m12, dist12, r12 = mutual_nn_match_symmetric(d1, d2)
    m21, dist21, r21 = mutual_nn_match_symmetric(d2, d1)
    assert len(m12) > 50
    a = {tuple(p): (d, r) for p, d, r in zip(m12.tolist(), dist12, r12, strict=True)}
    b = {(j, i): (d, r) for (i, j), d, r in zip(m21.tolist(), dist21, r21, strict=True)}
    assert a.keys() == b.keys()
    for k in a:
        assert a[k][0] == pytest.approx(b[k][0], abs=1e-5) and a[k][1] == pytest.approx(b[k][1], abs=1e-5)
    assert np.all((r12 > 0) & (r12 <= 1.0))


def _same_verdict(fq, fm, dq, dm, cam, conf):
    kw = dict(graph=True, ransac=True, graph_ransac=True, match=lambda a, b: mutual_nn_match_symmetric(
        a, b, max_distance=conf.match_max_distance_orb if a.dtype == np.uint8 else conf.match_max_distance_sp))
    ab = check_pair(fq, fm, dq, dm, cam, cam, conf, **kw)
    ba = check_pair(fm, fq, dm, dq, cam, cam, conf, **kw)
    assert np.array_equal(ab.graph_matches, ba.graph_matches[:, ::-1])
    for x, y in ((ab.graph, ba.graph), (ab.ransac, ba.ransac), (ab.ransac_on_graph, ba.ransac_on_graph)):
        assert (x.accepted, x.reason) == (y.accepted, y.reason)
    assert ab.graph.n_nodes == ba.graph.n_nodes and np.array_equal(ab.graph.kept, ba.graph.kept)
    assert ab.ransac.inliers == ba.ransac.inliers and ab.ransac_on_graph.inliers == ba.ransac_on_graph.inliers
    return ab.graph.accepted and ab.ransac_on_graph.accepted


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["superpoint", "orb"])
def test_corridor_pairs_same_verdict_when_query_and_match_swap(kind, shared_data, superpoint_weights):
    folder = shared_data / "rtabmap_corridor"
    feats = corridor_features(str(folder), kind, str(superpoint_weights) if kind == "superpoint" else None)
    conf = LcdConfig(pose=False)
    det = LoopDetector(conf, run_all_checks=True)
    for k, f in enumerate(feats):
        det.add(Keyframe(k, k * 1_000_000_000, np.eye(4), features=f))
    cam = default_camera(*feats[0].image_size, conf.default_focal_factor)
    desc = [compact_descriptors(f.descriptors, conf.descriptor_dtype) for f in feats]
    pairs = {(r.query_id, r.match_id) for r in det.records}
    accepted = sum(_same_verdict(feats[q], feats[m], desc[q], desc[m], cam, conf) for q, m in sorted(pairs))
    assert len(pairs) > 250 and accepted > 30
    # the relaxed thresholds of a loop that continues the previous one (lcd.consistent_min_matches)
    k = conf.consistent_min_matches
    low = dataclasses.replace(conf, graph_min_matches=k, graph_min_nodes=k, ransac_min_inliers=k)
    few = sorted({(r.query_id, r.match_id) for r in det.records if k <= r.n_matches < conf.graph_min_matches})
    assert len(few) >= 5  # SuperPoint 60+, ORB 6 (ORB pairs have many more matches)
    for q, m in few:
        _same_verdict(feats[q], feats[m], desc[q], desc[m], cam, low)
