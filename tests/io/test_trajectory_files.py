"""Trajectory files: real TUM / KITTI / EuRoC files, round trips, errors."""
from __future__ import annotations

from decimal import Decimal
from pathlib import Path

import numpy as np
import pytest

from slam_lcd.errors import (
    FileMissingError,
    InvalidPoseError,
    TrajectoryFormatError,
    UnsortedStampsError,
    UnsupportedFormatError,
)
from slam_lcd.io.trajectory_files import (
    detect_trajectory_format,
    ns_to_seconds_text,
    read_euroc,
    read_kitti,
    read_trajectory,
    read_tum,
    rotation_to_quat,
    write_euroc,
    write_kitti,
    write_trajectory,
    write_tum,
)
from slam_lcd.types import Trajectory

file_interface = pytest.importorskip("evo.tools.file_interface")

TUM_FILES = [
    "fr2_desk_groundtruth.txt",
    "fr2_desk_ORB.txt",
    "freiburg1_xyz-groundtruth.txt",
    "freiburg1_xyz-rgbdslam_drift.txt",
    "V102.txt",
]


@pytest.fixture(scope="module")
def traj_dir(shared_data) -> Path:
    return shared_data / "trajectories"


def _first_last_stamp_text(path: Path, sep=None) -> tuple[str, str]:
    rows = [ln for ln in path.read_text().splitlines() if ln.strip() and not ln.startswith("#")]
    return rows[0].split(sep)[0], rows[-1].split(sep)[0]


def _random_trajectory(n=50, seed=0) -> Trajectory:
    rng = np.random.default_rng(seed)
    poses = np.tile(np.eye(4), (n, 1, 1))
    for i in range(n):
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        x, y, z, w = q
        poses[i, :3, :3] = [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
        poses[i, :3, 3] = rng.normal(scale=100.0, size=3)
    # rotations of exactly 180 degrees exercise every branch of the quaternion conversion
    poses[0, :3, :3] = np.diag([1.0, -1.0, -1.0])
    poses[1, :3, :3] = np.diag([-1.0, 1.0, -1.0])
    poses[2, :3, :3] = np.diag([-1.0, -1.0, 1.0])
    stamps = 1_700_000_000_123_456_789 + np.cumsum(rng.integers(1, 10**8, size=n))
    return Trajectory(stamps=stamps, poses=poses)


# ------------------------------------------------------------------------- reading real files


@pytest.mark.parametrize("name", TUM_FILES)
def test_read_tum_real_files_match_independent_parsers(traj_dir, name):
    path = traj_dir / name
    traj = read_tum(path)
    raw = np.loadtxt(path, comments="#")
    assert len(traj) == len(raw)
    # stamps: exact decimal text of the first/last line, and float seconds for all
    first, last = _first_last_stamp_text(path)
    assert traj.stamps[0] == int(Decimal(first) * 10**9)
    assert traj.stamps[-1] == int(Decimal(last) * 10**9)
    np.testing.assert_allclose(traj.stamps * 1e-9, raw[:, 0], rtol=0, atol=1e-6)
    # positions exactly as written; full poses as evo reads them
    np.testing.assert_array_equal(traj.positions, raw[:, 1:4])
    evo_traj = file_interface.read_tum_trajectory_file(str(path))
    assert evo_traj.num_poses == len(traj)
    np.testing.assert_allclose(traj.poses, np.asarray(evo_traj.poses_se3), atol=1e-9)
    assert detect_trajectory_format(path) == "tum"


def test_known_first_stamps(traj_dir):
    assert read_tum(traj_dir / "fr2_desk_ORB.txt").stamps[0] == 1311868164363181000
    assert read_tum(traj_dir / "fr2_desk_groundtruth.txt").stamps[0] == 1311868163869700000
    # scientific notation keeps all digits (float seconds would lose the last ones)
    assert read_tum(traj_dir / "V102.txt").stamps[0] == 1403715529112143517


def test_read_kitti_real_files(traj_dir):
    for name in ("KITTI_00_gt.txt", "KITTI_00_ORB.txt"):
        path = traj_dir / name
        traj = read_kitti(path)
        raw = np.loadtxt(path).reshape(-1, 3, 4)
        assert len(traj) == len(raw) == 4541
        np.testing.assert_array_equal(traj.positions, raw[:, :, 3])
        # rotations are projected onto SO(3): within the file's 6-9 printed digits
        np.testing.assert_allclose(traj.poses[:, :3, :3], raw[:, :, :3], atol=2e-6)
        R = traj.poses[:, :3, :3]
        np.testing.assert_allclose(R @ np.transpose(R, (0, 2, 1)), np.tile(np.eye(3), (len(R), 1, 1)), atol=1e-12)
        # without a times file the stamp is the frame index in seconds
        np.testing.assert_array_equal(traj.stamps, np.arange(4541) * 10**9)
        evo_path = file_interface.read_kitti_poses_file(str(path))
        np.testing.assert_array_equal(traj.positions, evo_path.positions_xyz)
        assert detect_trajectory_format(path) == "kitti"


def test_read_kitti_with_times(traj_dir):
    traj = read_kitti(traj_dir / "KITTI_00_gt.txt", traj_dir / "KITTI_00_gt_times.txt")
    times = np.loadtxt(traj_dir / "KITTI_00_gt_times.txt")
    assert len(traj) == len(times)
    np.testing.assert_allclose(traj.stamps * 1e-9, times, atol=1e-9)
    assert traj.stamps[1] == 103735900  # "1.037359e-01" s
    assert traj.stamps[-1] == 470581600000  # "4.705816e+02" s


def test_read_euroc_groundtruth_with_extra_columns(traj_dir):
    path = traj_dir / "V102_groundtruth.csv"
    traj = read_euroc(path)
    stamps = np.loadtxt(path, delimiter=",", comments="#", usecols=0, dtype=np.int64)
    raw = np.loadtxt(path, delimiter=",", comments="#")
    assert raw.shape[1] == 17  # the ground truth has velocities and biases too
    assert len(traj) == len(stamps) == 16702
    np.testing.assert_array_equal(traj.stamps, stamps)
    assert traj.stamps[0] == 1403715524907143168 and traj.stamps[-1] == 1403715608412143104
    np.testing.assert_array_equal(traj.positions, raw[:, 1:4])
    evo_traj = file_interface.read_euroc_csv_trajectory(str(path))
    np.testing.assert_allclose(traj.poses, np.asarray(evo_traj.poses_se3), atol=1e-9)
    # w-first in the file: the first quaternion (w=0.161996, x=0.789985, ...) round-trips
    q = rotation_to_quat(traj.poses[0, :3, :3])
    q_file = np.array([0.789985, -0.205376, 0.554528, 0.161996])
    q_file /= np.linalg.norm(q_file)
    assert np.allclose(q, q_file, atol=1e-9) or np.allclose(q, -q_file, atol=1e-9)
    assert detect_trajectory_format(path) == "euroc"


def test_read_trajectory_dispatch(traj_dir):
    a = read_trajectory(traj_dir / "fr2_desk_ORB.txt")
    b = read_trajectory(traj_dir / "fr2_desk_ORB.txt", "tum")
    np.testing.assert_array_equal(a.poses, b.poses)
    k = read_trajectory(traj_dir / "KITTI_00_gt.txt", "kitti", times_path=traj_dir / "KITTI_00_gt_times.txt")
    assert k.stamps[-1] == 470581600000
    with pytest.raises(UnsupportedFormatError):
        read_trajectory(traj_dir / "fr2_desk_ORB.txt", "ply")


# ------------------------------------------------------------------------- round trips


@pytest.mark.parametrize("fmt", ["tum", "kitti", "euroc"])
def test_round_trip_random_poses(tmp_path, fmt):
    traj = _random_trajectory()
    out = tmp_path / f"traj.{fmt}"
    times = tmp_path / "times.txt" if fmt == "kitti" else None
    write_trajectory(out, traj, fmt, times_path=times)
    back = read_trajectory(out, fmt, times_path=times)
    assert len(back) == len(traj)
    np.testing.assert_array_equal(back.stamps, traj.stamps)
    np.testing.assert_allclose(back.poses, traj.poses, atol=1e-9, rtol=0)


@pytest.mark.parametrize(
    "name, fmt",
    [("fr2_desk_ORB.txt", "tum"), ("V102_groundtruth.csv", "euroc"), ("KITTI_00_ORB.txt", "kitti"),
     ("V102.txt", "euroc")],
)
def test_round_trip_real_files_through_every_format(traj_dir, tmp_path, name, fmt):
    src = read_trajectory(traj_dir / name)
    for target in ("tum", "euroc", "kitti"):
        out = tmp_path / f"out_{target}.txt"
        times = tmp_path / f"out_{target}_times.txt"
        write_trajectory(out, src, target, times_path=times)
        back = read_trajectory(out, target, times_path=times)
        np.testing.assert_array_equal(back.stamps, src.stamps)
        np.testing.assert_allclose(back.poses, src.poses, atol=1e-9, rtol=0)
        # auto-detection recognises what we wrote
        assert detect_trajectory_format(out) == target


def test_tum_writer_exact_stamp_text(tmp_path):
    traj = Trajectory(stamps=[1311868164363181000, 5], poses=np.tile(np.eye(4), (2, 1, 1)))
    # stamps must be sorted for a reader; the writer prints what it is given
    write_tum(tmp_path / "a.txt", traj)
    lines = (tmp_path / "a.txt").read_text().splitlines()
    assert lines[1].split()[0] == "1311868164.363181"
    assert ns_to_seconds_text(5) == "0.000000005"
    assert ns_to_seconds_text(-1_500_000_000) == "-1.5"


def test_writers_are_atomic_and_refuse_nan(tmp_path):
    out = tmp_path / "t.txt"
    out.write_text("previous content\n")
    bad = _random_trajectory(5)
    bad.poses[3, 0, 3] = np.nan
    for writer in (write_tum, write_kitti, write_euroc):
        with pytest.raises(InvalidPoseError):
            writer(out, bad)
        assert out.read_text() == "previous content\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["t.txt"]


# ------------------------------------------------------------------------- bad input


def _write(tmp_path, text, name="bad.txt"):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_malformed_line_reports_line_number(tmp_path):
    p = _write(tmp_path, "# header\n1.0 0 0 0 0 0 0 1\n\n2.0 0 0 0 0 0 1\n")
    with pytest.raises(TrajectoryFormatError) as e:
        read_tum(p)
    assert e.value.line == 4
    assert "line 4" in str(e.value) and str(p) in str(e.value) and "\n" not in str(e.value)

    p = _write(tmp_path, "1.0 0 0 0 0 0 0 1\n2.0 0 0 zero 0 0 0 1\n")
    with pytest.raises(TrajectoryFormatError) as e:
        read_tum(p)
    assert e.value.line == 2 and "'zero'" in str(e.value)

    p = _write(tmp_path, "1 0 0 0 0 1 0 0 0 0 1\n", "k.txt")
    with pytest.raises(TrajectoryFormatError) as e:
        read_kitti(p)
    assert e.value.line == 1

    p = _write(tmp_path, "#t,x\n100,1,2,3,1,0,0\n", "e.csv")
    with pytest.raises(TrajectoryFormatError) as e:
        read_euroc(p)
    assert e.value.line == 2


def test_nan_and_inf_poses_name_file_and_line(tmp_path):
    p = _write(tmp_path, "1.0 0 0 0 0 0 0 1\n2.0 nan 0 0 0 0 0 1\n")
    with pytest.raises(InvalidPoseError) as e:
        read_tum(p)
    assert "line 2" in str(e.value) and str(p) in str(e.value)
    p = _write(tmp_path, "100,1,2,inf,1,0,0,0\n", "e.csv")
    with pytest.raises(InvalidPoseError, match="line 1"):
        read_euroc(p)


def test_quaternions_normalised_and_zero_rejected(tmp_path):
    p = _write(tmp_path, "1.0 1 2 3 0 0 0 2\n2.0 1 2 3 0 0 2 0\n")
    traj = read_tum(p)
    np.testing.assert_allclose(traj.poses[0, :3, :3], np.eye(3), atol=1e-15)
    np.testing.assert_allclose(traj.poses[1, :3, :3], np.diag([-1.0, -1.0, 1.0]), atol=1e-15)
    p = _write(tmp_path, "1.0 0 0 0 0 0 0 1\n2.0 0 0 0 0 0 0 0\n")
    with pytest.raises(InvalidPoseError, match="line 2"):
        read_tum(p)


def test_unsorted_stamps(tmp_path):
    p = _write(tmp_path, "2.0 0 0 0 0 0 0 1\n1.0 0 0 0 0 0 0 1\n")
    with pytest.raises(UnsortedStampsError, match="line 2"):
        read_tum(p)
    # equal consecutive stamps occur in real files (fr2/desk ground truth) and are kept
    p = _write(tmp_path, "1.0 0 0 0 0 0 0 1\n1.0 0 0 0 0 0 0 1\n")
    assert len(read_tum(p)) == 2


def test_kitti_bad_rotation_and_times_mismatch(tmp_path):
    p = _write(tmp_path, "1 0 0 0 0 1 0 0 0 0 1 0\n2 0 0 0 0 1 0 0 0 0 1 0\n", "k.txt")
    with pytest.raises(InvalidPoseError, match="line 2"):
        read_kitti(p)
    p = _write(tmp_path, "1 0 0 0 0 1 0 0 0 0 1 0\n", "k.txt")
    t = _write(tmp_path, "0.0\n0.1\n", "times.txt")
    with pytest.raises(TrajectoryFormatError, match="2 stamps but the pose file has 1"):
        read_kitti(p, t)


def test_missing_empty_binary_and_unknown_files(tmp_path):
    with pytest.raises(FileMissingError):
        read_trajectory(tmp_path / "nope.txt")
    with pytest.raises(TrajectoryFormatError, match="no poses"):
        read_tum(_write(tmp_path, "# only a comment\n"))
    b = tmp_path / "bin.txt"
    b.write_bytes(b"\x89PNG\r\n\x1a\n\xff\xfe\x00")
    with pytest.raises(UnsupportedFormatError):
        read_trajectory(b)
    with pytest.raises(UnsupportedFormatError, match="5 columns"):
        read_trajectory(_write(tmp_path, "1 2 3 4 5\n"))
