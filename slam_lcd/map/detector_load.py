"""Handing a map to a loop detector: every map keyframe a candidate, the vocabulary restored.

The detector gets light keyframes (keypoints, camera, mounting, odometry pose) with their 3-D
points; float descriptors stay in the map's arrays until a keyframe is a candidate
(:class:`~slam_lcd.lcd.store.DescriptorSource`). An empty online vocabulary takes the map's
snapshot (words, their index and every keyframe's bag of words) instead of replaying the
descriptors: 20-40 ms a keyframe saved.
"""
from __future__ import annotations

from functools import partial
from pathlib import Path

import numpy as np

from ..lcd.store import DescriptorSource
from ..types import Features, Keyframe
from ..vocab.snapshot import restore_into
from . import store
from .contents import MapError, MapManifest, SessionKeyframes, kept_ids
from .keyframe_arrays import camera_from_json


def load_into(detector, root: Path, manifest: MapManifest, sessions: list[SessionKeyframes], vocab_fh=None) -> None:
    """Remember every keyframe of the map in ``detector``, session by session (see ``Map.load_into``)."""
    bows = restore_vocab(detector, root, manifest, sessions, vocab_fh)
    at = 0
    for _, items in map_keyframes(manifest, sessions):
        detector.begin_session()
        for kf, desc, p3, src in items:
            detector.remember(kf, desc, p3, src, bow=bows[at] if bows is not None else None)
            at += 1


def map_keyframes(manifest: MapManifest, sessions: list[SessionKeyframes]):
    """Per session: (meta, [(light Keyframe with keypoints, descriptors, points3d, source), ...]).

    Float descriptors come as a :class:`~slam_lcd.lcd.store.DescriptorSource` (read from the
    map's arrays when a keyframe is a candidate), ORB's bytes as they are."""
    dim = int(manifest.features.get("descriptor_dim", 0))
    for meta, s in zip(manifest.sessions, sessions, strict=True):
        camera = camera_from_json(meta.get("camera"))
        T_bc = np.asarray(meta.get("T_body_camera", np.eye(4).tolist()), float)
        kind = manifest.features.get("kind", "superpoint")
        size = (camera.width, camera.height) if camera else tuple(meta.get("image_size", (0, 0)))
        items = []
        for i in map(int, np.flatnonzero(s.kept())):  # a keyframe the map keeps only the pose of is no candidate
            k, r = s.ids[i], s.rows(i)
            feats = Features(s.keypoints[r], np.zeros(0, np.float32), np.zeros((0, 1), np.float32), size, kind)
            kf = Keyframe(id=int(k), stamp=int(s.stamps[i]), T_world_body=s.T_odom[i], camera=camera,
                          T_body_camera=T_bc, features=feats)
            p3 = s.points3d[r]
            src = str(s.points_source[i])
            desc = (s.descriptors_of(i) if s.descriptors.dtype == np.uint8 and not len(s.scales)  # ORB: as is
                    else DescriptorSource(partial(s.descriptors_of, i), dim))
            items.append((kf, desc, p3 if src != "none" else None, src))
        yield meta, items


def restore_vocab(detector, root: Path, manifest: MapManifest, sessions: list[SessionKeyframes], vocab_fh=None):
    """Bags of words of the snapshot restored into ``detector.db``, or None (replay instead)."""
    db = detector.db
    if manifest.vocab_file is None or not db.online or len(db) or db.words is not None:
        return None
    state = store.read_vocab(root, manifest, vocab_fh)
    ids = kept_ids(sessions)
    if state is None or not np.array_equal(state["kf_ids"], ids):
        return None
    try:
        return restore_into(db, state)
    except (ValueError, KeyError, TypeError, RuntimeError) as e:
        raise MapError(f"vocabulary snapshot cannot be used ({e})", root / manifest.vocab_file) from None
