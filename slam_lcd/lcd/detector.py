"""``LoopDetector``: the loop-closure plugin (keyframes in, verified loops out).

Chain per keyframe: features (extracted if missing) -> Bag-of-Words candidates (top-K,
recent keyframes excluded) -> one-to-one descriptor matches (at most
``lcd.verify_max_matches`` go on: a fixed budget per candidate) -> verification
(``conf.verify``: 'none', 'ransac', 'graph' or 'graph+ransac') -> metric relative pose ->
optional temporal consistency. Every candidate, accepted or not, is appended to
``detector.records`` with the reason and the evidence, so a run can be audited and
evaluated (``slam-lcd eval-lcd``).
"""
from __future__ import annotations

import dataclasses
import logging
from collections.abc import Callable
from functools import partial

import numpy as np

from ..errors import InputError
from ..features import load_extractor
from ..features.matching import mutual_nn_match_symmetric
from ..types import CameraModel, Features, Keyframe, LoopCandidate, LoopClosure
from ..vision.camera import default_camera
from ..vocab import BowDatabase
from .candidate_check import verify_candidate
from .config import LcdConfig, stops_at_first_accepted
from .geometry import keyframe_points3d
from .islands import IslandMember, verification_order
from .records import CandidateRecord, PartClock, StoredKeyframe, drop_arrays, failed_on_a_count, loop_closure
from .store import DESCRIPTOR_DTYPES, DescriptorSource, DescriptorStore, compact_descriptors, compact_loaded
from .temporal import TemporalConsistency
from .user_keyframe import check_user_keyframe

log = logging.getLogger(__name__)

VERIFY_MODES = ("none", "ransac", "graph", "graph+ransac")


class LoopDetector:
    """Loop-closure detection usable on its own: ``add(keyframe) -> list[LoopClosure]``.

    ``vocab``: a :class:`slam_lcd.vocab.Vocabulary`, or None for the online (incremental)
    vocabulary. ``extractor``: a :class:`slam_lcd.features.Extractor` used when a keyframe
    arrives without features. ``run_all_checks``: run graph and RANSAC verification on every
    candidate whatever ``conf.verify`` is (evaluation compares the modes on one run).
    ``retrieval_depth``: keep, per query, the ids of the best ``max(top_k, retrieval_depth)``
    BoW candidates in ``detector.retrieved`` (evaluation's Recall@N of retrieval; only the
    first ``top_k`` are verified). 0: nothing kept.
    """

    def __init__(self, conf: LcdConfig | None = None, vocab=None, extractor=None, *, vocab_conf=None,
                 run_all_checks: bool = False, retrieval_depth: int = 0):
        self.conf = conf or LcdConfig()
        if self.conf.verify not in VERIFY_MODES:
            raise InputError(f"lcd.verify must be one of {list(VERIFY_MODES)}, got {self.conf.verify!r}")
        if self.conf.descriptor_dtype not in DESCRIPTOR_DTYPES:
            raise InputError(f"lcd.descriptor_dtype must be one of {list(DESCRIPTOR_DTYPES)}, "
                             f"got {self.conf.descriptor_dtype!r}")
        self._store = DescriptorStore(self.conf.descriptor_storage)
        self.db = BowDatabase(vocab, vocab_conf)
        self.extractor = extractor
        self.run_all_checks = run_all_checks
        self.retrieval_depth = int(retrieval_depth)
        self.retrieved: dict[int, list[int]] = {}  # query id -> BoW-ranked match ids (with retrieval_depth)
        self.records: list[CandidateRecord] = []
        self.last_part_seconds: dict[str, float] = {}  # seconds per part of the last add()
        self.closures: list[LoopClosure] = []
        self._entries: dict[int, StoredKeyframe] = {}
        self._temporal = TemporalConsistency(self.conf.temporal_k, self.conf.temporal_window)
        self._prior: tuple[int, int] | None = None  # (query position, match position) of the last full-threshold loop
        self._kind: str | None = None
        self._floor = 0  # position of the current session's first keyframe (:meth:`begin_session`)
        # sees each loop the detector hands on (a record with its graph's matches and kept rows) before
        # the arrays are dropped: the loop pictures draw exactly what was verified
        self.loop_sink: Callable[[CandidateRecord], None] | None = None

    def __len__(self) -> int:
        return len(self._entries)

    # ------------------------------------------------------------------ sessions (maps)
    def begin_session(self) -> None:
        """Keyframes added from now on are a new session of the same place (a multi-session map).

        Earlier keyframes stay candidates; what only makes sense within one recording starts
        afresh: the recent-keyframe exclusion, temporal consistency, the continuation of the
        previous keyframe's loop, the odometry distance (a loop to an earlier session has no
        odometry between its keyframes, so the odometry-drift check applies within a session only).
        """
        self._floor = len(self._entries)
        self.db.begin_session()
        self._temporal = TemporalConsistency(self.conf.temporal_k, self.conf.temporal_window)
        self._prior = None

    def in_current_session(self, kf_id: int) -> bool:
        """Was keyframe ``kf_id`` added in the current session (not remembered from an earlier one)?"""
        e = self._entries.get(int(kf_id))
        return e is not None and e.position >= self._floor

    def remember(self, kf: Keyframe, descriptors: np.ndarray, points3d: np.ndarray | None,
                 points_source: str = "none", bow=None) -> None:
        """Insert a keyframe of an earlier session as a candidate, without querying (loading a map).

        ``kf`` carries its keypoints (``kf.features``), camera, mounting and odometry pose;
        ``descriptors`` are its stored (compact) descriptors, or a
        :class:`~slam_lcd.lcd.store.DescriptorSource` that reads them when the keyframe is a
        candidate (with ``bow`` given: nothing is copied at load); ``points3d`` its camera-frame points
        per keypoint (NaN where unknown) from ``points_source``. The bag of words is made from
        the descriptors as :meth:`add` would, unless ``bow`` gives it (a
        :class:`~slam_lcd.vocab.BowVector` of this database's words: a map's vocabulary snapshot,
        restored into :attr:`db` first), which skips the vocabulary's replay.
        """
        if kf.id in self._entries:
            raise InputError(f"keyframe id {kf.id} was already added to the loop detector")
        feats = kf.features
        if feats is None:
            raise InputError(f"keyframe {kf.id} comes without its keypoints (Keyframe.features)")
        if self._kind is None:
            self._kind = feats.kind
        elif feats.kind != self._kind:
            raise InputError(f"keyframe {kf.id} has {feats.kind} features but the detector holds {self._kind}")
        source = descriptors if isinstance(descriptors, DescriptorSource) else None
        if source is not None and bow is None:  # the vocabulary needs them now
            descriptors, source = source.load(), None
        dtype = self.conf.descriptor_dtype
        desc = (np.zeros((0, source.dim), np.dtype(dtype)) if source is not None
                else compact_descriptors(descriptors, dtype))
        kept = Features(keypoints=np.asarray(feats.keypoints, np.float32), scores=np.zeros(0, np.float32),
                        descriptors=np.zeros((0,) + desc.shape[1:], desc.dtype), image_size=feats.image_size,
                        kind=feats.kind)
        points3d = None if points3d is None else np.ascontiguousarray(points3d, dtype=np.float32)
        camera = self._camera(kf, feats)
        light = Keyframe(id=kf.id, stamp=kf.stamp, T_world_body=np.array(kf.T_world_body, float), camera=camera,
                         T_body_camera=np.array(kf.T_body_camera, float), features=kept,
                         landmarks=points3d if points_source == "landmarks" else None)
        entry = StoredKeyframe(kf.id, int(kf.stamp), len(self._entries), kept, camera, light.T_body_camera, points3d,
                       points_source if points3d is not None else "none", light, self._path_to(kf))
        if bow is None:  # (with a bow the float copy is not needed: ~0.25 ms a keyframe)
            self.db.add(kf.id, int(kf.stamp), desc if desc.dtype == np.uint8 else np.asarray(desc, np.float32))
        else:
            self.db.add_bow(kf.id, int(kf.stamp), bow)
        if source is not None:
            self._store.put_source(kf.id, partial(compact_loaded, source.load, dtype))
        else:
            self._store.put(kf.id, desc)
        self._entries[kf.id] = entry

    def verify_pair(self, query_id: int, match_id: int) -> LoopClosure | None:
        """Verify two kept keyframes directly (no BoW query), with the loop chain; the closure or None.

        Why: a map links consecutive keyframes of a session by their visual relative pose
        (metric, from the 3-D points), which is far less biased than wheel odometry over a
        session (``slam_lcd.map``). Not recorded in :attr:`records`.
        """
        q = self._entries[int(query_id)]
        # RANSAC and the metric pose only: two consecutive keyframes are no look-alike-place question, and
        # the graph check would cost most of the time on their ~1000 matches
        conf = dataclasses.replace(self.conf, verify="ransac")
        rec = self._verify_with(conf, q, self._store.get(q.id), LoopCandidate(q.id, int(match_id), 1.0), 0)
        if not rec.accepted or rec.pose is None or not rec.pose.ok:
            return None
        return self._closure(rec)

    def stored(self, kf_id: int):
        """What the detector keeps of keyframe ``kf_id``: (light keyframe, compact descriptors, 3-D points, source)."""
        e = self._entries[int(kf_id)]
        return e.keyframe, self._store.get(e.id), e.points3d, e.points_source

    # ------------------------------------------------------------------ helpers
    def _features(self, kf: Keyframe) -> Features:
        if kf.features is not None:
            return kf.features
        if kf.image is None:
            raise InputError(f"keyframe {kf.id} has neither features nor an image")
        if self.extractor is None:
            self.extractor = load_extractor()
        kf.features = self.extractor.extract(kf.image)
        return kf.features

    def _match(self, dq: np.ndarray, dm: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """One-to-one matches, distances and symmetric ratios (None when no ratio test is on;
        ``mutual_nn_match_symmetric``)."""
        c = self.conf
        binary = dq.dtype == np.uint8
        max_d = c.match_max_distance_orb if binary else c.match_max_distance_sp
        return mutual_nn_match_symmetric(dq, dm, max_distance=max_d,
                                         with_ratios=c.match_ratio is not None or c.graph_match_ratio is not None)

    def memory_bytes(self) -> dict[str, int]:
        """Bytes the detector holds for its past keyframes: descriptors (RAM / file) and the rest."""
        return {
            "keyframes": len(self._entries),
            "descriptors_resident": self._store.resident_bytes(),
            "descriptors_file": self._store.file_bytes(),
            "entries": sum(e.nbytes() for e in self._entries.values()),
        }

    def close(self) -> None:
        """Release the descriptor store's temporary file (``lcd.descriptor_storage = 'disk'``)."""
        self._store.close()

    def _camera(self, kf: Keyframe, feats: Features) -> CameraModel:
        if kf.camera is not None:
            return kf.camera
        w, h = feats.image_size
        return default_camera(w, h, self.conf.default_focal_factor)

    # ------------------------------------------------------------------ main entry
    def add(self, kf: Keyframe, *, insert: bool = True) -> list[LoopClosure]:
        """Query the database with ``kf``, verify its candidates, then insert it; returns accepted loops.

        ``insert=False`` only queries and verifies (localisation against a fixed map): ``kf``
        is not kept and later keyframes cannot match it.
        """
        if kf.id in self._entries:
            raise InputError(f"keyframe id {kf.id} was already added to the loop detector")
        check_user_keyframe(kf)
        clock = PartClock()
        feats = self._features(kf)
        clock.lap("features")
        if self._kind is None:
            self._kind = feats.kind
        elif feats.kind != self._kind:
            raise InputError(f"keyframe {kf.id} has {feats.kind} features but the detector holds {self._kind}")
        camera = self._camera(kf, feats)
        c = self.conf
        points3d, source = (None, "none")
        if c.pose and kf.camera is not None:
            points3d, source = keyframe_points3d(kf, c)
        points3d = None if points3d is None else np.ascontiguousarray(points3d, dtype=np.float32)
        landmarks = points3d if source == "landmarks" else (
            None if kf.landmarks is None else np.ascontiguousarray(kf.landmarks, dtype=np.float32))
        position = len(self._entries)
        path_m = self._path_to(kf)
        # the query is matched with the same compact descriptors it is stored with (symmetric pairs)
        desc = compact_descriptors(feats.descriptors, c.descriptor_dtype)
        # own small copies: views would keep the caller's larger arrays alive
        kept = Features(keypoints=np.array(feats.keypoints), scores=np.zeros(0, np.float32),
                        descriptors=np.zeros((0,) + desc.shape[1:], desc.dtype), image_size=feats.image_size,
                        kind=feats.kind)
        light = Keyframe(id=kf.id, stamp=kf.stamp, T_world_body=np.array(kf.T_world_body, float), camera=camera,
                         T_body_camera=np.array(kf.T_body_camera, float), features=kept,
                         landmarks=landmarks)
        entry = StoredKeyframe(kf.id, int(kf.stamp), position, kept, camera, light.T_body_camera, points3d, source,
                               light, path_m)
        clock.lap("points3d")

        closures: list[LoopClosure] = []
        candidates = []
        if len(self.db) and len(feats):
            depth = max(c.top_k, self.retrieval_depth, c.island_pool if c.islands else 0)
            candidates = self.db.query(
                feats.descriptors, top_k=depth, exclude_recent_s=c.exclude_recent_s,
                exclude_recent_n=c.exclude_recent_n, query_id=kf.id, stamp_ns=int(kf.stamp),
            )
        if self.retrieval_depth > 0:
            self.retrieved[kf.id] = [cand.match_id for cand in candidates[:max(c.top_k, self.retrieval_depth)]]
        clock.lap("bow_query")
        records = self._verify_candidates(entry, desc, candidates, clock)
        self.records.extend(records)

        accepted = [r for r in records if r.accepted]
        # the candidate with the most verified correspondences (ties: higher BoW score)
        best = max(accepted, key=lambda r: (r.support(c.verify), r.bow_score)) if accepted else None
        for r in accepted:
            if r is not best:
                r.accepted, r.reason = False, "not_best"
        ok, run = self._temporal.update(position, None if best is None else self._entries[best.match_id].position)
        if best is not None:
            if not ok:
                best.accepted, best.reason = False, f"temporal_pending({run}/{c.temporal_k})"
            else:
                closures.append(self._closure(best))
        strong = best is not None and best.accepted and not best.relaxed
        self._prior = (position, self._entries[best.match_id].position) if best is not None and strong else None
        self.closures.extend(closures)
        if self.loop_sink is not None and closures and best is not None:  # closures holds best's loop
            self.loop_sink(best)
        for r in records:
            drop_arrays(r)
        clock.lap("decision")
        if not insert:
            self.last_part_seconds = clock.seconds
            return closures
        self.db.add(kf.id, int(kf.stamp), feats.descriptors)
        clock.lap("bow_add")
        self._store.put(kf.id, desc)
        self._entries[kf.id] = entry
        clock.lap("store")
        self.last_part_seconds = clock.seconds
        return closures

    def _path_to(self, kf: Keyframe) -> float:
        """Odometry distance from the first keyframe to ``kf`` (a non-finite step counts as none)."""
        if len(self._entries) <= self._floor:
            return 0.0  # the session's first keyframe
        last = next(reversed(self._entries.values()))
        step = float(np.linalg.norm(np.asarray(kf.T_world_body, float)[:3, 3] - last.keyframe.T_world_body[:3, 3]))
        return last.path_m + (step if np.isfinite(step) else 0.0)

    def _verification_order(self, candidates) -> list[IslandMember]:
        positions = {cand.match_id: self._entries[cand.match_id].position for cand in candidates}
        return verification_order(candidates, positions, self.conf)

    def _verify_candidates(
        self, entry: StoredKeyframe, desc: np.ndarray, candidates, clock: PartClock
    ) -> list[CandidateRecord]:
        """Verify a query's candidates; stops at the first accepted one when ``verify_until`` says so.

        With islands, an island whose member was accepted verifies none of its other members
        (whatever ``verify_until``): they are neighbours of a loop already found.
        """
        c = self.conf
        records: list[CandidateRecord] = []
        stop = stops_at_first_accepted(c) and not self.run_all_checks
        done_islands: set[int] = set()
        for member in self._verification_order(candidates):
            cand, rank = member.candidate, member.rank
            if ((stop and any(r.accepted for r in records))
                    or (member.island in done_islands and not self.run_all_checks)):
                # bounded work per keyframe: the BoW ranking already put the likeliest first
                records.append(CandidateRecord(entry.id, cand.match_id, rank, float(cand.bow_score),
                                               reason="skipped_after_accept", query_stamp=entry.stamp,
                                               match_stamp=self._entries[cand.match_id].stamp))
                continue
            rec = self._verify(entry, desc, cand, rank, clock, relax=self._continues_prior(entry, cand.match_id))
            if rec.accepted:
                done_islands.add(member.island)
            records.append(rec)
        return records

    def _continues_prior(self, q: StoredKeyframe, match_id: int) -> bool:
        """Does (q, match) continue the previous keyframe's full-threshold loop (``lcd.consistent_*``)?"""
        c, prior = self.conf, self._prior
        if c.consistent_min_matches <= 0 or prior is None or prior[0] != q.position - 1:
            return False
        return abs(self._entries[match_id].position - prior[1]) <= c.consistent_window

    def _verify(self, q: StoredKeyframe, q_desc: np.ndarray, cand, rank: int, clock: PartClock | None = None,
                relax: bool = False) -> CandidateRecord:
        rec = self._verify_with(self.conf, q, q_desc, cand, rank, clock)
        if relax and not rec.accepted and failed_on_a_count(rec):
            k = self.conf.consistent_min_matches
            low = dataclasses.replace(self.conf, graph_min_matches=min(k, self.conf.graph_min_matches),
                                      graph_min_nodes=min(k, self.conf.graph_min_nodes),
                                      ransac_min_inliers=min(k, self.conf.ransac_min_inliers))
            rec = self._verify_with(low, q, q_desc, cand, rank, clock)
            rec.relaxed = True
        return rec

    def _verify_with(self, c: LcdConfig, q: StoredKeyframe, q_desc: np.ndarray, cand, rank: int,
                     clock: PartClock | None = None) -> CandidateRecord:
        clock = clock or PartClock()
        m = self._entries[cand.match_id]
        return verify_candidate(c, q, q_desc, m, self._store, cand, rank, clock, run_all_checks=self.run_all_checks,
                                match=self._match, same_session=m.position >= self._floor)

    def _closure(self, r: CandidateRecord) -> LoopClosure:
        return loop_closure(r, self.conf.verify, inter_session=not self.in_current_session(r.match_id))
