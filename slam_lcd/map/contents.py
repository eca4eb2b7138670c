"""What a map holds, as arrays and a table: each session's keyframes, the joint graph, the manifest.

The map folder (:mod:`slam_lcd.map.store`) writes and reads these; :class:`MapError` is what a
folder that cannot be used raises (one line naming the file and the problem).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import InputError

SCHEMA = 1
MANIFEST = "map.json"
LOCK = ".lock"
FORMAT_NAME = "slam-lcd map"


class MapError(InputError):
    """A map folder that cannot be used: missing, damaged, of another schema or another feature kind."""


MISSING = "map file missing"
REMOVED = "removed"  # points_source of a keyframe whose descriptors, keypoints and points the map dropped


class MapLockedError(MapError):
    """Another process is writing the map."""


class LogAlreadyInMapError(MapError):
    """The log (same bytes, same camera topic) is a session of the map already; ``session`` names it."""

    def __init__(self, message: str, path=None, session: str = ""):
        self.session = session
        super().__init__(message, path)


@dataclass
class SessionKeyframes:
    """One session's keyframes as the map keeps them (arrays; keypoint rows concatenated).

    ``offsets[i]:offsets[i+1]`` are keyframe i's rows of ``keypoints``, ``descriptors``,
    ``scales`` (int8 descriptors: value = int8 / scale; int4: two values a byte, high nibble
    first, value = (nibble - 8) / scale; empty for float16 and ORB's bytes) and ``points3d``
    (camera frame, NaN where unknown). Poses: ``T_odom`` in the session's own odometry frame,
    ``T_gt`` ground truth at the keyframe stamps where the run had it (NaN otherwise; only for
    evaluation), ``cov`` the odometry covariance since the previous keyframe (NaN: none) and
    ``cov_source`` where it came from: ``"given"`` by the log's odometry or ``"model"`` (the front
    end's motion model, which the map replaces by its per-metre allowance). A map written before
    the map recorded it has no ``cov_source``: its covariances read as given, so it joins and
    solves as it did when it was written.
    """

    ids: np.ndarray  # (n,) int64, unique in the map
    stamps: np.ndarray  # (n,) int64 ns
    T_odom: np.ndarray  # (n, 4, 4)
    cov: np.ndarray  # (n, 6, 6)
    T_gt: np.ndarray  # (n, 4, 4)
    offsets: np.ndarray  # (n + 1,) int64
    keypoints: np.ndarray  # (K, 2) float32
    descriptors: np.ndarray  # (K, D) int8 / float16 / uint8 (ORB), or (K, D/2) uint8 with scales (int4)
    scales: np.ndarray  # (K,) float32 for int8 and int4, else (0,)
    points3d: np.ndarray  # (K, 3) float32
    points_source: np.ndarray  # (n,) str: rgbd | stereo | landmarks | none
    cov_source: np.ndarray | None = None  # (n,) str: given | model; None: not recorded (read as given)
    # (n, 4, 4) the session's own estimate (odometry corrected by its own loops, its odometry frame), what the
    # pair verdicts read; None: not recorded (computed from the odometry and the session's own loops)
    T_own: np.ndarray | None = None

    ARRAYS = ("ids", "stamps", "T_odom", "cov", "T_gt", "offsets", "keypoints", "descriptors", "scales",
              "points3d", "points_source")
    OPTIONAL = ("cov_source", "T_own")

    def arrays(self) -> dict[str, np.ndarray]:
        """Every array to write (the optional ones where present)."""
        out = {k: getattr(self, k) for k in self.ARRAYS}
        out.update({k: getattr(self, k) for k in self.OPTIONAL if getattr(self, k) is not None})
        return out

    def cov_modelled(self) -> np.ndarray:
        """(n,) bool: which steps' covariances the front end modelled (none in a map that did not record it)."""
        if self.cov_source is None:
            return np.zeros(len(self.ids), bool)
        return np.asarray(self.cov_source) == "model"

    def __len__(self) -> int:
        return len(self.ids)

    def rows(self, i: int) -> slice:
        return slice(int(self.offsets[i]), int(self.offsets[i + 1]))

    def kept(self) -> np.ndarray:
        """Which keyframes the map keeps as candidates (the others keep only their pose: ``REMOVED``)."""
        return self.points_source != REMOVED

    def descriptors_of(self, i: int) -> np.ndarray:
        """Keyframe i's descriptors as the loop detector uses them (float32 unit rows, or ORB bytes)."""
        d = self.descriptors[self.rows(i)]
        if d.dtype == np.int8:
            return d.astype(np.float32) / self.scales[self.rows(i), None]
        if d.dtype == np.float16:
            return d.astype(np.float32)
        if len(self.scales):  # int4: bytes with a scale per row (ORB's bytes have none)
            q = np.empty((len(d), 2 * d.shape[1]), np.float32)
            q[:, 0::2], q[:, 1::2] = d >> 4, d & 15
            q -= 8.0
            n = np.linalg.norm(q, axis=1, keepdims=True)
            return q / np.where(n > 0, n, 1.0)
        return d

    def check(self, where: Path) -> None:
        n, K = len(self.ids), len(self.keypoints)
        ok = (self.stamps.shape == (n,) and self.T_odom.shape == (n, 4, 4) and self.cov.shape == (n, 6, 6)
              and self.T_gt.shape == (n, 4, 4) and self.offsets.shape == (n + 1,) and self.points_source.shape == (n,)
              and self.keypoints.shape == (K, 2) and len(self.descriptors) == K and self.points3d.shape == (K, 3)
              and (len(self.scales) in (0, K)) and n > 0 and int(self.offsets[0]) == 0 and int(self.offsets[-1]) == K
              and bool(np.all(np.diff(self.offsets) >= 0))
              and (self.cov_source is None or np.shape(self.cov_source) == (n,))
              and (self.T_own is None or np.shape(self.T_own) == (n, 4, 4)))
        if not ok:
            raise MapError("session file's arrays do not fit together (damaged or not written by slam-lcd)", where)
        if not np.all(np.isfinite(self.T_odom)) or (self.T_own is not None and not np.all(np.isfinite(self.T_own))):
            raise MapError("session file holds non-finite keyframe poses", where)


def kept_ids(sessions: list[SessionKeyframes]) -> np.ndarray:
    """The ids of the keyframes the map keeps as candidates (:meth:`SessionKeyframes.kept`), in map order."""
    return np.concatenate([s.ids[s.kept()] for s in sessions]) if sessions else np.zeros(0, np.int64)


@dataclass
class MapGraph:
    """Loops of every session (within and between) and the keyframes' poses in the map frame."""

    kf_ids: np.ndarray  # (N,) int64, every keyframe of the map
    T_map: np.ndarray  # (N, 4, 4) solved pose of each keyframe in its component's frame
    loop_query: np.ndarray  # (m,) int64
    loop_match: np.ndarray  # (m,) int64
    loop_T: np.ndarray  # (m, 4, 4) T_match_query
    loop_info: np.ndarray  # (m, 6, 6) information, GTSAM order
    loop_accepted: np.ndarray  # (m,) bool: in the graph (false: kept for the record, not used)
    loop_reason: np.ndarray  # (m,) str
    # a map that keeps places (map.lifelong): each keyframe's place (-1: not kept) and the generation
    # (sessions in the map) at which it was last matched or added; None: a map that keeps every keyframe
    kf_place: np.ndarray | None = None  # (N,) int64
    kf_last_used: np.ndarray | None = None  # (N,) int64
    # each kept keyframe's appearance (slam_lcd.map.places: sessions that look alike share one; -1: not
    # kept); None: a map without it, whose kept keyframes are all of one appearance
    kf_appearance: np.ndarray | None = None  # (N,) int64
    # the keyframes folded out of the joint graph (slam_lcd.map.fold: no variable, their factors marginalised
    # into "fold" loops; the pose is derived from their session's variables); None: none folded
    kf_folded: np.ndarray | None = None  # (N,) bool

    ARRAYS = ("kf_ids", "T_map", "loop_query", "loop_match", "loop_T", "loop_info", "loop_accepted", "loop_reason")
    OPTIONAL = ("kf_place", "kf_last_used", "kf_appearance", "kf_folded")

    def folded_ids(self) -> set[int]:
        """The ids of the keyframes folded out of the joint graph."""
        return set() if self.kf_folded is None else {int(k) for k in self.kf_ids[np.asarray(self.kf_folded, bool)]}

    def arrays(self) -> dict[str, np.ndarray]:
        """Every array to write (the optional ones where present), in the file's compact forms.

        Why compact: a map keeps a loop or visual link per keyframe of every visit, and as numpy's
        fixed-width text (4 bytes a character, 160 characters) a reason took 640 bytes, the information
        matrix 288: UTF-8 bytes as long as the longest reason, and the information in float32 (seven
        digits, more than a noise model needs), take a third of that. :meth:`from_file` reads both forms."""
        out = {k: getattr(self, k) for k in self.ARRAYS}
        out["loop_reason"] = np.char.encode(np.asarray(self.loop_reason, str), "utf-8") if len(self.loop_reason) \
            else np.zeros(0, "S1")
        out["loop_info"] = np.asarray(self.loop_info, np.float32)
        out.update({k: getattr(self, k) for k in self.OPTIONAL if getattr(self, k) is not None})
        return out

    @classmethod
    def from_file(cls, arrays: dict[str, np.ndarray]) -> MapGraph:
        """The graph of a file's arrays (:meth:`arrays`' compact forms, or the plain ones)."""
        a = dict(arrays)
        if a["loop_reason"].dtype.kind == "S":
            a["loop_reason"] = np.char.decode(a["loop_reason"], "utf-8")
        a["loop_info"] = np.asarray(a["loop_info"], float)
        return cls(**a)

    @classmethod
    def empty(cls) -> MapGraph:
        return cls(np.zeros(0, np.int64), np.zeros((0, 4, 4)), np.zeros(0, np.int64), np.zeros(0, np.int64),
                   np.zeros((0, 4, 4)), np.zeros((0, 6, 6)), np.zeros(0, bool), np.zeros(0, "<U8"))

    def check(self, where: Path) -> None:
        N, m = len(self.kf_ids), len(self.loop_query)
        ok = (self.T_map.shape == (N, 4, 4) and self.loop_match.shape == (m,) and self.loop_T.shape == (m, 4, 4)
              and self.loop_info.shape == (m, 6, 6) and self.loop_accepted.shape == (m,)
              and self.loop_reason.shape == (m,)
              and all(getattr(self, k) is None or getattr(self, k).shape == (N,) for k in self.OPTIONAL))
        if not ok:
            raise MapError("graph file's arrays do not fit together (damaged or not written by slam-lcd)", where)


@dataclass
class MapManifest:
    """``map.json``: the sessions table and the files that make the map now."""

    features: dict  # kind, weights_sha256, descriptor_dim, descriptor_form, vocabulary
    sessions: list[dict] = field(default_factory=list)
    graph_file: str | None = None
    vocab_file: str | None = None  # the online vocabulary's snapshot (absent: replayed when loaded)
    files: dict[str, dict] = field(default_factory=dict)  # relative name -> {"sha256", "bytes"}
    created: str = ""
    updated: str = ""
    generation: int = 0

    def to_json(self) -> dict:
        return {"format": FORMAT_NAME, "schema": SCHEMA, "created": self.created, "updated": self.updated,
                "generation": self.generation, "features": self.features, "sessions": self.sessions,
                "graph_file": self.graph_file, "vocab_file": self.vocab_file, "files": self.files}

    @property
    def n_keyframes(self) -> int:
        return sum(int(s["keyframes"]) for s in self.sessions)

    def next_kf_id(self) -> int:
        return max((int(s["kf_id_end"]) for s in self.sessions), default=0)
