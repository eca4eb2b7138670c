"""``Map``: a multi-session map in memory, read from and committed to a map folder.

Use (the pipeline takes a map the way it takes a user's iSAM2, as a collaborator)::

    m = Map.open("office_map", features=extractor_meta(extractor), write=True)  # lock held
    pipe = Pipeline(config, camera=camera, map=m)   # the map's keyframes become loop candidates
    ...                                             # feed odometry and frames as usual
    pipe.finalize()
    joined = m.add_session(pipe, name="tuesday", log_path="tuesday.bag")   # joint solve, in memory
    m.save()                                        # one atomic commit
    m.close()

``Map.open(path)`` without ``write`` only reads (``localize``): nothing in the folder changes.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO

import numpy as np

from ..types import Trajectory
from ..vocab.snapshot import keep_only, snapshot
from . import store
from .config import MapConfig
from .contents import kept_ids
from .detector_load import load_into
from .joint_graph import JointLoop, JointResult, SessionPoses, solve
from .keyframe_arrays import (
    LogHashes,
    camera_json,
    compact_for_map,
    extractor_meta,
    session_arrays,
    session_holding,
    visual_links,
)
from .lifelong import array_bytes, compact, count_folded, counts, fold_graph, reduce_append
from .localize import localise_pipeline
from .locks import WriterLock
from .pair_verdicts import judged_pairs, keep_pairs
from .session_graph import existing_loops, factor_graph, loop_arrays, odometry_independent, session_poses
from .store import LogAlreadyInMapError, MapError, MapGraph, MapManifest, SessionKeyframes, check_map_target, read_vocab

log = logging.getLogger(__name__)


READ_ATTEMPTS = 3  # a reader racing writers' commits reads the newest manifest again, this many times at most


@dataclass
class SessionSummary:
    name: str
    keyframes: int
    component: int
    inter_loops: int
    joined: bool


class Map:
    """A multi-session map (see module docstring). ``write=True`` holds the folder's writer lock."""

    def __init__(self, root: Path, manifest: MapManifest, sessions: list[SessionKeyframes], graph: MapGraph,
                 conf: MapConfig, lock=None):
        self.root = Path(root)
        self.manifest = manifest
        self.sessions = sessions
        self.graph = graph
        self.conf = conf
        self._lock = lock
        self._unsaved: list[tuple[dict, SessionKeyframes]] = []  # added, not committed yet
        self._generation_read = manifest.generation
        self.last_join: JointResult | None = None
        self._vocab: dict | None = None  # the vocabulary snapshot to save (add_session), None: none
        self._vocab_fh: BinaryIO | None = None  # a reader's snapshot file, opened with the manifest that names it
        self._log_sha256 = LogHashes()  # a log is hashed once
        self._rewritten: dict[str, SessionKeyframes] = {}  # sessions whose kept keyframes changed, not committed
        self._dirty = False  # changed without a new session (compacted), not committed

    # ------------------------------------------------------------------ open / close
    @classmethod
    def open(cls, root: str | Path, *, features: dict | None = None, conf: MapConfig | None = None,
             write: bool = False, create: bool = False) -> Map:
        """Read the map at ``root``. ``write``: take the writer lock first; ``create``: an absent map is empty.

        ``features`` (from :func:`extractor_meta`): refused with :class:`MapError` when the map holds
        another feature kind or other weights.
        """
        root = Path(root)
        conf = conf or MapConfig()
        lock = None
        if write:
            check_map_target(root, create=create)  # refused before the lock: the folder stays as it was
            lock = WriterLock(root, conf.lock_timeout_s).acquire()
        try:
            if not store.is_map(root):
                if not create:
                    raise MapError("no map here (no map.json)" if root.exists() else "no such map folder", root)
                if write:  # what a first append that never committed left behind (the lock is held)
                    store.remove_unfinished(root)
                    check_map_target(root, create=create)  # the folder may have changed while we waited
                if features is None:
                    raise MapError("a new map needs the feature kind it will hold", root)
                manifest = MapManifest(features=dict(features, descriptor_form=features.get("descriptor_form",
                                                                                               conf.descriptor_form)))
                m = cls(root, manifest, [], MapGraph.empty(), conf, lock)
            else:
                m = cls._read(root, conf, lock, write)
            if features is not None:
                m.check_features(features)
            return m
        except BaseException:
            if lock is not None:
                lock.release()
            raise

    @classmethod
    def _read(cls, root: Path, conf: MapConfig, lock, write: bool) -> Map:
        """The map as its manifest names it. A reader holds no lock: when a writer commits (and
        removes the generation the reader's manifest named) while it reads, it reads again."""
        for attempt in range(READ_ATTEMPTS):
            manifest = store.read_manifest(root)
            vocab_fh = None
            try:
                if not write and manifest.vocab_file is not None:
                    vocab_fh = store.open_listed(root, manifest, manifest.vocab_file)
                sessions = [store.read_session(root, manifest, i) for i in range(len(manifest.sessions))]
                graph = store.read_graph(root, manifest)
            except MapError as e:
                if vocab_fh is not None:
                    vocab_fh.close()
                if write or e.problem != store.MISSING or attempt == READ_ATTEMPTS - 1 \
                        or store.read_manifest(root).generation == manifest.generation:
                    raise
                continue
            m = cls(root, manifest, sessions, graph, conf, lock)
            m._vocab_fh = vocab_fh
            if write:
                store.remove_unlisted(root, manifest)  # a failed append's files
            return m
        raise AssertionError("unreachable")

    def close(self) -> None:
        if self._vocab_fh is not None:
            self._vocab_fh.close()
            self._vocab_fh = None
        if self._lock is not None:
            self._lock.release()
            self._lock = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def check_features(self, features: dict) -> None:
        have = self.manifest.features
        where = self.root / store.MANIFEST
        if have.get("kind") != features.get("kind"):
            raise MapError(f"the map holds {have.get('kind')} features, this run extracts {features.get('kind')}: "
                           "a map never mixes feature kinds (use --features "
                           f"{have.get('kind')} or another map)", where)
        if have.get("weights_sha256") != features.get("weights_sha256"):
            raise MapError(f"the map's SuperPoint weights have sha256 {str(have.get('weights_sha256'))[:12]}..., "
                           f"this run's {str(features.get('weights_sha256'))[:12]}...: a map never mixes weights "
                           "(give --weights with the map's file)", where)
        if int(have.get("descriptor_dim", 0)) != int(features.get("descriptor_dim", 0)):
            raise MapError(f"the map's descriptors have {have.get('descriptor_dim')} dimensions, this run's "
                           f"{features.get('descriptor_dim')}", where)

    # ------------------------------------------------------------------ contents
    @property
    def n_keyframes(self) -> int:
        return sum(len(s) for s in self.sessions)

    @property
    def session_names(self) -> list[str]:
        return [s["name"] for s in self.manifest.sessions]

    def session_of_log(self, log_path: str | Path, image_topic: str | None = None) -> str | None:
        """The name of the session recorded from this very log (same sha256), or None
        (:func:`~slam_lcd.map.keyframe_arrays.session_holding`: one rule for every way into a map)."""
        table = [s for s in self.manifest.sessions if s.get("log_sha256")]
        return session_holding(table, self._log_sha256(log_path), image_topic) if table else None

    def already_holds(self, log_path: str | Path, image_topic: str | None = None) -> str | None:
        """The one line that says ``log_path`` is skipped because the map holds it already, or None."""
        name = self.session_of_log(log_path, image_topic)
        if name is None:
            return None
        return (f"{log_path}: already in the map {self.root} as session {name!r} (same sha256"
                + (f", topic {image_topic}" if image_topic else "") + "): not appended again")

    def refuse_held(self, log_path: str | Path, image_topic: str | None = None) -> None:
        """Raise :class:`LogAlreadyInMapError` (naming the session) when the map holds this log already."""
        name = self.session_of_log(log_path, image_topic)
        if name is not None:
            raise LogAlreadyInMapError(self.already_holds(log_path, image_topic) or "", session=name)

    def next_kf_id(self) -> int:
        return self.manifest.next_kf_id()

    def poses(self) -> dict[int, np.ndarray]:
        return {int(k): T for k, T in zip(self.graph.kf_ids, self.graph.T_map, strict=True)}

    def session_trajectory(self, index: int, frame: str = "map") -> Trajectory:
        """Session ``index``'s keyframes in its component's frame (``frame='map'``) or its own odometry."""
        s = self.sessions[index]
        if frame == "odom":
            return Trajectory(s.stamps.copy(), s.T_odom.copy())
        P = self.poses()
        return Trajectory(s.stamps.copy(), np.array([P[int(k)] for k in s.ids]).reshape(-1, 4, 4))

    def components(self) -> list[list[str]]:
        comps: dict[int, list[str]] = {}
        for s in self.manifest.sessions:
            comps.setdefault(int(s["component"]), []).append(s["name"])
        return [comps[k] for k in sorted(comps)]

    def load_into(self, detector) -> None:
        """Give ``detector`` every keyframe of the map as a candidate (each session begins afresh).

        An empty online detector takes the map's vocabulary snapshot (words and bags of words as
        saved) when it holds exactly the map's keyframes in order; otherwise the stored
        descriptors are replayed through the vocabulary (a trained vocabulary always: its tree
        quantises cheaply). See :mod:`slam_lcd.map.detector_load`.
        """
        load_into(detector, self.root, self.manifest, self.sessions, self._vocab_fh)

    # ------------------------------------------------------------------ appending
    def add_session(self, pipeline, *, name: str | None = None, log_path: str | Path | None = None,
                    ground_truth: Trajectory | None = None, extra: dict | None = None) -> JointResult:
        """Take a finished pipeline's keyframes and loops as a new session; solve the joint graph (not saved yet)."""
        if self._lock is None:
            raise MapError("the map was opened read-only: open it with write=True to add a session", self.root)
        kfs = list(pipeline.keyframes)
        if not kfs:
            raise MapError(f"the session has no keyframe: nothing to add to the map {self.root}",
                           log_path or self.root)
        if log_path is not None:
            self.refuse_held(log_path, (extra or {}).get("image_topic"))
        sess = session_arrays(pipeline.detector, kfs, ground_truth,
                              self.manifest.features.get("descriptor_form", self.conf.descriptor_form))
        name = name or f"session{len(self.sessions) + 1}"
        names = set(self.session_names)
        base, n = name, 2
        while name in names:
            name, n = f"{base}_{n}", n + 1
        # this session's own corrected poses, its accepted loops; every inter-session loop offered
        own = pipeline.keyframe_trajectory()
        closures = {(int(c.query_id), int(c.match_id)): c for c in pipeline.closures}
        loops = existing_loops(self.sessions, self.graph)
        for rec in pipeline.loop_records:
            c = closures.get((rec.query_id, rec.match_id))
            if c is not None and rec.verdict == "accepted":
                loops.append(JointLoop(int(c.query_id), int(c.match_id), np.asarray(c.T_match_query, float),
                                       np.asarray(c.information, float), False, True, "ok"))
        if self.conf.visual_links:
            loops += visual_links(pipeline.detector, [k.id for k in kfs])
        for c in getattr(pipeline, "map_closures", []):
            loops.append(JointLoop(int(c.query_id), int(c.match_id), np.asarray(c.T_match_query, float),
                                   np.asarray(c.information, float), True, False, ""))
        sess.T_own = np.asarray(own.poses, float).reshape(-1, 4, 4)
        sessions = session_poses(self.manifest.sessions, self.sessions, self.poses(), loops, self.conf,
                                 self.graph.folded_ids())
        sessions.append(SessionPoses(name, sess.ids, sess.T_odom, sess.cov, sess.T_own, None,
                                     odometry_independent=odometry_independent(extra or {}),
                                     cov_modelled=sess.cov_modelled(), T_own=sess.T_own))
        result = solve(sessions, loops, self.conf, judged=judged_pairs(self.manifest.sessions))
        self.last_join = result
        ids = np.array([k for s in sessions for k in s.ids], np.int64)
        graph = MapGraph(kf_ids=ids, T_map=np.array([result.poses[int(k)] for k in ids]).reshape(-1, 4, 4),
                         **loop_arrays(loops), kf_folded=np.isin(ids, list(self.graph.folded_ids())))
        cam = getattr(pipeline, "camera", None)
        meta = {"name": name, "keyframes": len(sess), "kf_id_start": int(sess.ids.min()),
                "kf_id_end": int(sess.ids.max()) + 1, "stamps": [int(sess.stamps[0]), int(sess.stamps[-1])],
                "log_path": str(Path(log_path).resolve()) if log_path else None,
                "log_sha256": self._log_sha256(log_path) if log_path else None,
                "camera": camera_json(cam), "T_body_camera": np.asarray(pipeline.T_body_camera, float).tolist(),
                "features": self.manifest.features.get("kind"), "T_map_session": np.eye(4).tolist(),
                "component": 0, **(extra or {})}
        expected = np.concatenate([kept_ids(self.sessions), sess.ids])  # the detector's keyframes
        if self.conf.lifelong:  # keep places and variants, not every keyframe (slam_lcd.map.lifelong)
            table = [dict(m) for m in self.manifest.sessions]
            after, changed, graph = reduce_append(table, self.sessions, self.graph, graph, result, meta, sess, loops,
                                                  self.conf, getattr(pipeline.detector, "conf", None))
            sess = after[-1]
            for i in changed - {len(self.sessions)}:
                self._rewritten[table[i]["name"]] = after[i]
            self.sessions = after[:-1]
            graph, folded = fold_graph([*table, meta], after, graph, self.conf)
            count_folded(result.pairs, folded.by_pair)
        # the in-memory map follows at once (a second session may be added before saving)
        self._apply(meta, sess, graph, result)
        self._vocab = self._vocab_snapshot(pipeline.detector, expected)
        meta.update(map_keyframes_after=self.n_keyframes,  # the map's growth over sessions (map info)
                    map_kept_after=int(sum(s.kept().sum() for s in self.sessions)),
                    map_bytes_after=array_bytes(self.sessions, self.graph, self._vocab))
        return result

    def _apply(self, meta, sess, graph, result) -> None:
        metas = [dict(m) for m in self.manifest.sessions] + [meta]
        for m in metas:
            m["component"] = int(result.component[m["name"]])
            m["T_map_session"] = np.asarray(result.anchors[m["name"]], float).tolist()
        keep_pairs(metas, result)
        self.sessions = self.sessions + [sess]
        self.graph = graph
        self._unsaved.append((meta, sess))
        self.manifest = MapManifest(self.manifest.features, metas, self.manifest.graph_file, self.manifest.vocab_file,
                                    self.manifest.files, self.manifest.created, self.manifest.updated,
                                    self.manifest.generation)

    def _vocab_snapshot(self, detector, expected: np.ndarray | None = None) -> dict | None:
        """The detector's online vocabulary and bags of words when its keyframes are ``expected`` (default: the
        map's kept ones; after an append, those before it and the new session's), in order; pruned to the
        keyframes the map keeps now."""
        kept = kept_ids(self.sessions)
        expected = kept if expected is None else expected
        state = snapshot(detector.db, self.conf.vocab_centres)
        if state is None or not np.array_equal(state["kf_ids"], expected):
            return None
        return state if len(kept) == len(expected) else keep_only(state, kept)

    def compact(self, lcd_conf=None) -> dict:
        """Keep places and variants, not every keyframe (in memory: :meth:`save` commits it); a map that keeps
        places already keeps its records (:func:`slam_lcd.map.lifelong.compact`); ``lcd_conf``: the loop
        chain's settings whose pose stage says whether a kept view would localise another (default ones).
        Returns the map's counts (:func:`slam_lcd.map.lifelong.counts`) before and after."""
        if self._lock is None:
            raise MapError("the map was opened read-only: open it with write=True to compact it", self.root)

        before = counts(self.graph, self.sessions)
        after, changed, graph = compact(self.manifest.sessions, self.sessions, self.graph, self.poses(),
                                        existing_loops(self.sessions, self.graph), self.conf, lcd_conf)
        state = read_vocab(self.root, self.manifest) if self.manifest.vocab_file else None
        graph, folded = fold_graph(self.manifest.sessions, after, graph, self.conf)
        count_folded([r for m in self.manifest.sessions for r in m.get("pairs", [])], folded.by_pair)
        self.sessions, self.graph = after, graph
        self._rewritten.update({self.manifest.sessions[i]["name"]: after[i] for i in changed})
        self._vocab = keep_only(state, kept_ids(self.sessions)) if state is not None else None
        self._dirty = True
        return {"before": before, "after": counts(self.graph, self.sessions)}

    def save(self) -> None:
        """Commit the sessions added (or the map compacted) since the last save: one atomic step (the manifest's
        rename)."""
        if self._lock is None:
            raise MapError("the map was opened read-only", self.root)
        if not self._unsaved and not self._dirty:
            return
        on_disk = store.read_manifest(self.root) if store.is_map(self.root) else MapManifest(self.manifest.features)
        if on_disk.generation != self._generation_read:
            raise MapError("the map changed on disk since it was opened (another writer?): nothing saved", self.root)
        self.manifest = store.commit(self.root, on_disk, self._unsaved, self.graph, self.manifest.sessions,
                                     self._vocab, lock=self._lock, rewritten=self._rewritten)
        self._rewritten, self._dirty = {}, False
        self._generation_read = self.manifest.generation
        self._unsaved = []

    # ------------------------------------------------------------------ for a user's own pipeline / graph
    def loop_detector(self, lcd_conf=None, vocab_conf=None, extractor=None):
        """A :class:`~slam_lcd.lcd.LoopDetector` holding every keyframe of the map as a candidate.

        Query it with ``detector.add(keyframe, insert=False)`` (the keyframe's id must not be one
        of the map's: take ids from :meth:`next_kf_id` on; ``extractor`` extracts the features of a
        keyframe that comes without them): the verified matches come back as
        ``LoopClosure`` with ``match_id`` a map keyframe, ``T_match_query`` and ``information``.
        """
        from ..lcd import LoopDetector  # lazy: OpenCV (`slam-lcd map info` needs none)

        det = LoopDetector(lcd_conf, extractor=extractor, vocab_conf=vocab_conf)
        self.load_into(det)
        det.begin_session()
        return det

    def factor_graph(self, key=None):
        """(``gtsam.NonlinearFactorGraph``, ``gtsam.Values``): the map's joint graph for a user's own optimiser.

        Odometry steps of every session, accepted loops within and between sessions and the
        visual links, as ``BetweenFactorPose3``; values at the map's poses; ``key(kf_id) -> gtsam
        key`` (default: the keyframe id). No prior: the user fixes the gauge (e.g. a prior on
        one keyframe, or their own absolute factors).
        """
        return factor_graph(self.manifest.sessions, self.sessions, self.graph, self.poses(), key, self.conf)

    # ------------------------------------------------------------------ localisation
    def localise(self, pipeline):
        """Map-frame poses of a finished pipeline's keyframes from its matches to the map (the map is not changed)."""
        return localise_pipeline(self, pipeline)


__all__ = ["Map", "MapError", "compact_for_map", "extractor_meta"]
