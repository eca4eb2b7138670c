"""A TF buffer: answers ``T_parent_child(stamp)`` through chains of static and dynamic transforms.

Each edge of the frame tree (parent -> child, as published) is either static (one
transform, valid at all times) or dynamic (a time series, interpolated: translation
linearly, rotation by slerp). A lookup walks the tree between the two frames in either
direction (inverting edges walked child -> parent), like tf2's ``lookupTransform``.
Outside a dynamic edge's time range a lookup fails, unless within ``extrapolation_ns``
(then the nearest sample is used).
"""
from __future__ import annotations

import math
from collections import deque
from pathlib import Path

import numpy as np

from ..errors import InputError, InvalidPoseError
from ..geometry import inv, quat_slerp, quat_to_rot
from .decode import transform_to_matrix
from .reader import LogReader, open_log
from .transforms import checked_quat, tq_from_pose


class TfLookupError(InputError):
    """A transform that the buffer cannot answer (unknown frame, no chain, stamp out of range)."""


class _Edge:
    __slots__ = ("parent", "child", "static", "T", "_stamps", "_t", "_q", "_pending")

    def __init__(self, parent: str, child: str, static: bool):
        self.parent, self.child, self.static = parent, child, static
        self.T: np.ndarray | None = None  # a static edge's transform
        self._pending: list[tuple[int, tuple, tuple]] = []
        self._stamps = np.zeros(0, np.int64)
        self._t = np.zeros((0, 3))
        self._q = np.zeros((0, 4))

    def add(self, stamp: int, t, q):
        self._pending.append((stamp, t, q))

    def arrays(self):
        if self._pending:
            st = np.array([p[0] for p in self._pending], np.int64)
            tt = np.array([p[1] for p in self._pending], np.float64).reshape(-1, 3)
            qq = np.array([p[2] for p in self._pending], np.float64).reshape(-1, 4)
            self._pending = []
            st = np.concatenate([self._stamps, st])
            tt = np.concatenate([self._t, tt])
            qq = np.concatenate([self._q, qq])
            order = np.argsort(st, kind="stable")
            st, tt, qq = st[order], tt[order], qq[order]
            keep = np.ones(len(st), bool)
            keep[:-1] = st[1:] != st[:-1]  # the later sample of duplicate stamps wins
            self._stamps, self._t, self._q = st[keep], tt[keep], qq[keep]
        return self._stamps, self._t, self._q

    def at(self, stamp: int, tol: int) -> np.ndarray:
        if self.static:
            assert self.T is not None  # add_transform sets it with the static flag
            return self.T
        st, tt, qq = self.arrays()
        i = int(np.searchsorted(st, stamp))
        if i < len(st) and st[i] == stamp:
            t, q = tt[i], qq[i]
        elif 0 < i < len(st):
            a = (stamp - st[i - 1]) / (st[i] - st[i - 1])
            t = tt[i - 1] + a * (tt[i] - tt[i - 1])
            q = quat_slerp(qq[i - 1], qq[i], a)
        elif i == 0 and st[0] - stamp <= tol:
            t, q = tt[0], qq[0]
        elif i == len(st) and stamp - st[-1] <= tol:
            t, q = tt[-1], qq[-1]
        else:
            raise TfLookupError(
                f"transform {self.parent} -> {self.child} is known from {st[0]} to {st[-1]} ns, not at {stamp} ns"
            )
        T = np.eye(4)
        T[:3, :3] = quat_to_rot(q)
        T[:3, 3] = t
        return T


class TfBuffer:
    """Static and dynamic transforms of a log; ``lookup(parent, child, stamp_ns) -> T_parent_child``."""

    def __init__(self, extrapolation_ns: int = 0):
        self.extrapolation_ns = int(extrapolation_ns)
        self.edges: dict[tuple[str, str], _Edge] = {}
        self._adj: dict[str, set[str]] = {}
        self._parent_of: dict[str, str] = {}

    # -- filling ----------------------------------------------------------------------
    def add(self, msg, static: bool = False) -> None:
        """Add a tf2_msgs/TFMessage (or one TransformStamped) from /tf (static=False) or /tf_static."""
        transforms = msg.transforms if hasattr(msg, "transforms") else [msg]
        for ts in transforms:
            parent = ts.header.frame_id.lstrip("/")
            child = ts.child_frame_id.lstrip("/")
            stamp = int(ts.header.stamp.sec) * 1_000_000_000 + int(ts.header.stamp.nanosec)
            if static:
                self.add_transform(transform_to_matrix(ts.transform, f"transform {parent} -> {child}"), stamp, parent,
                                   child, True)
                continue
            tr, ro = ts.transform.translation, ts.transform.rotation
            t = (float(tr.x), float(tr.y), float(tr.z))
            if not all(map(math.isfinite, t)):
                raise InvalidPoseError(f"transform {parent} -> {child} at {stamp} ns has NaN/inf translation")
            q = checked_quat(float(ro.x), float(ro.y), float(ro.z), float(ro.w),
                             f"transform {parent} -> {child} rotation")
            self._edge(parent, child, False).add(stamp, t, q)

    def _edge(self, parent: str, child: str, static: bool) -> _Edge:
        key = (parent, child)
        edge = self.edges.get(key)
        if edge is None:
            old = self._parent_of.get(child)
            if old is not None and old != parent:
                raise TfLookupError(f"frame {child!r} has two parents: {old!r} and {parent!r}")
            edge = self.edges[key] = _Edge(parent, child, static)
            self._adj.setdefault(parent, set()).add(child)
            self._adj.setdefault(child, set()).add(parent)
            self._parent_of[child] = parent
        return edge

    def add_transform(self, T: np.ndarray, stamp_ns: int, parent: str, child: str, static: bool = False) -> None:
        """Add one 4x4 ``T_parent_child`` (static: valid at all times)."""
        edge = self._edge(parent, child, static)
        if static or edge.static:
            edge.static = True
            edge.T = np.asarray(T, dtype=np.float64)
        else:
            t, q = tq_from_pose(T, f"transform {parent} -> {child}")
            edge.add(int(stamp_ns), t, q)

    @classmethod
    def from_log(cls, source, tf_topics=("/tf",), static_topics=("/tf_static",), extrapolation_ns: int = 0) -> TfBuffer:
        """Buffer filled from an open LogReader or a path (topics that the log lacks are skipped)."""
        buf = cls(extrapolation_ns)
        own = not isinstance(source, LogReader)
        reader = open_log(source) if own else source
        try:
            present = reader.topics
            wanted = [t for t in (*tf_topics, *static_topics) if t in present or t.lstrip("/") in present]
            if not wanted:
                raise TfLookupError(f"log has none of the TF topics {list(tf_topics) + list(static_topics)}",
                                    reader.path)
            statics = {t.lstrip("/") for t in static_topics}
            for m in reader.messages(wanted):
                buf.add(m.msg, static=m.topic.lstrip("/") in statics)
        finally:
            if own:
                reader.close()
        return buf

    # -- queries ----------------------------------------------------------------------
    @property
    def frames(self) -> list[str]:
        return sorted(self._adj)

    def chain(self, parent: str, child: str) -> list[tuple[_Edge, bool]]:
        """Edges from ``parent`` to ``child`` as (edge, forward) pairs; forward = walked parent->child."""
        parent, child = parent.lstrip("/"), child.lstrip("/")
        for f in (parent, child):
            if f not in self._adj:
                raise TfLookupError(f"frame {f!r} is not in the TF tree; frames: {', '.join(self.frames) or '(none)'}")
        prev: dict[str, str | None] = {parent: None}
        todo = deque([parent])
        while todo:
            f = todo.popleft()
            if f == child:
                break
            for g in sorted(self._adj[f]):
                if g not in prev:
                    prev[g] = f
                    todo.append(g)
        if child not in prev:
            raise TfLookupError(f"frames {parent!r} and {child!r} are not connected in the TF tree")
        path = []
        f = child
        p = prev[f]
        while p is not None:
            if (p, f) in self.edges:
                path.append((self.edges[(p, f)], True))
            else:
                path.append((self.edges[(f, p)], False))
            f = p
            p = prev[f]
        return path[::-1]

    def lookup(self, parent: str, child: str, stamp_ns: int) -> np.ndarray:
        """``T_parent_child`` at ``stamp_ns`` (maps points of ``child`` into ``parent``)."""
        T = np.eye(4)
        for edge, forward in self.chain(parent, child):
            E = edge.at(int(stamp_ns), self.extrapolation_ns)
            T = T @ (E if forward else inv(E))
        return T

    def stamps(self, parent: str, child: str) -> np.ndarray:
        """Stamps at which the chain can be looked up without extrapolation: those of its densest
        dynamic edge, inside the time range every dynamic edge covers (empty chain of statics -> [])."""
        dyn = [e for e, _ in self.chain(parent, child) if not e.static]
        if not dyn:
            return np.zeros(0, np.int64)
        arrays = [e.arrays()[0] for e in dyn]
        lo = max(a[0] for a in arrays) - self.extrapolation_ns
        hi = min(a[-1] for a in arrays) + self.extrapolation_ns
        densest = max(arrays, key=len)
        return densest[(densest >= lo) & (densest <= hi)]

    def __repr__(self):
        n_static = sum(e.static for e in self.edges.values())
        return f"TfBuffer({len(self._adj)} frames, {n_static} static and {len(self.edges) - n_static} dynamic edges)"


def load_tf(path: str | Path, extrapolation_ns: int = 0) -> TfBuffer:
    return TfBuffer.from_log(path, extrapolation_ns=extrapolation_ns)
