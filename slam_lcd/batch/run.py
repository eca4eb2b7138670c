"""``run_batch``: many logs, one ``slam-lcd run`` each, one summary.

Order of work:

1. Before any log runs: the logs are found (:mod:`slam_lcd.batch.discovery`), the summary's
   place is checked (writable, not an input), the ground truth of each log is looked up
   (``gt_dir``), a vocabulary is read once to check it, and SuperPoint weights are found
   once (so a missing file fails the batch at once rather than every log, and a download
   happens once, not once per worker).
2. Logs whose folder holds complete outputs of this configuration are skipped
   (:mod:`slam_lcd.batch.done`) unless ``force``; the others go to the engine.
3. Rows arrive as logs finish: one progress bar for the batch, one status line per log.
4. The summary set is written (marked partial after a Ctrl-C).

A log that fails is an ``error`` row; the others go on. A Ctrl-C stops the batch (see
:mod:`slam_lcd.batch.engines`): finished logs are kept, running ones write partial sets,
the summary is written marked partial and ``BatchResult.interrupted`` is True.
"""
from __future__ import annotations

import logging
import os
import sys
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..config import Config, validate_config
from ..errors import FileMissingError, InputError
from ..features.weights import cache_dir, resolve_weights
from ..files.atomic import check_no_clash
from ..runtime.interrupts import defer_sigint
from ..runtime.progress import progress_bar
from .config import gpus_per_task
from .discovery import LogEntry, discover_logs, ground_truth_in
from .done import completed_report
from .engines import Engine, InlineEngine, LocalPoolEngine, RayEngine, import_ray
from .rows import cancelled_row
from .summary import summary_set, write_summary
from .worker import LogTask, SharedWork, skipped_row

log = logging.getLogger(__name__)


@dataclass
class BatchResult:
    out_dir: Path
    rows: list[dict] = field(default_factory=list)
    interrupted: bool = False
    engine: str = ""
    wall_s: float = 0.0
    outputs: list[str] = field(default_factory=list)

    def count(self, status: str) -> int:
        return sum(1 for r in self.rows if r["status"] == status)

    @property
    def failed(self) -> bool:
        return self.count("error") > 0

    def summary_lines(self) -> list[str]:
        counts = ", ".join(f"{self.count(s)} {s}" for s in ("ok", "skipped", "error", "interrupted", "cancelled")
                           if self.count(s))
        return [f"{len(self.rows)} logs: {counts}" + (" (interrupted: partial summary)" if self.interrupted else ""),
                f"batch wall time: {self.wall_s:.1f} s on {self.engine}",
                f"summary in {self.out_dir}/ ({', '.join(self.outputs)})"]


def status_line(row: dict, done: int, total: int) -> str:
    """One line per finished log: ``[2/4] ok  drive_02: 850 frames, ..., ATE 1.20 -> 0.31 m, 41.2 s``."""
    head = f"[{done}/{total}] {row['status']:<11} {row['name']}"
    if row.get("frames") is None:
        return f"{head}: {row['message']}"
    parts = [f"{row['frames']} frames", f"{row['keyframes']} keyframes",
             f"loops {row['loops_accepted']}/{row['loops_proposed']} accepted"]
    if row.get("ate_before_m") is not None:
        parts.append(f"ATE {row['ate_before_m']:.3f} -> {row['ate_after_m']:.3f} m")
    if row.get("wall_s") is not None:
        parts.append(f"{row['wall_s']:.1f} s")
    return f"{head}: {', '.join(parts)}"


def make_engine(ray: str | None, workers: int | None, config: Config, *, ray_temp_dir=None) -> Engine:
    """The engine for ``--ray`` / ``--workers`` (None workers: one per core, at most one per log)."""
    if ray is not None:
        import_ray()  # an InputError before any work when Ray is missing
        return RayEngine(ray, workers, cpus=config.batch.cpus_per_task,
                         gpus=gpus_per_task(config.batch, config.features),
                         max_retries=config.batch.max_retries, temp_dir=ray_temp_dir)
    if workers is not None and workers < 1:
        raise InputError(f"--workers must be at least 1, got {workers}")
    if workers == 1:
        return InlineEngine()
    n = workers or max(1, int((os.cpu_count() or 1) // max(config.batch.cpus_per_task, 1e-9)))
    return LocalPoolEngine(n)


def _prepare_shared(config: Config, vocab: str | Path | None) -> dict:
    """Work done once for the whole batch, before any log: weights found, vocabulary checked, cache folder."""
    env = {}
    cache = cache_dir(config.features.cache_dir)
    env["SLAM_LCD_CACHE_DIR"] = str(cache.resolve())
    if config.features.kind == "superpoint":
        fc = config.features
        weights = resolve_weights(fc.weights, cache=fc.cache_dir, url=fc.weights_url, sha256=fc.weights_sha256,
                                  allow_download=fc.allow_download)
        if not fc.weights:  # every worker reads the same file (no download per worker)
            env["SLAM_LCD_SUPERPOINT_WEIGHTS"] = str(Path(weights).resolve())
    if vocab is not None:
        from ..vocab import Vocabulary  # lazy: the batch driver loads numpy only to check --vocab

        Vocabulary.load(vocab)  # a VocabularyError now, not one per log
    return env


def _tasks(entries: Sequence[LogEntry], out: Path, gt_dir) -> list[LogTask]:
    tasks = []
    for e in entries:
        gt, problem = None, None
        if gt_dir is not None:
            gt = ground_truth_in(Path(gt_dir), e)
            if gt is None:
                problem = f"{e.path}: no ground-truth file for it in --gt-dir {gt_dir} (looked for {e.name}.*)"
        tasks.append(LogTask(str(e.path), e.name, str(out / e.name), None if gt is None else str(gt), problem))
    return tasks


def run_batch(
    logs: Iterable[str | Path],
    out_dir: str | Path,
    config: Config | None = None,
    *,
    workers: int | None = None,
    ray: str | None = None,
    engine: Engine | None = None,
    force: bool = False,
    image_topic: str | None = None,
    odom_topic: str | None = None,
    depth_topic: str | None = None,
    gt_topic: str | None = None,
    gt_dir: str | Path | None = None,
    vocab: str | Path | None = None,
    write_mcap: bool = True,
    progress: bool = True,
    input_paths: dict | None = None,
    on_row: Callable[[dict], None] | None = None,
    status_stream=None,
) -> BatchResult:
    """Run every log of ``logs`` into ``out_dir/<log name>/`` and write the summary (module docstring).

    ``engine`` (an :class:`~slam_lcd.batch.engines.Engine`) overrides ``workers``/``ray``.
    ``on_row(row)`` is called in this process after each log's row (tests, callers that
    stream results); a ``KeyboardInterrupt`` it raises stops the batch like a Ctrl-C.
    One status line per log goes to ``status_stream`` (default stdout: the lines are the
    batch's result); the bar (``progress``) goes to stderr.
    """
    t0 = time.perf_counter()
    cfg = validate_config(config or Config())
    out = Path(out_dir)
    if gt_dir is not None and not Path(gt_dir).is_dir():
        raise FileMissingError("ground-truth folder not found (--gt-dir)", gt_dir)
    if gt_dir is not None and gt_topic is not None:
        raise InputError("give --gt-topic or --gt-dir, not both")
    if vocab is not None and not Path(vocab).is_file():
        raise FileMissingError("vocabulary file not found (--vocab): train one with `slam-lcd vocab train`, or "
                               "leave --vocab out for the online vocabulary", vocab)
    entries = discover_logs(logs)
    inputs: dict[str, str | Path | None] = {f"log {e.name}": e.path for e in entries}
    inputs.update({"--gt-dir": gt_dir, "--vocab": vocab, **(input_paths or {})})
    # a log's own folder (DIR/<log name>) must not be a log, nor hold one it would replace
    folders = {f"the output folder of log {e.name}": out / e.name for e in entries}
    check_no_clash(folders, inputs, merged=folders.values())
    summary_set(out).check(inputs)
    eng = engine or make_engine(ray, workers, cfg)
    env = _prepare_shared(cfg, vocab)
    tasks = _tasks(entries, out, gt_dir)
    inline = isinstance(eng, InlineEngine)  # this process: its environment and threads are the caller's
    threads = None if inline else max(1, int(round(cfg.batch.cpus_per_task)))
    shared = SharedWork(cfg, image_topic, odom_topic, depth_topic, gt_topic, write_mcap,
                        None if vocab is None else str(Path(vocab).resolve()), {} if inline else env, threads,
                        {k: str(v) for k, v in (input_paths or {}).items() if v is not None})

    rows: dict[str, dict] = {}
    stream = status_stream if status_stream is not None else sys.stdout

    bar: Any = None  # progress_bar's tqdm, StageLine or silent bar, made before take() is first called

    def say(line: str) -> None:
        if hasattr(bar, "write"):  # a tqdm bar: print above it
            bar.write(line, file=stream)
        else:
            print(line, file=stream, flush=True)

    def take(row: dict) -> None:
        rows[row["name"]] = row
        bar.update(1)
        say(status_line(row, len(rows), len(tasks)))
        if on_row is not None:
            on_row(row)

    skipped, todo = [], []
    for t in tasks:
        report = None if (force or t.problem) else completed_report(t.out_dir, cfg, t.log)[0]
        (skipped.append(skipped_row(t, report)) if report is not None else todo.append(t))
    interrupted = False
    try:
        if todo:
            eng.prepare()  # e.g. reaching Ray: fails before the bar, as any bad flag
        bar = progress_bar(total=len(tasks), desc="logs", unit="log", enabled=progress)
        try:
            for row in skipped:
                take(row)
            if todo:
                eng.run(todo, shared, take)
        except KeyboardInterrupt:
            interrupted = True
        finally:
            bar.close()
    finally:
        eng.close()
    ordered = [rows.get(t.name) or cancelled_row(t.name, t.log, t.out_dir) for t in tasks]
    interrupted = interrupted or any(r["status"] in ("interrupted", "cancelled") for r in ordered)
    result = BatchResult(out, ordered, interrupted, eng.name, time.perf_counter() - t0)
    with defer_sigint():
        result.outputs = write_summary(out, ordered, engine=eng.name, wall_s=result.wall_s, interrupted=interrupted)
    return result


__all__ = ["BatchResult", "run_batch", "make_engine", "status_line"]
