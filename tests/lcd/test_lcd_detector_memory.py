"""What the loop detector keeps per keyframe: compact descriptors, in memory or in a temp file."""
from __future__ import annotations

import numpy as np
import pytest

from slam_lcd.errors import InputError
from slam_lcd.lcd import LcdConfig, LoopDetector
from slam_lcd.lcd.store import DescriptorStore
from slam_lcd.types import Keyframe

N_FRAMES = 60  # frames 41.. revisit the start: candidates that pass and fail


@pytest.fixture(scope="module")
def sp_features(shared_data, superpoint_weights):
    from support.lcd_corridor_cache import corridor_features

    return corridor_features(str(shared_data / "rtabmap_corridor"), "superpoint", str(superpoint_weights))[:N_FRAMES]


def _run(feats, **conf):
    det = LoopDetector(LcdConfig(pose=False, **conf), run_all_checks=True)
    for k, f in enumerate(feats):
        det.add(Keyframe(k, k * 1_000_000_000, np.eye(4), features=f))
    rows = [r.row() for r in det.records]
    return det, rows


def test_disk_store_gives_the_same_records_and_holds_no_descriptors(sp_features):
    mem, rows_mem = _run(sp_features, descriptor_storage="memory")
    disk, rows_disk = _run(sp_features, descriptor_storage="disk")
    assert rows_disk == rows_mem and any(r["accepted"] for r in rows_mem)
    n_values = sum(len(f) * f.descriptors.shape[1] for f in sp_features)
    assert mem.memory_bytes()["descriptors_resident"] == 2 * n_values  # float16
    assert disk.memory_bytes()["descriptors_resident"] == 0
    assert disk.memory_bytes()["descriptors_file"] == 2 * n_values
    disk.close()


def test_float16_descriptors_keep_the_detections(sp_features):
    half, rows_half = _run(sp_features, descriptor_storage="memory")
    full, rows_full = _run(sp_features, descriptor_storage="memory", descriptor_dtype="float32")
    assert full.memory_bytes()["descriptors_resident"] == 2 * half.memory_bytes()["descriptors_resident"]
    modes = ("ransac", "graph", "graph+ransac")

    def decisions(det):
        return [(r.query_id, r.match_id, r.accepted, *(r.passes(m) for m in modes)) for r in det.records]

    assert decisions(half) == decisions(full)


def test_store_round_trip_and_bad_settings(tmp_path):
    rng = np.random.default_rng(0)
    arrays = {k: rng.normal(size=(int(rng.integers(0, 50)), 256)).astype(np.float16) for k in range(5)}
    arrays[9] = rng.integers(0, 256, (40, 32), dtype=np.uint8)
    for mode in ("memory", "disk"):
        store = DescriptorStore(mode, directory=str(tmp_path))
        for k, a in arrays.items():
            store.put(k, a)
        for k, a in arrays.items():
            got = store.get(k)
            assert got.dtype == a.dtype and np.array_equal(got, a)
        store.close()
    assert list(tmp_path.iterdir()) == []  # the temp file is anonymous: nothing left behind
    with pytest.raises(InputError, match="descriptor store"):
        DescriptorStore("disk", directory=str(tmp_path / "missing")).put(0, arrays[0])
    with pytest.raises(InputError, match="descriptor_storage"):
        LoopDetector(LcdConfig(descriptor_storage="cloud"))
    with pytest.raises(InputError, match="descriptor_dtype"):
        LoopDetector(LcdConfig(descriptor_dtype="int4"))


def test_match_budget_bounds_what_each_candidate_verifies(sp_features):
    budget = 40
    det, _ = _run(sp_features, verify_max_matches=budget)
    verified = [r for r in det.records if r.graph is not None]
    assert any(r.n_matches > budget for r in verified)
    for r in verified:
        assert r.n_verified == min(r.n_matches, budget) == r.graph.n_matches
        assert r.ransac is None or r.ransac.n_matches == r.n_verified
    assert any(r.accepted for r in det.records)  # a budgeted candidate can still pass
