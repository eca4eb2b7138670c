"""The checks a run makes on its paths before any work: inputs exist, outputs land on no input, the map apart.

Shared by :func:`slam_lcd.run.runner.run_log` and the command line, which makes them before it loads a
model or takes a map's writer lock, so that a refused command waits for nothing and changes
nothing (docs/robustness.md, "Outputs never land on inputs").
"""
from __future__ import annotations

import os
from pathlib import Path

from ..config import Config
from ..errors import FileMissingError
from ..files.atomic import check_apart, check_no_clash
from ..map.store import check_map_target
from ..outputs.output_set import OutputSet
from ..outputs.write import RUN_OUTPUTS


def run_inputs(log_path, gt_file, cfg: Config, extra=None) -> dict:
    """What the run reads, by the flag that named it (outputs must not land on any of them)."""
    inputs = {"the log": log_path, "--gt": gt_file}
    inputs.update(extra or {})
    if cfg.features.weights:
        inputs["--weights"] = cfg.features.weights
    env = os.environ.get("SLAM_LCD_SUPERPOINT_WEIGHTS")
    if env:
        inputs["$SLAM_LCD_SUPERPOINT_WEIGHTS"] = env
    return inputs


def check_run_paths(log_path, out_dir, cfg: Config, gt_file=None, extra_inputs: dict | None = None,
                    map_dir=None, appended: bool = False) -> OutputSet:
    """Refuse, before any work, a run whose paths cannot work; returns the run's :class:`OutputSet`.

    The log and ``--gt`` must exist; no output may land on or in an input, or hold an input folder;
    the output folder must be writable. ``map_dir`` (``--map``): the map folder is never the output
    folder, inside it or around it; ``appended``: the map is written too, so it must not land on or
    in an input either, and must be a folder a map can be written to.
    """
    log_path, out_dir = Path(log_path), Path(out_dir)
    if not log_path.exists():
        raise FileMissingError("no such log file or directory", log_path)
    if gt_file is not None and not Path(gt_file).is_file():
        raise FileMissingError("ground-truth trajectory file not found (--gt)", gt_file)
    inputs = run_inputs(log_path, gt_file, cfg, extra_inputs)
    if map_dir is not None:
        check_map_paths(map_dir, {"--out": out_dir}, inputs, appended)
        if not appended:
            inputs["--map"] = map_dir
    outputs = OutputSet(out_dir, RUN_OUTPUTS)
    outputs.check(inputs)
    return outputs


def check_map_paths(map_dir, outputs: dict, inputs: dict, appended: bool) -> None:
    """The map folder ``--map`` apart from every output folder; appended, it is an output too: not on or in
    an input, and a folder a map can be written to (:func:`slam_lcd.map.store.check_map_target`)."""
    check_apart("--map", map_dir, outputs)
    if appended:
        check_no_clash({"--map": map_dir}, inputs, merged=[map_dir])
        check_map_target(map_dir, create=True)
