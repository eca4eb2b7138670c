"""`slam-lcd ate` takes evo's flags with evo's meanings and gives evo's numbers.

Every flag (`-r` with each pose relation, `-a`, `-s`, `-as`, `--n_to_align`, `--align_origin`,
`--t_max_diff`, `--t_offset`, and with `--rpe`: `--delta`, `--delta_unit` f/m/d/r,
`--all_pairs`, `--pairs_from_reference`) is run through the CLI on the real KITTI-00 and
TUM fr2/desk trajectories and on a demo run's corrected trajectory, and each statistic is
compared with evo's own `main_ape.ape` / `main_rpe.rpe` on evo's own file readers. Equal
means within 1e-6 (relative for figures above 1, such as sse). `--save_results` writes an
archive that evo's `load_res_file` reads back with the same statistics.
"""
from __future__ import annotations

import copy
import json
import shlex

import pytest

from slam_lcd.cli.main import main

evo_file = pytest.importorskip("evo.tools.file_interface")
from evo.core import metrics as evo_metrics  # noqa: E402
from evo.core import sync as evo_sync  # noqa: E402
from evo.main_ape import ape as evo_ape  # noqa: E402
from evo.main_rpe import rpe as evo_rpe  # noqa: E402

RELATIONS = {
    "full": evo_metrics.PoseRelation.full_transformation,
    "trans_part": evo_metrics.PoseRelation.translation_part,
    "rot_part": evo_metrics.PoseRelation.rotation_part,
    "angle_deg": evo_metrics.PoseRelation.rotation_angle_deg,
    "angle_rad": evo_metrics.PoseRelation.rotation_angle_rad,
    "point_distance": evo_metrics.PoseRelation.point_distance,
    "point_distance_error_ratio": evo_metrics.PoseRelation.point_distance_error_ratio,
}
UNITS = {"f": evo_metrics.Unit.frames, "m": evo_metrics.Unit.meters, "d": evo_metrics.Unit.degrees,
         "r": evo_metrics.Unit.radians}

# flags given to `slam-lcd ate` (evo's spelling); every flag of the issue appears on every data set
APE_CASES = [
    "", "-a", "-s", "-as", "-a --n_to_align 100", "-as --n_to_align 100", "--align_origin", "-s --align_origin",
    "-r full", "-r rot_part", "-r angle_deg", "-r angle_rad", "-r point_distance", "-a -r full", "-as -r angle_deg",
    "--align_origin -r rot_part",
]
TIMED_APE_CASES = ["-a --t_max_diff 0.02", "-as --t_max_diff 0.005", "-a --t_offset 0.004",
                   "-a --t_max_diff 0.03 --t_offset -0.012"]
RPE_CASES = [
    "--rpe", "--rpe -d 10", "--rpe -d 10 -u f --all_pairs", "--rpe -d 1 -u m", "--rpe -d 1 -u m --pairs_from_reference",
    "--rpe -d 0.5 -u m --all_pairs", "--rpe -d 0.5 -u m --all_pairs --pairs_from_reference", "--rpe -d 5 -u d",
    "--rpe -d 0.1 -u r --pairs_from_reference", "--rpe -d 2 -u m -r angle_deg", "--rpe -d 2 -u m -as -r full",
    "--rpe -d 10 -r point_distance", "--rpe -d 10 -as -r point_distance_error_ratio", "--rpe -d 1 -u m -a -r rot_part",
    "--rpe -d 1 -u m --align_origin -t 0.2 --all_pairs", "--rpe -d 1 -u m -a --n_to_align 100",
]


def parse_flags(text: str) -> dict:
    """What evo's parser would make of the same flags (only those used above)."""
    argv = shlex.split(text)
    o = dict(rpe=False, align=False, correct_scale=False, n_to_align=-1, align_origin=False, relation="trans_part",
             t_max_diff=0.01, t_offset=0.0, delta=1.0, delta_unit="f", delta_tol=0.1, all_pairs=False,
             pairs_from_reference=False)
    i = 0
    while i < len(argv):
        a = argv[i]
        if a == "--rpe":
            o["rpe"] = True
        elif a in ("-a", "-s", "-as"):
            o["align"] = o["align"] or "a" in a
            o["correct_scale"] = o["correct_scale"] or "s" in a
        elif a in ("--align_origin", "--all_pairs", "--pairs_from_reference"):
            o[a[2:]] = True
        else:
            key = {"-r": "relation", "-d": "delta", "-u": "delta_unit", "-t": "delta_tol"}.get(a, a.lstrip("-"))
            i += 1
            value = argv[i]
            o[key] = (value if key in ("relation", "delta_unit")
                      else int(value) if key == "n_to_align" else float(value))
        i += 1
    return o


def evo_stats(ref_e, est_e, o: dict, synced: bool) -> dict:
    if not synced:
        ref_e, est_e = evo_sync.associate_trajectories(ref_e, est_e, max_diff=o["t_max_diff"], offset_2=o["t_offset"])
    ref_e, est_e = copy.deepcopy(ref_e), copy.deepcopy(est_e)
    common = dict(align=o["align"], correct_scale=o["correct_scale"], n_to_align=o["n_to_align"],
                  align_origin=o["align_origin"])
    if o["rpe"]:
        res = evo_rpe(ref_e, est_e, RELATIONS[o["relation"]], delta=o["delta"], delta_unit=UNITS[o["delta_unit"]],
                      rel_delta_tol=o["delta_tol"], all_pairs=o["all_pairs"],
                      pairs_from_reference=o["pairs_from_reference"], **common)
    else:
        res = evo_ape(ref_e, est_e, RELATIONS[o["relation"]], **common)
    return {k: float(v) for k, v in res.stats.items()}, len(res.np_arrays["error_array"])


def ours(ref_path, est_path, flags: str, tmp_path, extra=()) -> dict:
    out = tmp_path / "r.json"
    rc = main(["ate", str(ref_path), str(est_path), *shlex.split(flags), *extra, "--json", str(out)])
    assert rc == 0, flags
    rep = json.loads(out.read_text())
    return rep["rpe" if "--rpe" in flags else "ape"]


def assert_same(mine: dict, theirs: dict, n_theirs: int, what: str) -> None:
    assert mine["n_errors"] == n_theirs, (what, mine["n_errors"], n_theirs)
    for key, value in theirs.items():
        assert abs(mine["stats"][key] - value) <= 1e-6 * max(1.0, abs(value)), (what, key, mine["stats"][key], value)


@pytest.fixture(scope="module")
def kitti_files(tdir):
    """KITTI 00 ground truth and ORB-SLAM estimate: (ref path, est path, evo's ref, evo's est)."""
    ref, est = tdir / "KITTI_00_gt.txt", tdir / "KITTI_00_ORB.txt"
    return ref, est, evo_file.read_kitti_poses_file(str(ref)), evo_file.read_kitti_poses_file(str(est))


@pytest.fixture(scope="module")
def fr2_files(tdir):
    """TUM fr2/desk ground truth and ORB-SLAM estimate: (ref path, est path, evo's ref, evo's est)."""
    ref, est = tdir / "fr2_desk_groundtruth.txt", tdir / "fr2_desk_ORB.txt"
    return ref, est, evo_file.read_tum_trajectory_file(str(ref)), evo_file.read_tum_trajectory_file(str(est))


@pytest.fixture(scope="module")
def demo_run(offline_demo, tmp_path_factory):
    """A demo run's corrected trajectory against the demo log's ground truth (exported to TUM, evo reads text)."""
    proc, out, log, _ = offline_demo
    assert proc.returncode == 0, proc.stderr[-2000:]
    gt = tmp_path_factory.mktemp("demo_gt") / "gt.tum"
    assert main(["export", f"{log}:/ground_truth/pose", "--to", "tum", str(gt)]) == 0
    est = out / "corrected.tum"
    return gt, est, evo_file.read_tum_trajectory_file(str(gt)), evo_file.read_tum_trajectory_file(str(est))


@pytest.mark.parametrize("flags", APE_CASES + RPE_CASES)
def test_kitti00_equals_evo(kitti_files, flags, tmp_path):
    """KITTI files carry no stamps: evo compares pose by index; so do we (stamps 0, 1, 2 ... s)."""
    ref, est, ref_e, est_e = kitti_files
    theirs, n = evo_stats(ref_e, est_e, parse_flags(flags), synced=True)
    assert_same(ours(ref, est, flags, tmp_path), theirs, n, f"KITTI-00 {flags}")


@pytest.mark.parametrize("flags", APE_CASES + TIMED_APE_CASES + RPE_CASES + ["--rpe -d 10 -u d --all_pairs"])
def test_fr2_desk_equals_evo(fr2_files, flags, tmp_path):
    ref, est, ref_e, est_e = fr2_files
    theirs, n = evo_stats(ref_e, est_e, parse_flags(flags), synced=False)
    assert_same(ours(ref, est, flags, tmp_path), theirs, n, f"fr2/desk {flags}")


@pytest.mark.parametrize("flags", ["-a", "-as", "--align_origin", "-a -r angle_deg", "-a --t_max_diff 0.001",
                                   "--rpe -d 1 -u m", "--rpe -d 10 -u d --pairs_from_reference",
                                   "--rpe -d 50 -as --all_pairs -r full"])
def test_demo_run_equals_evo(demo_run, flags, tmp_path):
    ref, est, ref_e, est_e = demo_run
    theirs, n = evo_stats(ref_e, est_e, parse_flags(flags), synced=False)
    assert_same(ours(ref, est, flags, tmp_path), theirs, n, f"demo run {flags}")


def test_save_results_is_read_by_evo(fr2_files, tmp_path):
    ref, est, ref_e, est_e = fr2_files
    for flags in ("-as -r angle_deg", "--rpe -d 1 -u m -a"):
        zip_path = tmp_path / "res.zip"
        mine = ours(ref, est, flags, tmp_path, extra=["--save_results", str(zip_path)])
        res = evo_file.load_res_file(str(zip_path), load_trajectories=True)
        assert res.stats.keys() == mine["stats"].keys()
        for k, v in res.stats.items():
            assert v == pytest.approx(mine["stats"][k], rel=1e-12, abs=1e-12), k
        assert len(res.np_arrays["error_array"]) == mine["n_errors"]
        assert res.info["title"] == mine["title"] and len(res.trajectories) == 2
        theirs, _ = evo_stats(ref_e, est_e, parse_flags(flags), synced=False)
        assert abs(res.stats["rmse"] - theirs["rmse"]) <= 1e-6


def test_rpe_pairs_side_is_said(fr2_files, tmp_path, capsys):
    """Pairs come from the estimate unless --pairs_from_reference (evo's default), and the output says which."""
    ref, est, _, _ = fr2_files
    est_side = ours(ref, est, "--rpe -d 1 -u m", tmp_path)
    ref_side = ours(ref, est, "--rpe -d 1 -u m --pairs_from_reference", tmp_path)
    assert not est_side["pairs_from_reference"] and ref_side["pairs_from_reference"]
    assert est_side["stats"]["rmse"] != ref_side["stats"]["rmse"]
    out = capsys.readouterr().out
    assert "pairs from the estimate" in out and "pairs from the reference" in out
