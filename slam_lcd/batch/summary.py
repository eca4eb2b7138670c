"""The batch's own outputs in ``--out``: summary.csv, summary.md and the ATE plot, as one set.

Why an :class:`~slam_lcd.outputs.output_set.OutputSet`: the three files describe the same rows and
are rewritten on every batch run. Published as a set they are never a mix of two runs, and
an interrupted batch writes them marked partial (``PARTIAL.txt`` in ``--out``, saying which
logs did not run). The per-log folders beside them are not part of the set and are never
touched by it.

summary.csv holds numbers at full precision (Python's shortest round-trip repr), so a
reader gets exactly the values of each log's report.json; summary.md rounds for people.
"""
from __future__ import annotations

import csv
import io
from collections.abc import Sequence
from pathlib import Path

from ..files.atomic import write_text
from ..outputs.output_set import OutputSet
from ..runtime.interrupts import signal_name
from .rows import COLUMNS

SUMMARY_OUTPUTS = ("summary.csv", "summary.md", "ate_before_after.png")
PLOT_NAME = "ate_before_after.png"


def _cell(v) -> str:
    if v is None:
        return ""
    if isinstance(v, float):
        return repr(v)
    return str(v)


def summary_csv(rows: Sequence[dict]) -> str:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(COLUMNS)
    for r in rows:
        w.writerow([_cell(r.get(c)) for c in COLUMNS])
    return buf.getvalue()


def read_summary_csv(path: str | Path) -> list[dict]:
    """Rows of a summary.csv with numbers as numbers (empty cells: None)."""
    ints = {"frames", "keyframes", "loops_proposed", "loops_verified", "loops_accepted", "loops_rejected",
            "false_loops"}
    floats = {"ate_before_m", "ate_after_m", "ate_ratio", "wall_s", "log_s", "realtime_factor"}
    rows = []
    with open(path, newline="", encoding="utf-8") as fh:
        for r in csv.DictReader(fh):
            rows.append({k: (None if v == "" and (k in ints or k in floats) else
                             int(v) if k in ints else float(v) if k in floats else v) for k, v in r.items()})
    return rows


def _f(v, fmt: str) -> str:
    return "" if v is None else format(v, fmt)


def summary_md(rows: Sequence[dict], *, engine: str, wall_s: float, interrupted: bool) -> str:
    counts = {s: sum(1 for r in rows if r["status"] == s) for s in dict.fromkeys(r["status"] for r in rows)}
    lines = ["# slam-lcd batch summary", ""]
    if interrupted:
        lines += [f"**Interrupted ({signal_name()}): a partial summary.** "
                  "Logs marked `interrupted` hold a result marked",
                  "partial (or nothing); `cancelled` ones were not run. Run the same command again to finish.", ""]
    lines += [f"- {len(rows)} logs: " + ", ".join(f"{n} {s}" for s, n in counts.items()),
              f"- engine: {engine}; batch wall time {wall_s:.1f} s", "",
              "| log | status | frames | keyframes | loops proposed / accepted / rejected | false loops | "
              "ATE before -> after (m) | wall (s) | real-time factor |",
              "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        loops = (f"{r['loops_proposed']} / {r['loops_accepted']} / {r['loops_rejected']}"
                 if r.get("loops_proposed") is not None else "")
        ate = (f"{r['ate_before_m']:.3f} -> {r['ate_after_m']:.3f} ({r['alignment']})"
               if r.get("ate_before_m") is not None else "")
        lines.append(f"| {r['name']} | {r['status']} | {_cell(r.get('frames'))} | {_cell(r.get('keyframes'))} | "
                     f"{loops} | {_cell(r.get('false_loops'))} | {ate} | {_f(r.get('wall_s'), '.1f')} | "
                     f"{_f(r.get('realtime_factor'), '.2f')} |")
    problems = [r for r in rows if r["status"] in ("error", "interrupted", "cancelled")]
    if problems:
        lines += ["", "## Messages", ""] + [f"- **{r['name']}** ({r['status']}): {r['message']}" for r in problems]
    lines += ["", "Columns: see docs/batch.md. Per-log outputs: `<log name>/` beside this file "
              "(report.md, loops.csv, trajectories, plots)."]
    return "\n".join(lines) + "\n"


def plot_ate_bars(rows: Sequence[dict], out: Path) -> bool:
    """Bars of ATE before / after per log (logs with ground truth); False when none has one."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import numpy as np
    from matplotlib.figure import Figure

    from ..eval.plots import save_figure

    have = [r for r in rows if r.get("ate_before_m") is not None and r.get("ate_after_m") is not None]
    if not have:
        return False
    x = np.arange(len(have))
    fig = Figure(figsize=(max(5.0, 0.9 * len(have) + 2.0), 4.0))
    ax = fig.add_subplot(111)
    w = 0.38
    ax.bar(x - w / 2, [r["ate_before_m"] for r in have], w, label="odometry (before)", color="tab:orange")
    ax.bar(x + w / 2, [r["ate_after_m"] for r in have], w, label="corrected (after)", color="tab:blue")
    ax.set_xticks(x)
    ax.set_xticklabels([r["name"] for r in have], rotation=30 if len(have) > 4 else 0,
                       ha="right" if len(have) > 4 else "center")
    aligns = sorted({r["alignment"] for r in have})
    ax.set_ylabel("ATE RMSE (m)")
    ax.set_title(f"ATE before / after loop closure per log ({', '.join(aligns)} alignment)")
    ax.legend()
    ax.grid(axis="y", alpha=0.3)
    save_figure(fig, out)
    return True


def summary_set(out_dir: str | Path) -> OutputSet:
    return OutputSet(out_dir, SUMMARY_OUTPUTS)


def write_summary(out_dir: str | Path, rows: Sequence[dict], *, engine: str, wall_s: float,
                  interrupted: bool = False) -> list[str]:
    """Write the summary set into ``out_dir`` (marked partial when ``interrupted``); the names written."""
    outputs = summary_set(out_dir)
    try:
        if interrupted:
            not_done = [r["name"] for r in rows if r["status"] in ("interrupted", "cancelled")]

            outputs.mark_partial(f"This batch was interrupted ({signal_name()}): the summary lists every log, "
                                 "but these did "
                                 f"not finish: {', '.join(not_done) or '(none)'}. Run the same command again to "
                                 "finish them (logs with complete outputs are skipped).")
        write_text(outputs.staging / "summary.csv", summary_csv(rows))
        write_text(outputs.staging / "summary.md",
                   summary_md(rows, engine=engine, wall_s=wall_s, interrupted=interrupted))
        try:
            plot_ate_bars(rows, outputs.staging / PLOT_NAME)
        except Exception as e:  # a plot must never cost the user the numbers
            import logging

            logging.getLogger(__name__).warning("ATE plot not written: %s", e)
        return outputs.publish()
    except BaseException:
        outputs.discard()
        raise
