"""The habits users bring to a CLI.

Global flags before or after the subcommand; one name per concept (old spellings kept as
hidden aliases); every flag's help states its default; near-miss suggestions for mistyped
subcommands, options and `--set` keys; progress bars off with --no-progress and one line
per stage when stderr is not a terminal; image folders read only image files, never a
ground-truth file.
"""
from __future__ import annotations

import argparse
import io

import cv2
import numpy as np
import pytest

from slam_lcd.cli.main import build_parser, main
from slam_lcd.cli.util import subparsers_of


def _run(argv, capsys):
    rc = main(argv)
    out, err = capsys.readouterr()
    return rc, out, err


# ----------------------------------------------------------------------------- global flags
@pytest.mark.parametrize("argv", [
    ["--debug", "info", "{log}"], ["info", "{log}", "--debug"],
    ["-v", "info", "{log}"], ["info", "{log}", "-v"], ["info", "{log}", "--verbose", "--no-progress"],
])
def test_global_flags_before_or_after_the_subcommand(shared_data, capsys, argv):
    log = shared_data / "bags" / "nav2_turtlebot.mcap"
    rc, out, err = _run([a.format(log=log) for a in argv], capsys)
    assert rc == 0, err
    assert "/odom" in out


def test_global_flags_reach_the_command(shared_data, tmp_path, capsys):
    """`--debug` after the subcommand really turns on tracebacks; `-v` after it really logs INFO."""
    from slam_lcd.errors import SlamLcdError

    missing = tmp_path / "nope.mcap"
    assert main(["info", str(missing)]) == 2
    with pytest.raises(SlamLcdError):
        main(["info", str(missing), "--debug"])
    args = build_parser().parse_args(["run", "x.mcap", "--out", "o", "-v"])
    assert args.verbose and not args.debug and not args.no_progress
    args = build_parser().parse_args(["-v", "run", "x.mcap", "--out", "o", "--no-progress"])
    assert args.verbose and args.no_progress
    args = build_parser().parse_args(["vocab", "train", "imgs", "--out", "v.npz", "--debug"])  # nested subcommand
    assert args.debug


# ----------------------------------------------------------------------------- help and names
def _all_options():
    root = build_parser()
    for parser in [root, *subparsers_of(root)]:
        for action in parser._actions:
            if action.option_strings and action.help != argparse.SUPPRESS and not isinstance(
                    action, (argparse._HelpAction, argparse._VersionAction)):
                yield parser.prog, action


def test_every_flag_says_its_default():
    missing = [f"{prog} {'/'.join(a.option_strings)}" for prog, a in _all_options()
               if "default" not in (a.help or "").lower() and "required" not in (a.help or "").lower()]
    assert not missing, missing


def test_one_name_per_concept():
    """The image topic is --image-topic, the output --out, wherever the concept appears."""
    by_prog = {}
    for prog, a in _all_options():
        by_prog.setdefault(prog, set()).update(a.option_strings)
    for prog in ("slam-lcd run", "slam-lcd eval-lcd", "slam-lcd vocab train"):
        assert "--image-topic" in by_prog[prog] and "--topic" not in by_prog[prog], prog
    for prog in ("slam-lcd run", "slam-lcd demo", "slam-lcd eval-lcd", "slam-lcd vocab train", "slam-lcd export",
                 "slam-lcd make-demo-log"):
        assert "--out" in by_prog[prog], prog
    for prog in ("slam-lcd run", "slam-lcd demo", "slam-lcd eval-lcd", "slam-lcd vocab train"):
        assert {"--features", "--weights", "--config", "--set", "--no-feature-cache"} <= by_prog[prog], prog


def test_old_spellings_still_work():
    p = build_parser()
    assert p.parse_args(["eval-lcd", "bag.mcap", "--gt", "g.csv", "--topic", "/cam"]).image_topic == "/cam"
    assert p.parse_args(["vocab", "train", "bag.mcap", "--out", "v.npz", "--topic", "/cam"]).image_topic == "/cam"
    assert p.parse_args(["export", "a.tum", "--to", "mcap", "b.mcap", "--topic", "/t"]).topic == "/t"
    # an output path after the options, or as --out
    assert p.parse_args(["export", "a.tum", "--to", "tum", "b.tum"]).out == "b.tum"
    assert p.parse_args(["export", "a.tum", "--to", "tum", "--out", "b.tum"]).out_opt == "b.tum"
    assert p.parse_args(["make-demo-log", "--frames", "5", "x.mcap"]).out == "x.mcap"


def test_make_demo_log_and_export_take_out(tmp_path, shared_data, capsys):
    assert main(["make-demo-log", "--out", str(tmp_path / "d.mcap"), "--frames", "5", "--size", "64x48"]) == 0
    assert (tmp_path / "d.mcap").is_file()
    src = shared_data / "trajectories" / "fr2_desk_ORB.txt"
    assert main(["export", str(src), "--to", "tum", "-o", str(tmp_path / "x.tum")]) == 0
    assert (tmp_path / "x.tum").is_file()
    assert main(["export", str(src), "--to", "tum", str(tmp_path / "y.tum"), "--out", str(tmp_path / "z.tum")]) == 2
    assert "two output paths" in capsys.readouterr().err


# ----------------------------------------------------------------------------- near misses
@pytest.mark.parametrize("argv, hint", [
    (["rn", "x.mcap"], "did you mean 'run'?"),
    (["vocab", "trian", "x"], "did you mean 'train'?"),
    (["run", "x.mcap", "--out", "o", "--imgae-topic", "/c"], "did you mean --image-topic"),
    (["ate", "a", "b", "-r", "trans"], "did you mean 'trans_part'"),
])
def test_near_miss_suggestions_for_usage_errors(capsys, argv, hint):
    rc, _, err = _run(argv, capsys)
    assert rc == 2 and hint in err and err.count("\n") == 1, err


def test_near_miss_for_set_keys(shared_data, tmp_path, capsys):
    log = shared_data / "bags" / "nav2_turtlebot.mcap"
    rc, _, err = _run(["run", str(log), "--out", str(tmp_path / "o"), "--set", "backend.loop_kernl=huber"], capsys)
    assert rc == 2 and "did you mean backend.loop_kernel" in err and err.count("\n") == 1
    rc, _, err = _run(["run", str(log), "--out", str(tmp_path / "o"), "--config", "defualt"], capsys)
    assert rc == 2 and "did you mean 'default'" in err


# ----------------------------------------------------------------------------- progress
def test_progress_bar_modes(monkeypatch):
    import slam_lcd.runtime.progress as progress

    err = io.StringIO()
    monkeypatch.setattr(progress.sys, "stderr", err)
    assert list(progress.progress_bar(range(5), desc="stage", unit="img", enabled=False)) == list(range(5))
    assert err.getvalue() == ""  # --no-progress: nothing
    assert list(progress.progress_bar(range(5), desc="stage", unit="img")) == list(range(5))
    text = err.getvalue()
    assert text.startswith("stage: 5/5 img in ") and text.count("\n") == 1 and "\r" not in text  # not a terminal
    err.truncate(0)
    err.seek(0)
    monkeypatch.setattr(progress, "stderr_is_terminal", lambda stream=None: True)
    bar = progress.progress_bar(total=3, desc="frames", unit="img")
    for _ in range(3):
        bar.update(1)
    bar.close()
    shown = err.getvalue()
    assert "frames" in shown and "3/3" in shown and "img/s" in shown and "<" in shown  # tqdm: rate and ETA
    err.truncate(0)
    err.seek(0)
    with progress.stage("training", enabled=True):
        pass
    assert "training ..." in err.getvalue() and "training: done in" in err.getvalue()


def test_vocab_train_reports_its_stages(tmp_path, capsys):
    folder = _image_folder(tmp_path)
    rc, out, err = _run(["vocab", "train", str(folder), "--out", str(tmp_path / "v.npz"), "--features", "orb",
                         "--tree", "hkmeans", "--set", "vocab.hk_depth=2"], capsys)
    assert rc == 0, err
    assert "features: 6/6 img in " in err and "training a hkmeans tree" in err
    rc, out, err = _run(["vocab", "train", str(folder), "--out", str(tmp_path / "w.npz"), "--features", "orb",
                         "--tree", "hkmeans", "--set", "vocab.hk_depth=2", "--no-progress"], capsys)
    assert rc == 0 and err == ""


# ----------------------------------------------------------------------------- image folders
def _image_folder(tmp_path):
    """Six textured frames, plus what sits beside frames in real data sets: a GT matrix image,
    a README, a CSV and a file with an image name that is not an image."""
    rng = np.random.default_rng(0)
    folder = tmp_path / "frames"
    folder.mkdir()
    base = (rng.random((120, 160)) * 255).astype(np.uint8)
    base = cv2.GaussianBlur(base, (3, 3), 0)
    for i in range(1, 7):
        cv2.imwrite(str(folder / f"{i}.png"), np.roll(base, 3 * i, axis=1))
    cv2.imwrite(str(folder / "samples_GT.bmp"), (np.eye(6) * 255).astype(np.uint8))
    cv2.imwrite(str(folder / "groundtruth.png"), (np.eye(6) * 255).astype(np.uint8))
    (folder / "README.txt").write_text("frames of a test\n")
    (folder / "pairs.csv").write_text("query,match\n")
    return folder


def test_image_folder_reads_only_frames(tmp_path):
    from slam_lcd.io.image_folder import is_ground_truth_name, list_image_files

    folder = _image_folder(tmp_path)
    names = [p.name for p in list_image_files(folder)]
    assert names == [f"{i}.png" for i in range(1, 7)]  # natural order; no GT, no text files
    assert is_ground_truth_name("samples_GT.bmp") and is_ground_truth_name("loops-gt.png")
    assert not is_ground_truth_name("000100.png") and not is_ground_truth_name("night_lights.png")
    # a file passed as ground truth is left out whatever its name
    cv2.imwrite(str(folder / "7.png"), np.zeros((120, 160), np.uint8))
    assert "7.png" not in [p.name for p in list_image_files(folder, exclude=[folder / "7.png"])]
    # an image name whose contents no decoder recognises is an error naming the file (never a silent skip)
    (folder / "8.png").write_bytes(b"not a png at all")
    from slam_lcd.errors import InputError

    with pytest.raises(InputError, match="8.png"):
        list_image_files(folder)


def test_corridor_gt_is_never_a_frame(shared_data, tmp_path, capsys):
    """The issue's case: `vocab train` on the corridor folder took samples_GT.bmp for an image (85 images)."""
    corridor = shared_data / "rtabmap_corridor"
    if not (corridor / "samples_GT.bmp").is_file():
        pytest.skip("corridor folder not found")
    from slam_lcd.cli.vocab import source_image_count
    from slam_lcd.io.image_folder import list_image_files as list_images

    assert source_image_count(corridor, None) == 84
    assert len(list_images(corridor)) == 84 and all("GT" not in p.name for p in list_images(corridor))
