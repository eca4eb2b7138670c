"""One summary row per log: built from a finished run, from an earlier run's report, or from a failure.

Why a row is plain data (a dict of str/int/float/None): it travels back from a worker
process or a Ray node by pickling, and it is what ``summary.csv`` holds, so it must not
carry objects that only make sense in the process that made them.

The columns (:data:`COLUMNS`, explained in docs/batch.md):

- ``status``: ``ok`` (run now, complete outputs; also a run that published its complete set
  just before a Ctrl-C reached it), ``skipped`` (complete outputs of the same
  configuration were there already: nothing was run), ``error`` (the log failed; ``message``
  says why, in one line naming the file), ``interrupted`` (Ctrl-C while it ran: its folder
  holds a set marked partial, or nothing), ``cancelled`` (Ctrl-C before it started);
- the run's figures, as ``slam-lcd run`` reports them (report.json): ``frames``,
  ``keyframes``, ``loops_proposed`` (candidates), ``loops_verified`` (passed geometric
  verification), ``loops_accepted`` (kept by the back end), ``loops_rejected``
  (proposed - accepted: failed verification or rejected by the back end),
  ``false_loops`` (accepted loops whose ground-truth distance is over
  run.loop_true_max_distance; empty without ground truth), ``ate_before_m`` /
  ``ate_after_m`` (RMSE of odometry / corrected trajectory against ground truth, aligned
  with ``alignment``), ``ate_ratio`` (after / before);
- ``wall_s``: the run's wall time (report.json's; for a skipped log the earlier run's),
  ``log_s``: the log's duration, ``realtime_factor``: log_s / wall_s (above 1: faster than
  the recording).
"""
from __future__ import annotations

from pathlib import Path

COLUMNS = ("name", "status", "frames", "keyframes", "loops_proposed", "loops_verified", "loops_accepted",
           "loops_rejected", "false_loops", "ate_before_m", "ate_after_m", "ate_ratio", "alignment",
           "wall_s", "log_s", "realtime_factor", "log", "out", "message")
STATUSES = ("ok", "skipped", "error", "interrupted", "cancelled")


def _base(name: str, log, out, status: str, message: str = "") -> dict:
    row = dict.fromkeys(COLUMNS)
    row.update(name=name, status=status, log=str(log), out=str(out), message=message, alignment="")
    return row


def _figures(row: dict, *, frames, keyframes, proposed, verified, accepted, false_loops, ate_before, ate_after,
             alignment, wall_s, log_s) -> dict:
    row.update(frames=int(frames), keyframes=int(keyframes), loops_proposed=int(proposed),
               loops_verified=int(verified), loops_accepted=int(accepted),
               loops_rejected=int(proposed) - int(accepted),
               false_loops=None if false_loops is None else int(false_loops),
               ate_before_m=None if ate_before is None else float(ate_before),
               ate_after_m=None if ate_after is None else float(ate_after),
               alignment=alignment or "", wall_s=float(wall_s), log_s=float(log_s))
    if ate_before is not None and ate_after is not None and ate_before:
        row["ate_ratio"] = float(ate_after) / float(ate_before)
    if wall_s and wall_s > 0:
        row["realtime_factor"] = float(log_s) / float(wall_s)
    return row


def row_from_result(name: str, log, result) -> dict:
    """The row of a run that just finished (a :class:`slam_lcd.run.runner.RunResult`)."""
    status = "interrupted" if result.interrupted else "ok"
    message = "interrupted (Ctrl-C): a partial result, see PARTIAL.txt" if result.interrupted else ""
    row = _base(name, log, result.out_dir, status, message)
    return _figures(row, frames=result.n_frames, keyframes=result.n_keyframes, proposed=result.loops_proposed,
                    verified=result.loops_verified, accepted=result.loops_accepted,
                    false_loops=result.false_loops_accepted, ate_before=result.ate_before,
                    ate_after=result.ate_after, alignment=result.alignment, wall_s=result.wall_s,
                    log_s=result.log_duration_s)


def row_from_report(name: str, log, out_dir, report: dict, status: str = "skipped", message: str = "") -> dict:
    """The row of an earlier run, from the report.json it wrote (a skipped log)."""
    loops = report.get("loops") or {}
    ev = report.get("eval") or None  # report.json schema 1 (slam_lcd/outputs/report_schema.py)
    ate = ev["ate"] if ev else None
    row = _base(name, log, out_dir, status, message)
    return _figures(row, frames=report["frames"], keyframes=report["keyframes"], proposed=loops["candidates"],
                    verified=loops["verified"], accepted=loops["accepted"], false_loops=loops.get("false_accepted"),
                    ate_before=ate["before"]["translation_m"]["rmse"] if ate else None,
                    ate_after=ate["after"]["translation_m"]["rmse"] if ate else None,
                    alignment=ev["alignment"] if ev else "", wall_s=report["wall_s"], log_s=report["log_duration_s"])


def error_row(name: str, log, out_dir, message: str) -> dict:
    """A log that failed: its one-line message (which names the file)."""
    return _base(name, log, out_dir, "error", " ".join(str(message).split()))


def interrupted_row(name: str, log, out_dir) -> dict:
    """A log whose run was stopped by Ctrl-C before it could report (its folder says what is there)."""
    out = Path(out_dir)
    held = "a set marked partial (PARTIAL.txt)" if (out / "PARTIAL.txt").exists() else "no new outputs"
    return _base(name, log, out_dir, "interrupted", f"interrupted (Ctrl-C) before it finished: {held}")


def cancelled_row(name: str, log, out_dir) -> dict:
    return _base(name, log, out_dir, "cancelled", "not run: the batch was interrupted (Ctrl-C) before it started")
