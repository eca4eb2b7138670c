"""Trajectory text files: TUM, KITTI and EuRoC CSV, read and written without loss.

Why a reader of our own: users hand us files from every SLAM system, and the usual
parsers (``numpy.loadtxt``) either drop the line number of a bad row or go through
float seconds, losing nanoseconds of a 10-digit Unix stamp. Here stamps are parsed
from their decimal text straight into integer nanoseconds, every bad line is reported
with its 1-based number, and writers print shortest round-trip floats, so that
write → read gives back the same poses to ~1e-15.

Formats
- TUM: ``t tx ty tz qx qy qz qw`` (seconds, quaternion x-y-z-w), whitespace separated,
  exactly 8 columns; ``#`` (and ``%``) comment lines and blank lines are skipped.
- KITTI: 12 values per line, the row-major 3x4 matrix ``[R | t]``. The file has no
  stamps: with ``times_path`` (one stamp in seconds per line, KITTI's ``times.txt``)
  those are used, otherwise pose *i* gets stamp *i* seconds (its frame index), so two
  KITTI files without times associate frame by frame.
- EuRoC CSV: ``timestamp[ns], px, py, pz, qw, qx, qy, qz[, ...]`` (quaternion w first);
  extra columns (the ground-truth file's velocities and biases) are ignored on read.

Poses: quaternions are normalised (a norm below 1e-6 is an error), KITTI rotations are
projected onto the nearest rotation (a matrix further than 1e-2 from one is an error).
Stamps must not go backwards (equal consecutive stamps occur in real files and are kept,
with one warning line). A quaternion further than 1e-3 from unit length is normalised with
one warning line per file (a norm of 2 is a broken writer, not rounding).
"""
from __future__ import annotations

import logging
from collections.abc import Iterator
from decimal import Decimal, InvalidOperation
from pathlib import Path

import numpy as np

from ..errors import (
    FileMissingError,
    InvalidPoseError,
    TrajectoryFormatError,
    UnsortedStampsError,
    UnsupportedFormatError,
)
from ..files.atomic import atomic_write
from ..geometry import nearest_rotation, quat_to_rot, rot_to_quat
from ..geometry import rot_to_quat as rotation_to_quat  # noqa: F401  (public name kept for callers)
from ..types import Trajectory
from .trajectory_formats import FORMATS

log = logging.getLogger(__name__)

__all__ = [
    "FORMATS",
    "detect_trajectory_format",
    "read_euroc",
    "read_kitti",
    "read_kitti_times",
    "read_trajectory",
    "read_tum",
    "write_euroc",
    "write_kitti",
    "write_trajectory",
    "write_tum",
]

_EXTENSIONS = {".tum": "tum", ".kitti": "kitti", ".csv": "euroc"}
_QUAT_MIN_NORM = 1e-6
# quaternions written with 4 decimals are off unit length by ~1e-4; more than this is a broken file
_QUAT_UNIT_TOLERANCE = 1e-3
_ROTATION_MAX_DEVIATION = 1e-2
EUROC_HEADER = "#timestamp [ns],p_RS_R_x [m],p_RS_R_y [m],p_RS_R_z [m],q_RS_w [],q_RS_x [],q_RS_y [],q_RS_z []"


# ----------------------------------------------------------------------------- helpers


def _data_lines(path: Path, comma: bool = False) -> Iterator[tuple[int, list[str]]]:
    """Yield ``(line_number, fields)`` of non-blank, non-comment lines of a text file."""
    path = Path(path)
    if not path.exists():
        raise FileMissingError("trajectory file not found", path)
    if not path.is_file():
        raise FileMissingError("trajectory path is not a file", path)
    try:
        with open(path, encoding="utf-8") as fh:
            for number, line in enumerate(fh, start=1):
                text = line.strip()
                if not text or text.startswith("#") or text.startswith("%"):
                    continue
                fields = [f.strip() for f in text.split(",")] if comma else text.split()
                yield number, fields
    except UnicodeDecodeError:
        raise UnsupportedFormatError("not a text trajectory file (binary content)", path) from None


def _decimal(text: str, path: Path, line: int, what: str) -> Decimal:
    try:
        value = Decimal(text)
    except InvalidOperation:
        raise TrajectoryFormatError(f"{what} {text!r} is not a number", path, line) from None
    if not value.is_finite():
        raise InvalidPoseError(f"line {line}: {what} is {text}", path)
    return value


def _seconds_to_ns(text: str, path: Path, line: int) -> int:
    """Exact decimal seconds → integer nanoseconds (no float rounding of big stamps)."""
    body = text[1:] if text[:1] in "+-" else text
    whole, dot, frac = body.partition(".")
    if not body.isascii():
        raise TrajectoryFormatError(f"timestamp {text!r} is not a number", path, line)
    if whole.isdigit() and (frac.isdigit() or (dot and not frac)) and len(frac) <= 9:
        ns = int(whole) * 1_000_000_000 + int((frac + "000000000")[:9])
        return -ns if text.startswith("-") else ns
    if whole.isdigit() and not dot:
        ns = int(whole) * 1_000_000_000
        return -ns if text.startswith("-") else ns
    # exponents, more than 9 decimals, odd spellings: the exact (slower) route
    return int((_decimal(text, path, line, "timestamp") * 1_000_000_000).to_integral_value())


def _ns_text_to_ns(text: str, path: Path, line: int) -> int:
    if text.isascii() and text.lstrip("-").isdigit():
        return int(text)
    return int(_decimal(text, path, line, "timestamp").to_integral_value())


def _float_matrix(rows: list[list[str]], lines: list[int], path: Path) -> np.ndarray:
    """Rows of number texts → (N, k) float64; a bad token or NaN/inf names its line."""
    try:
        values = np.array(rows, dtype=np.float64)
    except ValueError:
        for line, fields in zip(lines, rows, strict=True):
            for f in fields:
                if not _is_float(f):
                    raise TrajectoryFormatError(f"value {f!r} is not a number", path, line) from None
        raise
    finite = np.isfinite(values).all(axis=1)
    if not finite.all():
        i = int(np.flatnonzero(~finite)[0])
        raise InvalidPoseError(f"line {lines[i]}: pose contains NaN or inf ({' '.join(rows[i])})", path)
    return values


def _is_float(text: str) -> bool:
    try:
        float(text)
        return True
    except ValueError:
        return False


def _poses_from_quats(t: np.ndarray, q_xyzw: np.ndarray, lines: list[int], path: Path) -> np.ndarray:
    norm = np.linalg.norm(q_xyzw, axis=1)
    small = norm < _QUAT_MIN_NORM
    if small.any():
        i = int(np.flatnonzero(small)[0])
        raise InvalidPoseError(f"line {lines[i]}: quaternion norm {norm[i]:.3g} is too close to zero", path)
    off = np.abs(norm - 1.0) > _QUAT_UNIT_TOLERANCE
    if off.any():  # normalised, as evo does, but said: a norm of 2 usually means a broken writer
        i = int(np.flatnonzero(off)[0])
        log.warning("%s: %d quaternion(s) are not of unit length (first at line %d: norm %.6g); normalised",
                    path, int(off.sum()), lines[i], norm[i])
    T = np.tile(np.eye(4), (len(t), 1, 1))
    T[:, :3, :3] = quat_to_rot(q_xyzw)
    T[:, :3, 3] = t
    return T


def _check_sorted(stamps, lines: list[int], path: Path) -> None:
    arr = np.asarray(stamps, dtype=np.int64)
    back = np.flatnonzero(np.diff(arr) < 0)
    if back.size:
        i = int(back[0]) + 1
        raise UnsortedStampsError(
            f"line {lines[i]}: timestamp goes backwards ({arr[i]} ns after {arr[i - 1]} ns); "
            f"{back.size} such place(s)",
            path,
        )


def _finish(stamps, poses: np.ndarray, lines: list[int], path: Path) -> Trajectory:
    if len(poses) == 0:
        raise TrajectoryFormatError("no poses in file", path)
    _check_sorted(stamps, lines, path)
    arr = np.asarray(stamps, dtype=np.int64)
    rep = np.flatnonzero(np.diff(arr) == 0)
    if rep.size:  # kept (real files have them), but said: association then picks one of the two
        i = int(rep[0]) + 1
        log.warning("%s: %d repeated timestamp(s) (first at line %d: %s s again); both poses are kept",
                    path, int(rep.size), lines[i], ns_to_seconds_text(int(arr[i])))
    return Trajectory(stamps=arr, poses=poses)


def _collect(path: Path, ncols: int, what: str, comma: bool = False, at_least: bool = False):
    """All data lines of a file, checked for their column count: (line numbers, fields)."""
    lines, rows = [], []
    for line, fields in _data_lines(path, comma=comma):
        if len(fields) != ncols and not (at_least and len(fields) > ncols):
            raise TrajectoryFormatError(
                f"expected {'at least ' if at_least else ''}{ncols} columns {what}, found {len(fields)}", path, line
            )
        lines.append(line)
        rows.append(fields)
    return lines, rows


def ns_to_seconds_text(ns: int) -> str:
    """Integer nanoseconds → exact decimal seconds text (``1311868164.363181``)."""
    ns = int(ns)
    sign = "-" if ns < 0 else ""
    sec, frac = divmod(abs(ns), 1_000_000_000)
    frac_text = f"{frac:09d}".rstrip("0") or "0"
    return f"{sign}{sec}.{frac_text}"


def _check_writable(traj: Trajectory, path: Path) -> None:
    if len(traj) == 0:
        raise InvalidPoseError("refusing to write an empty trajectory", path)
    if not np.all(np.isfinite(traj.poses)):
        bad = int(np.flatnonzero(~np.isfinite(traj.poses).reshape(len(traj), -1).all(axis=1))[0])
        raise InvalidPoseError(f"pose {bad} contains NaN or inf; refusing to write it", path)

# ----------------------------------------------------------------------------- TUM


def read_tum(path: str | Path) -> Trajectory:
    """Read a TUM file (``t tx ty tz qx qy qz qw``; comments ``#`` allowed)."""
    p = Path(path)
    lines, rows = _collect(p, 8, "'t tx ty tz qx qy qz qw' (TUM)")
    if not rows:
        raise TrajectoryFormatError("no poses in file", p)
    values = _float_matrix([r[1:] for r in rows], lines, p)
    stamps = [_seconds_to_ns(r[0], p, ln) for ln, r in zip(lines, rows, strict=True)]
    return _finish(stamps, _poses_from_quats(values[:, 0:3], values[:, 3:7], lines, p), lines, p)


def write_tum(path: str | Path, traj: Trajectory, notes: dict[int, str] | None = None) -> None:
    """Write ``t tx ty tz qx qy qz qw`` lines (exact decimal seconds), atomically; ``notes``: ``# text`` lines
    before the poses of those indices (TUM readers skip them)."""
    path, notes = Path(path), notes or {}
    _check_writable(traj, path)
    rows = zip(traj.stamps.tolist(), traj.poses[:, :3, 3].tolist(), rot_to_quat(traj.poses[:, :3, :3]).tolist(),
               strict=True)
    with atomic_write(path, "w", encoding="utf-8") as fh:
        fh.write("# timestamp tx ty tz qx qy qz qw\n")
        for i, (stamp, t, q) in enumerate(rows):
            fh.write((f"# {notes[i]}\n" if i in notes else "")
                     + " ".join([ns_to_seconds_text(stamp), *map(repr, t), *map(repr, q)]) + "\n")


# ----------------------------------------------------------------------------- KITTI


def read_kitti_times(path: str | Path) -> tuple[np.ndarray, list[int]]:
    """Read a KITTI ``times.txt`` (one stamp in seconds per line) → (ns stamps, line numbers)."""
    path = Path(path)
    lines, rows = _collect(path, 1, "(time in seconds)")
    stamps = [_seconds_to_ns(r[0], path, ln) for ln, r in zip(lines, rows, strict=True)]
    _check_sorted(stamps, lines, path)
    return np.asarray(stamps, dtype=np.int64), lines


def read_kitti(path: str | Path, times_path: str | Path | None = None, *, file_rotations: bool = False) -> Trajectory:
    """Read a KITTI pose file (12 values per line); stamps from ``times_path`` or frame index (s).

    The 3x3 blocks are orthonormal only to the printed precision (~1e-7 in KITTI-00) and are
    projected to the nearest rotation; ``file_rotations=True`` keeps them as written (after the
    same check), as evo does, so that ``slam-lcd ate`` equals evo to the last digits.
    """
    path = Path(path)
    lines, rows = _collect(path, 12, "(row-major 3x4 [R|t], KITTI)")
    if not rows:
        raise TrajectoryFormatError("no poses in file", path)
    values = _float_matrix(rows, lines, path).reshape(-1, 3, 4)
    R = values[:, :, :3]
    R_fixed = nearest_rotation(R)
    deviation = np.abs(R - R_fixed).max(axis=(1, 2))
    bad = (deviation > _ROTATION_MAX_DEVIATION) | (np.linalg.det(R) <= 0)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise InvalidPoseError(
            f"line {lines[i]}: 3x3 part is not a rotation matrix (off by {deviation[i]:.3g})", path
        )
    poses = np.tile(np.eye(4), (len(values), 1, 1))
    poses[:, :3, :3] = R if file_rotations else R_fixed
    poses[:, :3, 3] = values[:, :, 3]
    if times_path is not None:
        stamps, _ = read_kitti_times(times_path)
        if len(stamps) != len(poses):
            raise TrajectoryFormatError(
                f"times file {times_path} has {len(stamps)} stamps but the pose file has {len(poses)} poses",
                path,
            )
    else:
        stamps = np.arange(len(poses), dtype=np.int64) * 1_000_000_000
    return _finish(stamps, poses, lines, path)


def write_kitti(path: str | Path, traj: Trajectory, times_path: str | Path | None = None) -> None:
    """Write 12-value KITTI lines (and, with ``times_path``, the stamps in seconds), atomically."""
    path = Path(path)
    _check_writable(traj, path)
    with atomic_write(path, "w", encoding="utf-8") as fh:
        for row in traj.poses[:, :3, :].reshape(len(traj), 12).tolist():
            fh.write(" ".join(map(repr, row)) + "\n")
    if times_path is not None:
        with atomic_write(times_path, "w", encoding="utf-8") as fh:
            for stamp in traj.stamps.tolist():
                fh.write(ns_to_seconds_text(stamp) + "\n")


# ----------------------------------------------------------------------------- EuRoC


def read_euroc(path: str | Path) -> Trajectory:
    """Read a EuRoC CSV (``ns, px, py, pz, qw, qx, qy, qz[, extra columns]``)."""
    path = Path(path)
    lines, rows = _collect(path, 8, "'ns,px,py,pz,qw,qx,qy,qz' (EuRoC, comma separated)", comma=True, at_least=True)
    if not rows:
        raise TrajectoryFormatError("no poses in file", path)
    values = _float_matrix([r[1:8] for r in rows], lines, path)
    stamps = [_ns_text_to_ns(r[0], path, ln) for ln, r in zip(lines, rows, strict=True)]
    q_xyzw = values[:, [4, 5, 6, 3]]
    poses = _poses_from_quats(values[:, 0:3], q_xyzw, lines, path)
    return _finish(stamps, poses, lines, path)


def write_euroc(path: str | Path, traj: Trajectory) -> None:
    """Write a EuRoC CSV with integer-ns stamps and w-first quaternions, atomically."""
    path = Path(path)
    _check_writable(traj, path)
    q_wxyz = rot_to_quat(traj.poses[:, :3, :3])[:, [3, 0, 1, 2]]
    with atomic_write(path, "w", encoding="utf-8") as fh:
        fh.write(EUROC_HEADER + "\n")
        for stamp, t, q in zip(traj.stamps.tolist(), traj.poses[:, :3, 3].tolist(), q_wxyz.tolist(), strict=True):
            fh.write(",".join([str(stamp), *map(repr, t), *map(repr, q)]) + "\n")


# ----------------------------------------------------------------------------- dispatch


def detect_trajectory_format(path: str | Path) -> str:
    """Guess 'tum' | 'kitti' | 'euroc' from the extension, else from the first data line."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix in _EXTENSIONS:
        if not path.exists():
            raise FileMissingError("trajectory file not found", path)
        return _EXTENSIONS[suffix]
    if suffix == ".g2o":
        raise UnsupportedFormatError(
            "g2o files hold a pose graph, not a timed trajectory; use slam_lcd.backend.g2o.read_g2o",
            path,
        )
    if suffix in (".bag", ".mcap", ".db3") or (path.is_dir() and (path / "metadata.yaml").is_file()):
        raise UnsupportedFormatError(
            "this is a log, not a trajectory text file; give it as LOG:TOPIC", path
        )
    for line, fields in _data_lines(path):
        if "," in " ".join(fields):
            return "euroc"
        if len(fields) == 8:
            return "tum"
        if len(fields) == 12:
            return "kitti"
        raise UnsupportedFormatError(
            f"cannot tell the trajectory format: line {line} has {len(fields)} columns "
            "(TUM has 8, KITTI 12, EuRoC is comma separated)",
            path,
        )
    raise TrajectoryFormatError("no poses in file", path)


def read_trajectory(path: str | Path, fmt: str | None = None, *, times_path: str | Path | None = None,
                    file_rotations: bool = False) -> Trajectory:
    """Read a TUM / KITTI / EuRoC file; ``fmt=None`` detects the format (``file_rotations``: see :func:`read_kitti`)."""
    fmt = detect_trajectory_format(path) if fmt is None else fmt.lower()
    if fmt == "tum":
        return read_tum(path)
    if fmt == "kitti":
        return read_kitti(path, times_path=times_path, file_rotations=file_rotations)
    if fmt == "euroc":
        return read_euroc(path)
    raise UnsupportedFormatError(f"unknown trajectory format {fmt!r}; known: {', '.join(FORMATS)}", path)


def write_trajectory(
    path: str | Path, traj: Trajectory, fmt: str | None, *, times_path: str | Path | None = None
) -> None:
    """Write ``traj`` as 'tum' | 'kitti' | 'euroc' (``fmt=None``: from the extension, default TUM)."""
    if fmt is None:
        fmt = _EXTENSIONS.get(Path(path).suffix.lower(), "tum")
    fmt = fmt.lower()
    if fmt == "tum":
        write_tum(path, traj)
    elif fmt == "kitti":
        write_kitti(path, traj, times_path=times_path)
    elif fmt == "euroc":
        write_euroc(path, traj)
    else:
        raise UnsupportedFormatError(f"unknown trajectory format {fmt!r}; known: {', '.join(FORMATS)}", path)
