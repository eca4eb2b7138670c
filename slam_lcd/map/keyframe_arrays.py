"""What the map stores of each keyframe: descriptors in a compact form, camera, the session's arrays.

Also the feature identity a map records (:func:`extractor_meta`), the visual links between
consecutive keyframes and the sha256 by which a log is recognised.
"""
from __future__ import annotations

import hashlib
from itertools import pairwise
from pathlib import Path

import numpy as np

from ..files.hashing import sha256_of
from ..types import CameraModel, Keyframe, Trajectory
from .contents import SessionKeyframes
from .joint_types import LINK, JointLoop


def extractor_meta(extractor, descriptor_form: str = "int8") -> dict:
    """What a map records of the features it holds: kind, weights' sha256, descriptor size and form."""
    ident = extractor.identity() if hasattr(extractor, "identity") else {"kind": extractor.kind}
    return {"kind": ident.get("kind", getattr(extractor, "kind", "")), "weights_sha256": ident.get("weights_sha256"),
            "descriptor_dim": int(getattr(extractor, "descriptor_dim", 0) or 0),
            "descriptor_form": descriptor_form if ident.get("kind") != "orb" else "binary",
            "identity": {k: (v if isinstance(v, (int, float, str, bool, type(None))) else str(v))
                         for k, v in ident.items()}}


def camera_json(c: CameraModel | None) -> dict | None:
    if c is None:
        return None
    return {"width": c.width, "height": c.height, "fx": c.fx, "fy": c.fy, "cx": c.cx, "cy": c.cy,
            "distortion_model": c.distortion_model, "D": np.asarray(c.D, float).tolist(), "baseline": c.baseline}


def camera_from_json(d: dict | None) -> CameraModel | None:
    if not d:
        return None
    return CameraModel(int(d["width"]), int(d["height"]), float(d["fx"]), float(d["fy"]), float(d["cx"]),
                       float(d["cy"]), str(d.get("distortion_model", "none")), np.asarray(d.get("D", []), float),
                       d.get("baseline"))


INT4_CLIP_SIGMAS = 2.5  # int4: values beyond 2.5 standard deviations of the row are clipped


def compact_for_map(desc: np.ndarray, form: str) -> tuple[np.ndarray, np.ndarray]:
    """(stored descriptors, scales) of one keyframe's descriptors in the map's ``descriptor_form``.

    SuperPoint rows: ``int4`` (two values a byte, 128 B, one scale per row: value = q / scale,
    the scale putting 2.5 standard deviations at the last level), ``int8`` (256 B, the scale
    putting the row's peak at 127) or ``float16``. ORB's binary rows as they are (no scales).
    Restored rows are renormalised to unit length (SuperPoint's are), so the scale only has to
    be right up to a factor.
    """
    desc = np.asarray(desc)
    if desc.dtype == np.uint8:
        return np.ascontiguousarray(desc), np.zeros(0, np.float32)
    d = desc.astype(np.float32)
    if form == "float16":
        return d.astype(np.float16), np.zeros(0, np.float32)
    if form == "int4":
        if d.shape[1] % 2:
            raise ValueError(f"int4 descriptors need an even dimension, not {d.shape[1]}")
        spread = INT4_CLIP_SIGMAS * d.std(axis=1) if len(d) else np.zeros(0, np.float32)
        scale = np.where(spread > 0, 7.0 / np.maximum(spread, 1e-12), 1.0).astype(np.float32)
        q = (np.clip(np.rint(d * scale[:, None]), -7, 7).astype(np.int16) + 8).astype(np.uint8)  # 1..15
        return (q[:, 0::2] << 4) | q[:, 1::2], scale
    peak = np.abs(d).max(axis=1) if len(d) else np.zeros(0, np.float32)
    scale = np.where(peak > 0, 127.0 / np.maximum(peak, 1e-12), 1.0).astype(np.float32)
    return np.clip(np.rint(d * scale[:, None]), -127, 127).astype(np.int8), scale


def session_arrays(detector, kfs: list[Keyframe], gt: Trajectory | None, form: str) -> SessionKeyframes:
    """A finished session's keyframes as the map stores them (what the detector kept of each, ``form``
    the map's descriptor form; ground truth at the keyframe stamps, for evaluation only)."""
    det = detector
    ids, stamps, T_odom, cov, cov_src, offs = [], [], [], [], [], [0]
    kps, descs, scales, p3s, srcs = [], [], [], [], []
    for kf in kfs:
        light, desc, p3, src = det.stored(kf.id)
        n = len(light.features.keypoints)
        ids.append(int(kf.id))
        stamps.append(int(kf.stamp))
        T_odom.append(np.asarray(kf.T_world_body, float))
        c = kf.covariance_since_last
        cov.append(np.asarray(c, float) if c is not None else np.full((6, 6), np.nan))
        cov_src.append("model" if kf.covariance_source == "model" else "given")
        kps.append(np.asarray(light.features.keypoints, np.float32).reshape(-1, 2))
        d, sc = compact_for_map(desc, form)
        descs.append(d)
        scales.append(sc)
        p3s.append(np.asarray(p3, np.float32).reshape(-1, 3) if p3 is not None else np.full((n, 3), np.nan, np.float32))
        srcs.append(src if p3 is not None else "none")
        offs.append(offs[-1] + n)
    stamps_a = np.array(stamps, np.int64)
    T_gt = np.full((len(ids), 4, 4), np.nan)
    if gt is not None and len(gt) > 1:
        from ..geometry import interpolate_poses  # lazy: scipy

        inside = (stamps_a >= gt.stamps[0]) & (stamps_a <= gt.stamps[-1])
        if inside.any():
            T_gt[inside] = interpolate_poses(gt.stamps, gt.poses, stamps_a[inside])
    dim = descs[0].shape[1] if descs and descs[0].ndim == 2 else 0
    return SessionKeyframes(
        ids=np.array(ids, np.int64), stamps=stamps_a, T_odom=np.array(T_odom).reshape(-1, 4, 4),
        cov=np.array(cov).reshape(-1, 6, 6), T_gt=T_gt, offsets=np.array(offs, np.int64),
        keypoints=np.concatenate(kps) if kps else np.zeros((0, 2), np.float32),
        descriptors=np.concatenate([d.reshape(-1, dim) for d in descs]) if descs else np.zeros((0, dim)),
        scales=np.concatenate(scales).astype(np.float32) if scales else np.zeros(0, np.float32),
        points3d=np.concatenate(p3s) if p3s else np.zeros((0, 3), np.float32),
        points_source=np.array(srcs, dtype="<U10"), cov_source=np.array(cov_src, dtype="<U5"))


def visual_links(detector, kf_ids: list[int]) -> list[JointLoop]:
    """Visual relative poses of consecutive keyframes (``map.visual_links``); pairs that do not verify get none."""
    out = []
    for a, b in pairwise(kf_ids):
        c = detector.verify_pair(b, a)
        if c is not None and np.all(np.isfinite(c.T_match_query)):
            out.append(JointLoop(int(b), int(a), np.asarray(c.T_match_query, float), np.asarray(c.information, float),
                                 False, True, LINK))
    return out


class LogHashes:
    """``log_sha256`` of each log file computed once (by resolved path, size and modification time)."""

    def __init__(self):
        self._cache: dict[tuple, str | None] = {}

    def __call__(self, log_path) -> str | None:
        p = Path(log_path)
        try:
            st = p.stat()
            key = (str(p.resolve()), st.st_size, st.st_mtime_ns)
        except OSError:
            return None
        if key not in self._cache:
            self._cache[key] = log_sha256(p)
        return self._cache[key]


def session_holding(table: list[dict], sha: str | None, image_topic: str | None = None) -> str | None:
    """The session of ``table`` recorded from the log of sha256 ``sha`` (and ``image_topic``, when given), or None.

    One rule for every way into a map (``run --map``, ``batch --map``, ``demo --sessions``,
    ``Map.add_session``): a log appended twice adds nothing but loops onto its own copy, so it is
    skipped (an interrupted ``run a b c --map`` is resumed by running it again). Another camera of
    the same log is another session: with ``image_topic`` given, only a session recorded from that
    topic (or from an unrecorded one) counts."""
    if sha is None:
        return None
    for s in table:
        if s.get("log_sha256") == sha and (image_topic is None or s.get("image_topic") in (None, image_topic)):
            return str(s["name"])
    return None


def log_sha256(path) -> str | None:
    """sha256 of a log file; of a rosbag2 folder, the sha256 of its files' relative names and sha256s."""
    p = Path(path)
    try:
        if not p.is_dir():
            return sha256_of(p)
        return hashlib.sha256("".join(f"{q.relative_to(p).as_posix()} {sha256_of(q)}\n"
                                      for q in sorted(p.rglob("*")) if q.is_file()).encode()).hexdigest()
    except OSError:
        return None
