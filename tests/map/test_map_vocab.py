"""The map's vocabulary snapshot: a reopened map queries like the database that saved it, without replay."""
from __future__ import annotations

import numpy as np
import pytest

from slam_lcd.lcd import LoopDetector
from slam_lcd.map import store
from slam_lcd.map.config import MapConfig
from slam_lcd.map.keyframe_arrays import session_arrays
from slam_lcd.map.session_map import Map
from slam_lcd.map.store import MapError
from slam_lcd.types import Features, Keyframe
from slam_lcd.vocab import VocabConfig

FEATURES = {"kind": "superpoint", "weights_sha256": "x", "descriptor_dim": 32, "descriptor_form": "int8"}


def _stream(n, seed=0, places=12):
    """n keyframes revisiting ``places`` places: unit descriptors near each place's landmarks."""
    rng = np.random.default_rng(seed)
    land = rng.normal(size=(places, 60, 32)).astype(np.float32)
    out = []
    for i in range(n):
        d = land[i % places] + 0.15 * rng.normal(size=(60, 32)).astype(np.float32)
        out.append(d / np.linalg.norm(d, axis=1, keepdims=True))
    return out


def _kf(i, d):
    feats = Features(np.zeros((len(d), 2), np.float32), np.zeros(0, np.float32), np.zeros((0, 1), np.float32),
                     (64, 48), "superpoint")
    return Keyframe(id=i, stamp=1000 * (i + 1), T_world_body=np.eye(4), features=feats)


def _save_map(root, vconf, centres="int8", n=40):
    det = LoopDetector(vocab_conf=vconf)
    kfs = [_kf(i, d) for i, d in enumerate(_stream(n))]
    for kf, d in zip(kfs, _stream(n), strict=True):
        det.remember(kf, d, None, "none")
    m = Map.open(root, features=FEATURES, write=True, create=True, conf=MapConfig(visual_links=False,
                                                                                  vocab_centres=centres))
    m.sessions = [session_arrays(det, kfs, None, FEATURES["descriptor_form"])]
    m._unsaved = [({"name": "s", "keyframes": n, "kf_id_start": 0, "kf_id_end": n, "T_map_session": np.eye(4).tolist(),
                    "component": 0}, m.sessions[0])]
    m.manifest.sessions = [m._unsaved[0][0]]
    m.graph = store.MapGraph(m.sessions[0].ids, m.sessions[0].T_odom, np.zeros(0, np.int64), np.zeros(0, np.int64),
                             np.zeros((0, 4, 4)), np.zeros((0, 6, 6)), np.zeros(0, bool), np.zeros(0, "<U8"))
    m._vocab = m._vocab_snapshot(det)
    m.save()
    m.close()
    return det


@pytest.mark.parametrize("min_words", [5000, 64])  # the word index inactive / its graph in the snapshot
def test_reopened_map_queries_like_the_database_that_saved_it(tmp_path, min_words):
    vconf = VocabConfig(ann_min_words=min_words)
    det = _save_map(tmp_path / "m", vconf)
    m = Map.open(tmp_path / "m")
    assert m.manifest.vocab_file and m.manifest.vocab_file in m.manifest.files
    again = LoopDetector(vocab_conf=vconf)
    m.load_into(again)
    a, b = det.db, again.db
    assert b.kf_ids == a.kf_ids and b.n_words == a.n_words and b.words.n_images == a.words.n_images
    assert b.words.index.active == a.words.index.active == (min_words == 64)
    assert np.allclose(b._database_norms(), a._database_norms())
    for q in _stream(6, seed=7):
        ra = a.query(q, top_k=5)
        rb = b.query(q, top_k=5)
        assert [c.match_id for c in ra] == [c.match_id for c in rb]
        assert np.allclose([c.bow_score for c in ra], [c.bow_score for c in rb])
    # the restored words go on growing like the saved ones
    for q in _stream(3, seed=9):
        i = 1000 + len(a)
        assert np.array_equal(a.add(i, 10 ** 9 + i, q).words, b.add(i, 10 ** 9 + i, q).words)


def test_without_a_snapshot_the_vocabulary_is_replayed(tmp_path):
    det = _save_map(tmp_path / "m", VocabConfig())
    m = Map.open(tmp_path / "m")
    m.manifest.vocab_file = None  # as a map of this schema written before snapshots reads
    again = LoopDetector()
    m.load_into(again)
    assert again.db.kf_ids == det.db.kf_ids and again.db.n_words > 0
    # a snapshot of other keyframes (here: the map lost its last keyframe) is not used either
    m = Map.open(tmp_path / "m")
    s = m.sessions[0]
    m.sessions[0] = store.SessionKeyframes(s.ids[:-1], s.stamps[:-1], s.T_odom[:-1], s.cov[:-1], s.T_gt[:-1],
                                           s.offsets[:-1], s.keypoints, s.descriptors, s.scales, s.points3d,
                                           s.points_source[:-1])
    again = LoopDetector()
    m.load_into(again)
    assert again.db.kf_ids == det.db.kf_ids[:-1]


def test_tampered_snapshot_is_a_map_error_naming_the_file(tmp_path):
    _save_map(tmp_path / "m", VocabConfig())
    m = Map.open(tmp_path / "m")
    path = tmp_path / "m" / m.manifest.vocab_file
    raw = bytearray(path.read_bytes())
    raw[len(raw) // 2] ^= 0xFF
    path.write_bytes(bytes(raw))
    with pytest.raises(MapError) as e:
        m.load_into(LoopDetector())
    assert path.name in str(e.value)


def test_snapshot_bytes_int8_and_float16(tmp_path):
    for form in ("int8", "float16"):
        _save_map(tmp_path / form, VocabConfig(), centres=form)
        m = Map.open(tmp_path / form)
        assert (tmp_path / form / m.manifest.vocab_file).stat().st_size > 0
    a = (tmp_path / "int8" / Map.open(tmp_path / "int8").manifest.vocab_file).stat().st_size
    b = (tmp_path / "float16" / Map.open(tmp_path / "float16").manifest.vocab_file).stat().st_size
    assert a < b
