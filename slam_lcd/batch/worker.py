"""What runs in a worker for one log: ``slam_lcd.run.runner.run_log``, turned into a summary row.

Why this is its own module: it is the code a worker process (local pool) or a Ray node
imports and calls, so it depends on nothing of the batch's driver side and everything it
gets is plain, picklable data (:class:`LogTask`, :class:`SharedWork`).

Work shared by the tasks of one worker process:

- the feature extractor (SuperPoint weights) is loaded once per process and configuration
  (:func:`shared_extractor`), not once per log;
- a vocabulary file is loaded once per process (:func:`shared_vocabulary`);
- every task uses the driver's cache folder (``$SLAM_LCD_CACHE_DIR``, passed in
  :attr:`SharedWork.env`), so all logs share one feature cache. The cache is safe for
  concurrent writers: each entry is written under a temporary name and renamed into place
  (:func:`slam_lcd.files.atomic.atomic_path`), and entries are keyed by content (extractor
  fingerprint, log identity, topic, stamp), so two writers of one key write the same bytes.

Ctrl-C in a local pool: the driver sets a shared event; each worker's watcher thread then
raises SIGINT in its own process, once, if it is running a log (:func:`pool_worker_init`).
``run_log`` turns that into a result marked partial. Idle workers ignore SIGINT, and a task
that starts after the event is set does not run (a ``cancelled`` row).
"""
from __future__ import annotations

import dataclasses
import json
import os
import signal
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..errors import SlamLcdError
from ..outputs.output_set import _process_alive
from ..run.options import Models, OutputOptions, Sources
from ..runtime.interrupts import STOP_SIGNALS, _terminate, keep_lost_interrupts
from .done import completed_report
from .rows import cancelled_row, error_row, interrupted_row, row_from_report, row_from_result

if TYPE_CHECKING:
    from ..config import Config


@dataclass(frozen=True)
class LogTask:
    """One log of a batch: where it is, its output folder, and its ground truth if any."""

    log: str
    name: str
    out_dir: str
    gt_file: str | None = None
    # a problem found before running (e.g. no ground-truth file in --gt-dir): an error row
    problem: str | None = None


@dataclass(frozen=True)
class SharedWork:
    """What every task of a batch gets the same of (the run's flags, and the shared resources)."""

    config: Config
    image_topic: str | None = None
    odom_topic: str | None = None
    depth_topic: str | None = None
    gt_topic: str | None = None
    write_mcap: bool = True
    vocab_path: str | None = None
    # environment every worker sets before running: the one cache folder, the weights file
    env: dict = field(default_factory=dict)
    # torch / OpenCV threads of a worker process (None: leave the process as it is)
    threads: int | None = None
    # extra inputs (e.g. {"--config": path}) that outputs must never land on
    input_paths: dict = field(default_factory=dict)


# --------------------------------------------------------------------------- per-process shared work
_EXTRACTORS: dict = {}
_VOCABS: dict = {}
LOADS = {"extractor": 0, "vocabulary": 0}  # how often this process loaded one (tests, benchmarks)


def shared_extractor(features_conf):
    """The extractor of ``features_conf``, loaded once per process (weights read once)."""
    from ..features import load_extractor  # lazy: the driver imports this module too; models load in workers

    key = (json.dumps(dataclasses.asdict(features_conf), sort_keys=True, default=str),
           os.environ.get("SLAM_LCD_SUPERPOINT_WEIGHTS"), os.environ.get("SLAM_LCD_CACHE_DIR"))
    ex = _EXTRACTORS.get(key)
    if ex is None:
        ex = _EXTRACTORS[key] = load_extractor(features_conf)
        LOADS["extractor"] += 1
    return ex


def shared_vocabulary(path: str | None):
    """The vocabulary at ``path``, loaded once per process (and again only if the file changes)."""
    if path is None:
        return None
    from ..vocab import Vocabulary  # lazy: as load_extractor above

    p = Path(path)
    st = p.stat() if p.is_file() else None
    key = (str(p.resolve()), st.st_size if st else None, st.st_mtime_ns if st else None)
    voc = _VOCABS.get(key)
    if voc is None:
        voc = _VOCABS[key] = Vocabulary.load(p)
        LOADS["vocabulary"] += 1
    return voc


def limit_threads(n: int | None) -> None:
    """torch and OpenCV threads of this process (N workers on N cores: one thread each)."""
    if not n:
        return
    for var in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
        os.environ[var] = str(n)
    import cv2
    import torch

    cv2.setNumThreads(n)
    if torch.get_num_threads() != n:
        torch.set_num_threads(n)


# --------------------------------------------------------------------------- Ctrl-C in a local pool
# stop: the pool's shared stop event (None: not a pool worker); orphaned: the driver is gone
_POOL: dict[str, Any] = {"stop": None, "orphaned": False}
_RUNNING = threading.Event()
DRIVER_POLL_S = 0.25  # how often a pool worker checks that the batch's driver is still there
ORPHAN_STOP_S = 60.0  # the most an orphaned worker waits for its running log to write its partial set


def pool_worker_init(stop_event, threads: int | None, driver_pid: int | None = None) -> None:
    """Initializer of a local-pool worker process (see the module docstring, Ctrl-C).

    The worker leaves the terminal's process group, so a Ctrl-C reaches only the driver,
    which passes it on through ``stop_event``: each running log gets exactly one SIGINT.
    SIGTERM and SIGHUP sent to the worker itself (``systemd`` stops every process of a
    service) stop its running log the same way; an idle worker leaves them to the driver.
    When the driver (``driver_pid``) is gone, whatever killed it, the worker stops its running
    log (a partial set), runs nothing more and exits.
    """
    try:
        os.setpgrp()
    except OSError:  # pragma: no cover - already a group leader
        pass
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    for s in STOP_SIGNALS:
        signal.signal(s, signal.SIG_IGN)
    keep_lost_interrupts()  # the SIGINT a stop forwards must not be lost in a finaliser either
    _POOL["stop"] = stop_event
    if threads:
        for var in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
            os.environ[var] = str(threads)
    threading.Thread(target=_forward_stop, args=(stop_event,), name="slam-lcd-batch-stop", daemon=True).start()
    if driver_pid is not None:
        threading.Thread(target=_watch_driver, args=(driver_pid,), name="slam-lcd-batch-driver", daemon=True).start()


def _forward_stop(stop_event) -> None:
    stop_event.wait()
    if _RUNNING.is_set():
        signal.raise_signal(signal.SIGINT)


def _watch_driver(driver_pid: int) -> None:
    """Stop this worker once the batch's driver is gone (see :func:`pool_worker_init`)."""
    while _process_alive(driver_pid) and os.getppid() != 1:
        time.sleep(DRIVER_POLL_S)
    _POOL["orphaned"] = True
    if _RUNNING.is_set():
        signal.raise_signal(signal.SIGINT)  # the running log writes its partial set
        deadline = time.monotonic() + ORPHAN_STOP_S
        while _RUNNING.is_set() and time.monotonic() < deadline:
            time.sleep(0.05)
    os._exit(128 + signal.SIGTERM)


# --------------------------------------------------------------------------- one log
def run_task(task: LogTask, shared: SharedWork) -> dict:
    """Run one log and return its summary row; never raises for a failing log (an error row)."""
    stop = _POOL["stop"]
    if stop is None:
        return _run(task, shared)
    _RUNNING.set()  # before the stop check: a stop set after it is forwarded as SIGINT
    signal.signal(signal.SIGINT, signal.default_int_handler)
    for s in STOP_SIGNALS:
        signal.signal(s, _terminate)
    try:
        if stop.is_set() or _POOL["orphaned"]:
            return cancelled_row(task.name, task.log, task.out_dir)
        return _run(task, shared)
    finally:
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        for s in STOP_SIGNALS:
            signal.signal(s, signal.SIG_IGN)
        _RUNNING.clear()


def _run(task: LogTask, shared: SharedWork) -> dict:
    from ..run.runner import run_log  # at call time: tests patch it on runner

    if task.problem:
        return error_row(task.name, task.log, task.out_dir, task.problem)
    for k, v in shared.env.items():
        if os.environ.get(k) != v:
            os.environ[k] = v
    started_ns = time.time_ns()
    try:
        limit_threads(shared.threads)
        cfg = shared.config
        extractor = shared_extractor(cfg.features)
        vocab = shared_vocabulary(shared.vocab_path)
        sources = Sources(image_topic=shared.image_topic, odom_topic=shared.odom_topic, gt_topic=shared.gt_topic,
                          depth_topic=shared.depth_topic, gt_file=task.gt_file)
        result = run_log(task.log, Path(task.out_dir), cfg, sources=sources,
                         models=Models(extractor=extractor, vocab=vocab),
                         output=OutputOptions(progress=False, write_mcap=shared.write_mcap,
                                              input_paths=shared.input_paths))
    except KeyboardInterrupt:
        return stopped_row(task, shared.config, started_ns)
    except SlamLcdError as e:
        return error_row(task.name, task.log, task.out_dir, str(e))
    except OSError as e:
        where = f"{e.filename}: " if getattr(e, "filename", None) else f"{task.log}: "
        return error_row(task.name, task.log, task.out_dir, f"{where}{e.strerror or e}")
    except Exception as e:  # a bug met on one log must not cost the batch the others
        return error_row(task.name, task.log, task.out_dir,
                         f"{task.log}: internal error ({type(e).__name__}: {e}); rerun it alone with "
                         "`slam-lcd run --debug` for the traceback")
    return row_from_result(task.name, task.log, result)


def stopped_row(task: LogTask, config, since_ns: int) -> dict:
    """The row of a log whose run a Ctrl-C stopped before it returned a result.

    Why not always ``interrupted``: the Ctrl-C can land just after the run published its
    complete set (between the rename and the return). That folder is a finished result of
    this configuration, written since ``since_ns``: it is reported ``ok``, from its report.
    """
    report, _ = completed_report(task.out_dir, config, task.log)
    try:
        fresh = report is not None and (Path(task.out_dir) / "report.json").stat().st_mtime_ns >= since_ns
    except OSError:
        fresh = False
    if fresh:
        assert report is not None  # fresh: the report was read
        return row_from_report(task.name, task.log, task.out_dir, report, status="ok",
                               message="finished as the batch was interrupted (Ctrl-C)")
    return interrupted_row(task.name, task.log, task.out_dir)


def skipped_row(task: LogTask, report: dict) -> dict:
    """The row of a log whose complete outputs exist (nothing is run)."""
    return row_from_report(task.name, task.log, task.out_dir, report, status="skipped",
                           message="complete outputs of this configuration exist (--force redoes it)")
