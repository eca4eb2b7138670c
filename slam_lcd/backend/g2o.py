"""Read and write 3D pose graphs in g2o text format.

Read: ``VERTEX_SE3:QUAT id x y z qx qy qz qw``, ``EDGE_SE3:QUAT i j x y z qx qy qz qw``
followed by the 21 upper-triangular entries of the 6x6 information matrix in g2o's
``[t, r]`` order, and the older TORO/iSAM-style ``VERTEX3 id x y z roll pitch yaw`` /
``EDGE3 i j x y z roll pitch yaw`` + 21 entries (rotation ``Rz(yaw) Ry(pitch) Rx(roll)``).

Information matrices are returned in GTSAM's ``[r, t]`` order; the writer converts back.

Why our own parser: ``gtsam.readG2o`` reads the 21 numbers of ``EDGE3`` lines as an
information matrix in GTSAM order, but the GTSAM example graphs (``sphere2500.txt``) store
the *square-root* information in ``[t, r]`` order: their odometry residuals against the
ground truth have standard deviations 0.10 m (sqrt-info 10) and 0.010/0.010/0.040 rad
(sqrt-info 100/100/25). ``edge3_matrix`` says how to read those 21 numbers.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np
from scipy.spatial.transform import Rotation

from ..errors import FileMissingError, TrajectoryFormatError, UnsupportedFormatError
from ..files.atomic import atomic_write
from ..geometry import quat_to_rot, rot_to_quat

# g2o [t, r] <-> GTSAM [r, t]: the permutation is its own inverse.
SWAP_TR = np.array([3, 4, 5, 0, 1, 2])


@dataclass
class G2oEdge:
    """Relative-pose constraint ``T_i_j`` with its 6x6 information (GTSAM ``[r, t]`` order)."""

    i: int
    j: int
    T_i_j: np.ndarray
    information: np.ndarray


def read_g2o(
    path: str | Path, edge3_matrix: Literal["information", "sqrt_information"] = "information"
) -> tuple[dict[int, np.ndarray], list[G2oEdge]]:
    """Parse a 3D g2o file into ``(poses id -> 4x4, edges)``; poses may be empty.

    Unknown tags (``FIX``, 2D records, landmarks) raise :class:`UnsupportedFormatError`
    naming the line, so a graph is never half-read silently. Edges keep file order within
    each tag (``EDGE_SE3:QUAT`` records come before ``EDGE3`` ones in a mixed file).
    """
    path = Path(path)
    if not path.is_file():
        raise FileMissingError("g2o file not found", path)
    need = {"VERTEX_SE3:QUAT": 8, "VERTEX3": 7, "EDGE_SE3:QUAT": 7 + 21 + 2, "EDGE3": 6 + 21 + 2}
    rows: dict[str, list[tuple[int, list[str]]]] = {t: [] for t in need}
    with open(path, encoding="utf-8", errors="replace") as fh:
        for n, line in enumerate(fh, 1):
            s = line.split()
            if not s or s[0].startswith("#"):
                continue
            tag = s[0]
            if tag not in need:
                raise UnsupportedFormatError(f"line {n}: unsupported g2o record {tag!r} (3D SE3 graphs only)", path)
            if len(s) - 1 != need[tag]:
                raise TrajectoryFormatError(f"bad {tag} record: expected {need[tag]} fields, got {len(s) - 1}",
                                            path, line=n)
            rows[tag].append((n, s[1:]))
    if not any(rows.values()):
        raise UnsupportedFormatError("no VERTEX/EDGE records found", path)
    poses: dict[int, np.ndarray] = {}
    for tag, rotation in (("VERTEX_SE3:QUAT", "quat"), ("VERTEX3", "rpy")):
        if rows[tag]:
            ids, T, _ = _parse_block(path, rows[tag], 1, rotation, None)
            poses.update({int(i[0]): t for i, t in zip(ids, T, strict=True)})
    edges: list[G2oEdge] = []
    for tag, rotation, kind in (("EDGE_SE3:QUAT", "quat", "information"), ("EDGE3", "rpy", edge3_matrix)):
        if rows[tag]:
            ids, T, info = _parse_block(path, rows[tag], 2, rotation, kind)
            edges += [G2oEdge(int(i), int(j), t, m) for (i, j), t, m in zip(ids, T, info, strict=True)]
    return poses, edges


def _parse_block(path, rows, n_ids: int, rotation: str, info_kind: str | None):
    """Vectorised conversion of same-tag records: (ids, (N,4,4) poses, (N,6,6) information | None)."""
    try:
        ids = np.array([[int(x) for x in r[:n_ids]] for _, r in rows], dtype=np.int64)
        vals = np.array([[float(x) for x in r[n_ids:]] for _, r in rows], dtype=np.float64)
    except ValueError as e:
        bad = next(n for n, r in rows if not _numeric(r, n_ids))
        raise TrajectoryFormatError(f"bad record: {e}", path, line=bad) from None
    if not np.all(np.isfinite(vals)):
        bad = rows[int(np.flatnonzero(~np.all(np.isfinite(vals), axis=1))[0])][0]
        raise TrajectoryFormatError("non-finite values in record", path, line=bad)
    T = np.tile(np.eye(4), (len(rows), 1, 1))
    T[:, :3, 3] = vals[:, :3]
    if rotation == "quat":
        q = vals[:, 3:7]
        norm = np.linalg.norm(q, axis=1)
        if np.any(norm < 1e-9):
            raise TrajectoryFormatError("zero quaternion", path, line=rows[int(np.argmin(norm))][0])
        T[:, :3, :3] = quat_to_rot(q)
        rest = vals[:, 7:]
    else:
        T[:, :3, :3] = Rotation.from_euler("ZYX", vals[:, [5, 4, 3]]).as_matrix()
        rest = vals[:, 6:]
    if info_kind is None:
        return ids, T, None
    U = np.zeros((len(rows), 6, 6))
    U[:, np.triu_indices(6)[0], np.triu_indices(6)[1]] = rest
    if info_kind == "sqrt_information":
        info = np.swapaxes(U, 1, 2) @ U
    else:
        info = U + np.swapaxes(U, 1, 2) - U * np.eye(6)
    info = info[:, SWAP_TR][:, :, SWAP_TR]
    return ids, T, info


def _numeric(r, n_ids) -> bool:
    try:
        [int(x) for x in r[:n_ids]]
        [float(x) for x in r[n_ids:]]
        return True
    except ValueError:
        return False


def write_g2o(path: str | Path, poses: dict[int, np.ndarray], edges: list[G2oEdge]) -> None:
    """Write ``VERTEX_SE3:QUAT`` / ``EDGE_SE3:QUAT`` records (information in g2o ``[t, r]`` order), atomically."""
    iu = np.triu_indices(6)
    with atomic_write(path, "w", encoding="utf-8") as fh:
        for k in sorted(poses):
            T = poses[k]
            q = rot_to_quat(T[:3, :3])
            fh.write(f"VERTEX_SE3:QUAT {k} " + " ".join(f"{x:.9g}" for x in (*T[:3, 3], *q)) + "\n")
        for e in edges:
            q = rot_to_quat(e.T_i_j[:3, :3])
            info = np.asarray(e.information)[np.ix_(SWAP_TR, SWAP_TR)]
            nums = (*e.T_i_j[:3, 3], *q, *info[iu])
            fh.write(f"EDGE_SE3:QUAT {e.i} {e.j} " + " ".join(f"{x:.9g}" for x in nums) + "\n")


def chain_initial_estimate(edges: list[G2oEdge], first: int = 0) -> dict[int, np.ndarray]:
    """Initial poses by composing the odometry edges ``i -> i+1`` from ``first`` (files without vertices)."""
    step = {e.i: e.T_i_j for e in edges if e.j == e.i + 1}
    poses = {first: np.eye(4)}
    k = first
    while k in step:
        poses[k + 1] = poses[k] @ step[k]
        k += 1
    return poses
