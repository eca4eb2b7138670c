"""Is a log already done? The test that makes a re-run of the same batch do no work.

A log counts as done when its output folder holds a complete set (see
:mod:`slam_lcd.outputs.output_set`) of a run of the same configuration on the same log:

- no ``PARTIAL.txt`` (an interrupted or half-replaced set is redone);
- ``report.json`` reads, says the run was not interrupted, and every output it lists (files, and
  folders such as ``loops/``) exists;
- ``config.yaml`` is the configuration this batch would run with, byte for byte (a changed
  ``--set`` redoes the log instead of serving stale results);
- the log is not newer than the report (a re-recorded log is redone).

Flags outside the configuration (topics, ``--gt``) are not compared: ``--force`` redoes a log
whatever its folder holds.
"""
from __future__ import annotations

import json
from pathlib import Path

from ..config import Config, dump_config
from ..outputs.output_set import PARTIAL_MARKER


def _newest_mtime(path: Path) -> int:
    if path.is_dir():
        return max((f.stat().st_mtime_ns for f in path.rglob("*") if f.is_file()), default=path.stat().st_mtime_ns)
    return path.stat().st_mtime_ns


def completed_report(out_dir: str | Path, config: Config, log: str | Path) -> tuple[dict | None, str]:
    """``(report, "")`` when the log is done (see the module docstring), else ``(None, why not)``."""
    out = Path(out_dir)
    if not out.is_dir():
        return None, "no earlier outputs"
    if (out / PARTIAL_MARKER).exists():
        return None, "earlier outputs are partial"
    try:
        report = json.loads((out / "report.json").read_text(encoding="utf-8"))
        saved_config = (out / "config.yaml").read_text(encoding="utf-8")
    except (OSError, ValueError):
        return None, "earlier outputs are incomplete"
    if not isinstance(report, dict) or report.get("interrupted", True):
        return None, "earlier outputs are partial"
    listed = report.get("outputs")
    if not isinstance(listed, list) or not all(isinstance(n, str) and (out / n).exists() for n in listed):
        return None, "earlier outputs are incomplete"
    if saved_config != dump_config(config):
        return None, "earlier outputs are of another configuration"
    try:
        if _newest_mtime(Path(log)) > (out / "report.json").stat().st_mtime_ns:
            return None, "the log is newer than its outputs"
    except OSError:
        return None, "the log cannot be read"
    return report, ""
