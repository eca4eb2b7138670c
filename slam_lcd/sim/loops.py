"""Ground-truth loop pairs: frames that see the same place, far apart in time.

Two frames form a loop pair when their *camera* poses are within ``max_dist`` metres and
``max_angle_deg`` degrees of each other and at least ``min_gap_s`` seconds apart. That is
the usual place-recognition ground truth (as in the RTAB-Map and KITTI loop matrices),
built from the exact poses of the simulator.

CSV format (written by :func:`write_loop_pairs`, one header line)::

    query_index,match_index,query_stamp_ns,match_stamp_ns,distance_m,angle_deg

``query_index > match_index`` are frame indices in the image sequence (0-based, camera
stamps order); the stamps identify the frames in a log.

Between two recordings of the same world (sessions, :mod:`slam_lcd.sim.sessions`),
:func:`gt_cross_pairs` gives the same kind of pairs from one trajectory to the other (no
time gap: the recordings are different) and :func:`shared_place_fraction` how much of one
recording's keyframes see a place the other saw. Trajectories whose ground-truth frames
differ (``frame_id``: two different worlds) share no place.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from ..errors import InputError
from ..files.atomic import atomic_write
from ..types import Trajectory

CSV_HEADER = "query_index,match_index,query_stamp_ns,match_stamp_ns,distance_m,angle_deg"


def _camera_poses(traj: Trajectory, T_body_camera: np.ndarray | None) -> np.ndarray:
    return traj.poses if T_body_camera is None else traj.poses @ np.asarray(T_body_camera)


def gt_loop_pairs(traj: Trajectory, max_dist: float = 1.0, max_angle_deg: float = 20.0, min_gap_s: float = 20.0,
                  T_body_camera: np.ndarray | None = None) -> np.ndarray:
    """Loop pairs ``(K, 2)`` int64 ``[query, match]`` (query later than match), sorted.

    ``traj`` holds body poses at the camera stamps (then pass ``T_body_camera``) or camera
    poses directly.
    """
    T = _camera_poses(traj, T_body_camera)
    if len(T) < 2:
        return np.zeros((0, 2), np.int64)
    pos = T[:, :3, 3]
    pairs = cKDTree(pos).query_pairs(max_dist, output_type="ndarray")
    if len(pairs) == 0:
        return np.zeros((0, 2), np.int64)
    i, j = np.maximum(pairs[:, 0], pairs[:, 1]), np.minimum(pairs[:, 0], pairs[:, 1])
    gap = (traj.stamps[i] - traj.stamps[j]) * 1e-9
    keep = gap >= min_gap_s
    i, j = i[keep], j[keep]
    ang = _angles_deg(T[i, :3, :3], T[j, :3, :3])
    keep = ang <= max_angle_deg
    out = np.column_stack([i[keep], j[keep]]).astype(np.int64)
    order = np.lexsort((out[:, 1], out[:, 0])) if len(out) else np.zeros(0, int)
    return out[order]


def _angles_deg(Ra: np.ndarray, Rb: np.ndarray) -> np.ndarray:
    tr = np.einsum("nij,nij->n", Ra, Rb)  # trace(Ra^T Rb)
    return np.degrees(np.arccos(np.clip((tr - 1.0) / 2.0, -1.0, 1.0)))


def gt_cross_pairs(traj_a: Trajectory, traj_b: Trajectory, max_dist: float = 1.0, max_angle_deg: float = 20.0,
                   T_body_camera: np.ndarray | None = None) -> np.ndarray:
    """Pairs ``(M, 2)`` int64 ``[index in a, index in b]`` whose camera poses are within
    ``max_dist`` metres and ``max_angle_deg`` degrees (viewing direction and roll: the whole
    rotation), sorted by a's then b's index.

    Both trajectories must be in one world frame (ground truth); when their ``frame_id``
    differ (two worlds: :func:`slam_lcd.sim.sessions.world_frame`) no place is shared and
    the result is empty, however close the poses.
    """
    empty = np.zeros((0, 2), np.int64)
    if traj_a.frame_id != traj_b.frame_id or len(traj_a) == 0 or len(traj_b) == 0:
        return empty
    Ta, Tb = _camera_poses(traj_a, T_body_camera), _camera_poses(traj_b, T_body_camera)
    sdm = cKDTree(Ta[:, :3, 3]).sparse_distance_matrix(cKDTree(Tb[:, :3, 3]), max_dist, output_type="ndarray")
    if len(sdm) == 0:
        return empty
    i, j = sdm["i"].astype(np.int64), sdm["j"].astype(np.int64)
    keep = _angles_deg(Ta[i, :3, :3], Tb[j, :3, :3]) <= max_angle_deg
    out = np.column_stack([i[keep], j[keep]])
    return out[np.lexsort((out[:, 1], out[:, 0]))] if len(out) else empty


def keyframe_indices(traj: Trajectory, min_translation: float = 0.5, min_rotation_deg: float = 15.0) -> np.ndarray:
    """Indices a keyframe selector would keep: the first pose, then each pose that moved
    ``min_translation`` metres or turned ``min_rotation_deg`` degrees from the last kept one
    (the front end's defaults). Both 0: every pose."""
    n = len(traj)
    if n == 0 or (min_translation <= 0 and min_rotation_deg <= 0):
        return np.arange(n, dtype=np.int64)
    pos, R = traj.poses[:, :3, 3], traj.poses[:, :3, :3]
    keep, last = [0], 0
    for k in range(1, n):
        moved = np.linalg.norm(pos[k] - pos[last])
        turned = _angles_deg(R[k][None], R[last][None])[0]
        if (min_translation > 0 and moved >= min_translation) or (min_rotation_deg > 0 and turned >= min_rotation_deg):
            keep.append(k)
            last = k
    return np.asarray(keep, dtype=np.int64)


def _subset(traj: Trajectory, idx: np.ndarray) -> Trajectory:
    return Trajectory(stamps=traj.stamps[idx], poses=traj.poses[idx], frame_id=traj.frame_id,
                      child_frame_id=traj.child_frame_id)


def shared_place_fraction(traj_a: Trajectory, traj_b, max_dist: float = 1.0, max_angle_deg: float = 20.0,
                          T_body_camera: np.ndarray | None = None, min_translation: float = 0.5,
                          min_rotation_deg: float = 15.0) -> float:
    """Fraction of ``traj_a``'s keyframes with a counterpart among ``traj_b``'s keyframes
    (:func:`gt_cross_pairs` thresholds; :func:`keyframe_indices` picks the keyframes of both).

    ``traj_b``: one trajectory or several (their union: a map of several sessions).
    Not symmetric: a short route inside a long one shares all of its places, the long one
    only some of its own. 0.0 when ``traj_a`` is empty.
    """
    bs = [traj_b] if isinstance(traj_b, Trajectory) else list(traj_b)
    ka = _subset(traj_a, keyframe_indices(traj_a, min_translation, min_rotation_deg))
    if len(ka) == 0:
        return 0.0
    hit = np.zeros(len(ka), bool)
    for b in bs:
        kb = _subset(b, keyframe_indices(b, min_translation, min_rotation_deg))
        pairs = gt_cross_pairs(ka, kb, max_dist, max_angle_deg, T_body_camera)
        hit[pairs[:, 0]] = True
    return float(hit.mean())


def loop_pair_table(traj: Trajectory, pairs: np.ndarray, T_body_camera: np.ndarray | None = None) -> list[tuple]:
    """Rows ``(query_index, match_index, query_stamp, match_stamp, distance_m, angle_deg)``."""
    T = _camera_poses(traj, T_body_camera)
    rows = []
    if len(pairs):
        i, j = pairs[:, 0], pairs[:, 1]
        d = np.linalg.norm(T[i, :3, 3] - T[j, :3, 3], axis=1)
        a = _angles_deg(T[i, :3, :3], T[j, :3, :3])
        for k in range(len(pairs)):
            rows.append((int(i[k]), int(j[k]), int(traj.stamps[i[k]]), int(traj.stamps[j[k]]),
                         float(d[k]), float(a[k])))
    return rows


def write_loop_pairs(
    path: str | Path, traj: Trajectory, pairs: np.ndarray, T_body_camera: np.ndarray | None = None
) -> Path:
    """Write loop pairs as CSV (see module docstring), atomically."""
    path = Path(path)
    with atomic_write(path, "w", encoding="utf-8", newline="\n") as fh:
        fh.write(CSV_HEADER + "\n")
        for qi, mi, qs, ms, d, a in loop_pair_table(traj, pairs, T_body_camera):
            fh.write(f"{qi},{mi},{qs},{ms},{d:.4f},{a:.3f}\n")
    return path


def read_loop_pairs(path: str | Path) -> np.ndarray:
    """Read the ``(K, 2)`` index pairs back from a file written by :func:`write_loop_pairs`."""
    path = Path(path)
    lines = path.read_text(encoding="utf-8").splitlines()
    if not lines or lines[0].strip() != CSV_HEADER:
        raise InputError("not a slam-lcd loop-pairs CSV (header missing)", path)
    rows = [ln.split(",")[:2] for ln in lines[1:] if ln.strip()]
    return np.array(rows, dtype=np.int64).reshape(-1, 2)
