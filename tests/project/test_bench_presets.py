"""tools/bench_presets.py: a preset laid over another, and one part end to end (the figures come from running it)."""
from __future__ import annotations

import json

import torch

from slam_lcd.config import load_config

from support.module_files import load_module
from support.paths import REPO

TOOL = REPO / "tools" / "bench_presets.py"


def load_tool():
    return load_module(TOOL, "bench_presets")


def test_a_preset_is_laid_over_another_by_its_own_keys():
    sets = load_tool().preset_overrides("fast")
    assert sets == ["features.resize_max=320", "features.keypoint_threshold=0.005"]
    cfg = load_config("euroc", sets)  # the EuRoC part: the dataset's preset plus the feature preset's keys
    assert cfg.features.resize_max == 320 and cfg.sensors.image_topic == "/cam0/image_raw"
    assert load_tool().preset_overrides("default") and load_config("default", load_tool().preset_overrides("default"))


def test_forward_part_prints_the_machine_and_the_table(tmp_path, capsys, superpoint_weights):
    threads = torch.get_num_threads()
    try:
        rc = load_tool().main(["--presets", "fast", "--parts", "forward", "--reps", "1", "--weights",
                               str(superpoint_weights), "--json", str(tmp_path / "rows.json")])
    finally:
        torch.set_num_threads(threads)
    assert rc == 0
    out = capsys.readouterr().out
    assert out.startswith("machine: ") and "CPU capability" in out and "| fast | 320 | 320x240 |" in out
    row = json.loads((tmp_path / "rows.json").read_text())["fast"]
    assert row["input"] == "320x240" and row["forward_ms"] > 0 and row["keypoints"] > 50
