"""On-disk feature cache, so a re-run of the pipeline does not recompute features.

One ``.npz`` per image under ``<root>/<extractor fingerprint>/<log key>/<topic key>/<stamp>.npz``:

- the extractor fingerprint hashes everything that changes the output (kind, thresholds,
  NMS radius, max keypoints, sampling mode, sha256 of the weights; ORB parameters and the
  OpenCV version) but not the device;
- the log key hashes the log's resolved path, size and modification time (for a rosbag2
  folder: of every file in it), so an edited or replaced log is never served stale features.

Files are written atomically and read with ``allow_pickle=False``; an unreadable entry is
treated as a miss and recomputed.
"""
from __future__ import annotations

import hashlib
import re
from pathlib import Path

import numpy as np

from ..atomic import atomic_path
from ..types import Features
from .extract import Extractor
from .weights import cache_dir


def log_key(log: str | Path) -> str:
    """Stable identity of a log file or rosbag2 folder: path + sizes + mtimes."""
    p = Path(log).resolve()
    h = hashlib.sha256(str(p).encode())
    if p.is_dir():
        for f in sorted(x for x in p.rglob("*") if x.is_file()):
            st = f.stat()
            h.update(f"{f.relative_to(p)}:{st.st_size}:{st.st_mtime_ns}".encode())
    elif p.exists():
        st = p.stat()
        h.update(f"{st.st_size}:{st.st_mtime_ns}".encode())
    return f"{re.sub(r'[^A-Za-z0-9_.-]', '_', p.name)[:40]}-{h.hexdigest()[:16]}"


def topic_key(topic: str) -> str:
    safe = re.sub(r"[^A-Za-z0-9_.-]", "_", topic.strip("/")) or "_"
    return f"{safe[:60]}-{hashlib.sha256(topic.encode()).hexdigest()[:8]}"


class FeatureCache:
    """Features of (log, topic, stamp) for one extractor configuration."""

    def __init__(self, extractor: Extractor, root: str | Path | None = None):
        self.extractor = extractor
        self.root = Path(root) if root is not None else cache_dir(extractor.conf.cache_dir) / "features"
        self.base = self.root / extractor.fingerprint
        self._log_keys: dict[str, str] = {}
        self.hits = 0
        self.misses = 0

    def path(self, log: str | Path, topic: str, stamp: int) -> Path:
        lk = self._log_keys.get(str(log))
        if lk is None:
            lk = self._log_keys[str(log)] = log_key(log)
        return self.base / lk / topic_key(topic) / f"{int(stamp)}.npz"

    def get(self, log: str | Path, topic: str, stamp: int) -> Features | None:
        p = self.path(log, topic, stamp)
        if not p.is_file():
            return None
        try:
            with np.load(p, allow_pickle=False) as z:
                w, h = (int(v) for v in z["image_size"])
                return Features(
                    keypoints=z["keypoints"].astype(np.float32),
                    scores=z["scores"].astype(np.float32),
                    descriptors=z["descriptors"],
                    image_size=(w, h),
                    kind=str(z["kind"]),
                )
        except Exception:  # truncated / foreign file: recompute and overwrite
            return None

    def put(self, log: str | Path, topic: str, stamp: int, feats: Features) -> Path:
        p = self.path(log, topic, stamp)
        with atomic_path(p) as tmp:
            with open(tmp, "wb") as fh:
                np.savez(
                    fh,
                    keypoints=feats.keypoints,
                    scores=feats.scores,
                    descriptors=feats.descriptors,
                    image_size=np.array(feats.image_size, np.int64),
                    kind=np.array(feats.kind),
                )
        return p

    def extract(self, log: str | Path, topic: str, stamp: int, image: np.ndarray) -> Features:
        """Cached features if present, else extract and store them."""
        f = self.get(log, topic, stamp)
        if f is not None:
            self.hits += 1
            return f
        self.misses += 1
        f = self.extractor.extract(image)
        self.put(log, topic, stamp, f)
        return f

    def extract_batch(self, log: str | Path, topic: str, stamps: list[int], images: list[np.ndarray]) -> list[Features]:
        """Batched version: only the misses go through the network, in one batch."""
        out: list[Features | None] = [self.get(log, topic, s) for s in stamps]
        todo = [i for i, f in enumerate(out) if f is None]
        self.hits += len(stamps) - len(todo)
        self.misses += len(todo)
        if todo:
            for i, f in zip(todo, self.extractor.extract_batch([images[i] for i in todo])):
                self.put(log, topic, stamps[i], f)
                out[i] = f
        return out  # type: ignore[return-value]
