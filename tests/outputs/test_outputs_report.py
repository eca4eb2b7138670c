"""What a run says about itself: report.json versioned and read back through its
schema, loops.csv with one header whatever the candidate count, no ratio against a ~0
odometry error, no warning for a camera that is the body frame."""
from __future__ import annotations

import csv
import json
import logging

import numpy as np
import pytest

from slam_lcd.outputs.loops import loop_columns, write_loops_csv
from slam_lcd.outputs.report_schema import REPORT_SCHEMA, REPORT_SCHEMA_VERSION, check_report
from slam_lcd.outputs.result import RunResult


def _header(path):
    with open(path, newline="") as fh:
        return next(csv.reader(fh))


def test_loops_csv_header_same_with_0_and_100_candidates(report_run, tmp_path):
    rc, out, _ = report_run
    assert rc == 0
    rows = list(csv.DictReader(open(out / "loops.csv")))
    assert len(rows) >= 100  # the demo run proposes a few hundred candidates
    write_loops_csv(tmp_path / "empty.csv", [])
    write_loops_csv(tmp_path / "hundred.csv", rows[:100])
    assert _header(tmp_path / "empty.csv") == _header(out / "loops.csv") == _header(tmp_path / "hundred.csv")
    assert _header(out / "loops.csv") == loop_columns()
    assert (tmp_path / "empty.csv").read_text().count("\n") == 1


def test_report_json_round_trips_through_its_schema(report_run):
    rc, out, log = report_run
    rep = json.loads((out / "report.json").read_text())
    assert check_report(rep) == []
    jsonschema = pytest.importorskip("jsonschema", reason="the independent validator is optional")
    jsonschema.validate(rep, REPORT_SCHEMA)
    assert rep["schema"] == REPORT_SCHEMA_VERSION
    assert rep["input"]["log"] == str(log)
    assert rep["input"]["gt_source"] == f"topic {rep['input']['topics']['gt']}"
    assert rep["command_line"][:2] == ["slam-lcd", "run"] and "eval.rpe_delta=2.0" in rep["command_line"]
    assert rep["config_overrides"] == ["eval.rpe_delta=2.0"]
    ev = rep["eval"]
    assert ev["t_max_diff_s"] == 0.02 and ev["rpe_delta"] == 2.0 and ev["alignment"] == "se3"
    for metric in ("ate", "rpe"):
        for when in ("before", "after"):
            e = ev[metric][when]
            assert e["pairs"] > 0 and e["rotation_deg"]["rmse"] > 0 and e["translation_m"]["rmse"] > 0
    assert ev["ate"]["after"]["rotation_deg"]["rmse"] < ev["ate"]["before"]["rotation_deg"]["rmse"]
    accepted = [r for r in csv.DictReader(open(out / "loops.csv")) if r["backend_verdict"] == "accepted"]
    assert [(lp["query_id"], lp["match_id"]) for lp in rep["accepted_loops"]] == \
        [(int(r["query_id"]), int(r["match_id"])) for r in accepted]
    assert len(rep["accepted_loops"]) == rep["loops"]["accepted"] > 0
    assert rep["config"]["features"]["kind"] == "orb"


def test_schema_check_names_what_is_wrong(report_run):
    _, out, _ = report_run
    rep = json.loads((out / "report.json").read_text())
    del rep["input"]["log"]
    rep["schema"] = REPORT_SCHEMA_VERSION + 1
    rep["eval"]["ate"]["after"]["pairs"] = "many"
    problems = check_report(rep)
    assert any("report.input: key 'log' missing" in p for p in problems), problems
    assert any(p.startswith("report.schema:") for p in problems), problems
    assert any(p.startswith("report.eval.ate.after.pairs:") for p in problems), problems


def test_no_ratio_against_a_zero_odometry_error():
    r = RunResult(out_dir=None, ate_before=2e-5, ate_after=4e-5, alignment="se3")
    line = [ln for ln in r.summary_lines() if ln.startswith("ATE")][0]
    assert "% of odometry" not in line and "no ratio" in line and r.ate_ratio is None
    r = RunResult(out_dir=None, ate_before=1.0, ate_after=0.25, alignment="se3")
    assert "(25.0% of odometry)" in r.summary_lines()[2]


def test_camera_that_is_the_body_frame_needs_no_transform(caplog):
    from slam_lcd.frontend.config import FrontendConfig
    from slam_lcd.io.tf import TfBuffer
    from slam_lcd.sensors.mounting import camera_mounting

    with caplog.at_level(logging.WARNING):
        T = camera_mounting(FrontendConfig(), TfBuffer(), "openni_rgb_optical_frame",
                            body_frame="openni_rgb_optical_frame")
        assert np.array_equal(T, np.eye(4)) and not caplog.records
        camera_mounting(FrontendConfig(), TfBuffer(), "camera", body_frame="base_link")
    assert any("no transform base_link -> camera" in r.getMessage() for r in caplog.records)
