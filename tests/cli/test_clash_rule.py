"""No command writes onto an input or two outputs on one path (docs/robustness.md, "Outputs never land on inputs").

For every command that writes, the table below names each pair of paths it takes that can
clash: an output on an input, an output inside an input folder (a rosbag2 bag read as a whole
or through one of its files, an image folder), an input inside an output folder the output
would replace, and two outputs of the command on one path (or one inside the other's folder).
Each case must end before any work in one line, exit status 2, every input byte-identical and
nothing new on disk.
"""
from __future__ import annotations

import os
import shutil
from pathlib import Path

import pytest

from support.bad_input_files import assert_one_line, run_cli, sha256_tree

ORB = ["--features", "orb", "--no-feature-cache", "--no-progress"]
TOPIC = "/ground_truth/pose"


@pytest.fixture(scope="module")
def logs(tmp_path_factory):
    """A tiny MCAP log, the same as a rosbag2 folder, a TUM file and an image folder, built once."""
    from slam_lcd.sim import make_demo_log

    d = tmp_path_factory.mktemp("clash_inputs")
    make_demo_log(d / "log.mcap", "mcap", frames=10, width=64, height=48)
    make_demo_log(d / "bag2", "rosbag2", frames=10, width=64, height=48)
    (d / "traj.tum").write_text("".join(f"{i}.0 {i * 0.1} 0 0 0 0 0 1\n" for i in range(10)))
    images = d / "images"
    images.mkdir()
    import cv2
    import numpy as np

    rng = np.random.default_rng(0)
    for i in range(3):
        cv2.imwrite(str(images / f"{i}.png"), rng.integers(0, 255, (48, 64), dtype=np.uint8))
    return d


def _tree(folder: Path) -> dict[str, float]:
    return {str(p): p.stat().st_mtime_ns for p in sorted(folder.rglob("*"))} | {
        str(p): 0 for p in folder.rglob(".*")}


# command -> (argv template, needle of the one line). {d}: a private copy of the inputs above.
# {bagfile}: the storage file inside the rosbag2 folder.
CASES = {
    "run": [
        (["run", "{d}/log.mcap", "--out", "{d}/log.mcap", *ORB], "overwrite the input"),
        (["run", "{d}/bag2", "--out", "{d}/bag2", *ORB], "overwrite the input"),
        (["run", "{d}/bag2", "--out", "{d}/bag2/out", *ORB], "inside the input folder"),
        (["run", "{bagfile}", "--out", "{d}/bag2/out", *ORB], "rosbag2 folder"),
        (["run", "{d}/log.mcap", "--out", "{d}/o", "--gt", "{d}/o/odometry.tum", *ORB], "overwrite the input"),
        (["run", "{d}/o/loops/log.mcap", "--out", "{d}/o", *ORB], "lies inside this output folder"),
        (["run", "{d}/log.mcap", "--out", "{d}/o", "--config", "{d}/o/config.yaml", *ORB], "overwrite the input"),
    ],
    "batch": [
        (["batch", "{d}/log.mcap", "--out", "{d}/log.mcap", *ORB], "overwrite the input"),
        (["batch", "{d}/bag2", "--out", "{d}", *ORB], "overwrite the input"),
        (["batch", "{d}/bag2", "--out", "{d}/bag2/runs", *ORB], "inside the input folder"),
        (["batch", "{d}/log.mcap", "--out", "{d}/o", "--vocab", "{d}/o/summary.csv", *ORB], "overwrite the input"),
    ],
    "export": [
        (["export", "{d}/bag2:" + TOPIC, "--to", "rosbag2", "{d}/bag2"], "overwrite the input"),
        (["export", "{d}/bag2:" + TOPIC, "--to", "rosbag2", "{d}/bag2/out"], "inside the input folder"),
        (["export", "{bagfile}:" + TOPIC, "--to", "tum", "{d}/bag2/x.tum"], "rosbag2 folder"),
        (["export", "{d}/log.mcap:" + TOPIC, "--to", "mcap", "{d}/log.mcap"], "overwrite the input"),
        (["export", "{d}/o/traj.tum", "--to", "rosbag2", "{d}/o"], "lies inside this output folder"),
        (["export", "{d}/traj.tum", "--to", "kitti", "{d}/x.kitti", "--times-out", "{d}/x.kitti"],
         "two outputs on one path"),
        (["export", "{d}/traj.tum", "--to", "kitti", "{d}/x.kitti", "--times-out", "{d}/traj.tum"],
         "overwrite the input"),
        (["export", "{d}/traj.tum", "--to", "kitti", "{d}/x.kitti", "--times", "{d}/x.kitti"],
         "overwrite the input"),
        (["export", "{d}/traj.tum", "--to", "rosbag2", "{d}/b", "--times-out", "{d}/b/t.txt"], "only applies"),
    ],
    "make-demo-log": [
        (["make-demo-log", "{d}/x.mcap", "--loops-csv", "{d}/x.mcap", "--frames", "5", "--size", "32x24"],
         "two outputs on one path"),
        (["make-demo-log", "{d}/x", "--format", "rosbag2", "--loops-csv", "{d}/x/l.csv", "--frames", "5"],
         "inside the output folder"),
        (["make-demo-log", "{d}/e.mcap", "--layout", "euroc", "--loops-csv", "{d}/camchain-e.yaml", "--frames", "5"],
         "two outputs on one path"),
    ],
    "ate": [
        (["ate", "{d}/traj.tum", "{d}/traj.tum", "--json", "{d}/traj.tum"], "overwrite the input"),
        (["ate", "{d}/traj.tum", "{d}/log.mcap:" + TOPIC, "--save_plot", "{d}/log.mcap"], "overwrite the input"),
        (["ate", "{d}/traj.tum", "{d}/bag2:" + TOPIC, "--json", "{d}/bag2/r.json"], "inside the input folder"),
        (["ate", "{d}/traj.tum", "{d}/traj.tum", "--json", "{d}/r", "--save_plot", "{d}/r"], "two outputs on one path"),
        (["ate", "{d}/traj.tum", "{d}/traj.tum", "--save_results", "{d}/r", "--save_plot", "{d}/r"],
         "two outputs on one path"),
    ],
    "vocab train": [
        (["vocab", "train", "{d}/images", "--out", "{d}/images/v.npz", *ORB], "inside the input folder"),
        (["vocab", "train", "{d}/log.mcap", "--out", "{d}/log.mcap", *ORB], "overwrite the input"),
        (["vocab", "train", "{d}/bag2", "--out", "{d}/bag2", *ORB], "overwrite the input"),
    ],
    "eval-lcd": [
        (["eval-lcd", "{d}/images", "--gt", "{d}/traj.tum", "--out", "{d}/images", *ORB], "overwrite the input"),
        (["eval-lcd", "{d}/images", "--gt", "{d}/traj.tum", "--out", "{d}/images/e", *ORB], "inside the input folder"),
        (["eval-lcd", "{d}/images", "--gt", "{d}/o/pr.csv", "--out", "{d}/o", *ORB], "overwrite the input"),
    ],
    "demo": [
        (["demo", "--out", "{cache}/demo/demo-f5-seed0-32x24-v{version}.mcap", "--frames", "5", "--size", "32x24",
          *ORB], "two outputs on one path"),
    ],
}


def _cases():
    for cmd, cases in CASES.items():
        for i, (argv, needle) in enumerate(cases):
            yield pytest.param(argv, needle, id=f"{cmd}-{i}")


@pytest.mark.parametrize("argv,needle", list(_cases()))
def test_no_command_writes_onto_an_input_or_two_outputs_on_one_path(logs, tmp_path, capfd, monkeypatch, argv,
                                                                     needle):
    from slam_lcd import __version__

    d = tmp_path / "in"
    shutil.copytree(logs, d)
    (d / "o").mkdir()
    (d / "o" / "loops").mkdir()
    shutil.copy(d / "log.mcap", d / "o" / "loops" / "log.mcap")  # an input inside an output's folder
    for name in ("odometry.tum", "config.yaml", "report.md", "summary.csv", "pr.csv", "traj.tum"):
        text = "1.0 0 0 0 0 0 0 1\n" if name.endswith((".tum", ".csv")) else "run:\n  plots: false\n"
        (d / "o" / name).write_text(text)
    cache = tmp_path / "cache"
    cache.mkdir()
    monkeypatch.setenv("SLAM_LCD_CACHE_DIR", str(cache))
    bagfile = next(p for p in (d / "bag2").iterdir() if p.name != "metadata.yaml")
    args = [a.format(d=d, bagfile=bagfile, cache=cache, version=__version__) for a in argv]
    before_sha, before_tree = sha256_tree(d), _tree(tmp_path)
    rc, _, err = run_cli(args, capfd)
    assert rc == 2, err
    assert_one_line(err, needle)
    assert sha256_tree(d) == before_sha, "an input changed"
    assert _tree(tmp_path) == before_tree, "something was written"


def test_clash_rule_in_the_library():
    """``check_no_clash``: outputs against inputs and against each other; merged folders keep other names."""
    from slam_lcd.errors import InputError
    from slam_lcd.files.atomic import check_no_clash

    root = Path(os.environ.get("TMPDIR", "/tmp"))
    check_no_clash({"OUT": root / "a", "--x": root / "b"}, {"IN": root / "c"})
    check_no_clash({"OUT": root / "d", "name": root / "d" / "n"}, {"IN": root / "d" / "user.txt"}, merged=[root / "d"])
    with pytest.raises(InputError, match="two outputs on one path"):
        check_no_clash({"OUT": root / "a", "--x": root / "a"}, {})
    with pytest.raises(InputError, match="inside the output folder"):
        check_no_clash({"OUT": root / "a", "--x": root / "a" / "x"}, {})
    with pytest.raises(InputError, match="lies inside this output folder"):
        check_no_clash({"OUT": root / "a"}, {"IN": root / "a" / "x"})
