"""On-disk feature cache, so a re-run of the pipeline does not recompute features.

One ``.npz`` per image under ``<root>/<extractor fingerprint>/<log key>/<topic key>/<stamp>.npz``:

- the extractor fingerprint hashes everything that changes the output (kind, thresholds,
  NMS radius, max keypoints, sampling mode, sha256 of the weights; ORB parameters and the
  OpenCV version) but not the device;
- the log key hashes the log's resolved path, size and modification time (for a rosbag2
  folder: of every file in it), so an edited or replaced log is never served stale features.

Files are written atomically and read with ``allow_pickle=False``. An entry that does not load,
or is not what this extractor writes for this image (a foreign ``.npz``: other arrays, shapes,
descriptor width or type, image size, kind; NaN or out-of-image keypoints), is treated as a
miss, recomputed and overwritten; the first such entry of a cache is named in one warning.
"""
from __future__ import annotations

import hashlib
import logging
import re
import zipfile
from pathlib import Path

import numpy as np

from ..files.atomic import atomic_path
from ..files.npz import save_npz
from ..types import Features
from .extract import Extractor
from .weights import cache_dir

_log = logging.getLogger(__name__)


class _UnusableEntry(Exception):
    """A cache entry that is not this extractor's features of this image."""


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
        self.unusable = 0  # entries that did not load or were not this extractor's: recomputed

    def path(self, log: str | Path, topic: str, stamp: int) -> Path:
        lk = self._log_keys.get(str(log))
        if lk is None:
            lk = self._log_keys[str(log)] = log_key(log)
        return self.base / lk / topic_key(topic) / f"{int(stamp)}.npz"

    def get(self, log: str | Path, topic: str, stamp: int,
            image_size: tuple[int, int] | None = None) -> Features | None:
        """The cached features, or None (a miss) when there are none or the entry cannot be used
        (``image_size``: (width, height) the entry must have been made from)."""
        p = self.path(log, topic, stamp)
        if not p.is_file():
            return None
        try:
            with np.load(p, allow_pickle=False) as z:
                return self._checked(z, image_size)
        except Exception as e:  # truncated / foreign file: recompute and overwrite
            self.unusable += 1
            if self.unusable == 1:
                why = (e if isinstance(e, _UnusableEntry) else "not an .npz (zip) file" if not zipfile.is_zipfile(p)
                       else f"it does not load: {type(e).__name__}: {e}")
                _log.warning("%s: feature cache entry skipped (%s); it and any other such entry are recomputed "
                            "and overwritten", p, " ".join(str(why).split())[:200])
            return None

    def _checked(self, z, image_size) -> Features:
        missing = [k for k in ("keypoints", "scores", "descriptors", "image_size", "kind") if k not in z.files]
        if missing:
            raise _UnusableEntry(f"no array {', '.join(missing)}: not a slam-lcd feature file")
        kp, sc, desc, size = z["keypoints"], z["scores"], z["descriptors"], z["image_size"]
        kind = str(z["kind"])
        ext = self.extractor
        if ext.kind and kind != ext.kind:
            raise _UnusableEntry(f"features of kind {kind!r}, not {ext.kind!r}")
        if size.shape != (2,) or size.dtype.kind not in "iu":
            raise _UnusableEntry(f"image_size of shape {size.shape}, not (width, height)")
        w, h = (int(v) for v in size)
        if image_size is not None and (w, h) != tuple(image_size):
            raise _UnusableEntry(f"made from a {w}x{h} image, not {image_size[0]}x{image_size[1]}")
        n = kp.shape[0] if kp.ndim == 2 else -1
        if kp.ndim != 2 or kp.shape[1] != 2 or kp.dtype.kind != "f":
            raise _UnusableEntry(f"keypoints of shape {kp.shape} ({kp.dtype}), not N x 2 floats")
        if sc.shape != (n,) or desc.ndim != 2 or desc.shape[0] != n:
            raise _UnusableEntry(f"scores {sc.shape} and descriptors {desc.shape} do not fit {n} keypoints")
        if ext.descriptor_dim and (desc.shape[1] != ext.descriptor_dim
                                   or desc.dtype != np.dtype(ext.descriptor_dtype)):
            raise _UnusableEntry(f"descriptors {desc.shape[1]} x {desc.dtype}, not {ext.descriptor_dim} x "
                                 f"{np.dtype(ext.descriptor_dtype)}")
        if n and (not np.all(np.isfinite(kp)) or kp.min() < -1 or kp[:, 0].max() > w or kp[:, 1].max() > h):
            raise _UnusableEntry(f"keypoints outside the {w}x{h} image (or NaN)")
        return Features(keypoints=kp.astype(np.float32), scores=sc.astype(np.float32), descriptors=desc,
                        image_size=(w, h), kind=kind)

    def put(self, log: str | Path, topic: str, stamp: int, feats: Features) -> Path:
        p = self.path(log, topic, stamp)
        with atomic_path(p) as tmp:
            with open(tmp, "wb") as fh:
                save_npz(fh, {
                    "keypoints": feats.keypoints,
                    "scores": feats.scores,
                    "descriptors": feats.descriptors,
                    "image_size": np.array(feats.image_size, np.int64),
                    "kind": np.array(feats.kind),
                })
        return p

    def extract(self, log: str | Path, topic: str, stamp: int, image: np.ndarray) -> Features:
        """Cached features if present, else extract and store them."""
        f = self.get(log, topic, stamp, _size_of(image))
        if f is not None:
            self.hits += 1
            return f
        self.misses += 1
        f = self.extractor.extract(image)
        self.put(log, topic, stamp, f)
        return f

    def extract_batch(self, log: str | Path, topic: str, stamps: list[int], images: list[np.ndarray]) -> list[Features]:
        """Batched version: only the misses go through the network, in one batch."""
        out: list[Features | None] = [self.get(log, topic, s, _size_of(im))
                                      for s, im in zip(stamps, images, strict=True)]
        todo = [i for i, f in enumerate(out) if f is None]
        self.hits += len(stamps) - len(todo)
        self.misses += len(todo)
        if todo:
            for i, f in zip(todo, self.extractor.extract_batch([images[i] for i in todo]), strict=True):
                self.put(log, topic, stamps[i], f)
                out[i] = f
        return out  # type: ignore[return-value]


def _size_of(image) -> tuple[int, int] | None:
    """(width, height) of an image array, or None (not an array: the entry's size is not checked)."""
    shape = getattr(image, "shape", None)
    return (int(shape[1]), int(shape[0])) if shape is not None and len(shape) >= 2 else None
