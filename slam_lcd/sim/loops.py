"""Ground-truth loop pairs: frames that see the same place, far apart in time.

Two frames form a loop pair when their *camera* poses are within ``max_dist`` metres and
``max_angle_deg`` degrees of each other and at least ``min_gap_s`` seconds apart. That is
the usual place-recognition ground truth (as in the RTAB-Map and KITTI loop matrices),
built from the exact poses of the simulator.

CSV format (written by :func:`write_loop_pairs`, one header line)::

    query_index,match_index,query_stamp_ns,match_stamp_ns,distance_m,angle_deg

``query_index > match_index`` are frame indices in the image sequence (0-based, camera
stamps order); the stamps identify the frames in a log.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from ..atomic import atomic_write
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


def loop_pair_table(traj: Trajectory, pairs: np.ndarray, T_body_camera: np.ndarray | None = None) -> list[tuple]:
    """Rows ``(query_index, match_index, query_stamp, match_stamp, distance_m, angle_deg)``."""
    T = _camera_poses(traj, T_body_camera)
    rows = []
    if len(pairs):
        i, j = pairs[:, 0], pairs[:, 1]
        d = np.linalg.norm(T[i, :3, 3] - T[j, :3, 3], axis=1)
        a = _angles_deg(T[i, :3, :3], T[j, :3, :3])
        for k in range(len(pairs)):
            rows.append((int(i[k]), int(j[k]), int(traj.stamps[i[k]]), int(traj.stamps[j[k]]), float(d[k]), float(a[k])))
    return rows


def write_loop_pairs(path: str | Path, traj: Trajectory, pairs: np.ndarray, T_body_camera: np.ndarray | None = None) -> Path:
    """Write loop pairs as CSV (see module docstring), atomically."""
    path = Path(path)
    with atomic_write(path, "w", encoding="utf-8", newline="\n") as fh:
        fh.write(CSV_HEADER + "\n")
        for qi, mi, qs, ms, d, a in loop_pair_table(traj, pairs, T_body_camera):
            fh.write(f"{qi},{mi},{qs},{ms},{d:.4f},{a:.3f}\n")
    return path


def read_loop_pairs(path: str | Path) -> np.ndarray:
    """Read the ``(K, 2)`` index pairs back from a file written by :func:`write_loop_pairs`."""
    from ..errors import InputError

    path = Path(path)
    lines = path.read_text(encoding="utf-8").splitlines()
    if not lines or lines[0].strip() != CSV_HEADER:
        raise InputError("not a slam-lcd loop-pairs CSV (header missing)", path)
    rows = [ln.split(",")[:2] for ln in lines[1:] if ln.strip()]
    return np.array(rows, dtype=np.int64).reshape(-1, 2)
