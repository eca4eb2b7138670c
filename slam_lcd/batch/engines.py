"""Where the logs of a batch run: in this process, in a local process pool, or as Ray tasks.

Why three and no scheduler of our own: one log is one independent task, so a batch needs
only "run these, tell me each result as it comes". ``concurrent.futures`` does that on one
machine with nothing to install; Ray Core does it on a laptop and on a cluster alike, with
resources per task (CPUs, GPU fractions), retries when a node is lost, and ``ray.wait`` to
stream results. Every engine has the same contract (:meth:`Engine.run`):

- ``on_row(row)`` is called in the driver as each log finishes, in completion order;
- a Ctrl-C (``KeyboardInterrupt`` in the driver, also one raised by ``on_row``) stops the
  batch: logs not started are not run, running ones are asked to stop and write their
  result so far (marked partial), their rows are still delivered, and the
  ``KeyboardInterrupt`` is raised again for the caller to finish the summary.
"""
from __future__ import annotations

import logging
import os
import time
from collections.abc import Callable, Sequence
from pathlib import Path

from ..errors import InputError
from .rows import error_row, interrupted_row
from .worker import LogTask, SharedWork, pool_worker_init, run_task, stopped_row

log = logging.getLogger(__name__)

OnRow = Callable[[dict], None]
# seconds the driver waits, after a Ctrl-C, for running Ray tasks to write their partial sets
RAY_STOP_WAIT_S = 60.0
# modules the local pool's fork server imports once for all its workers
PRELOAD = ["slam_lcd.batch.worker", "slam_lcd.run.runner", "slam_lcd.run.pipeline",
           "slam_lcd.features.superpoint_extractor"]


class Engine:
    name = "engine"

    def prepare(self) -> None:
        """Start what the engine needs (a Ray connection) before any log; errors here stop the batch."""

    def close(self) -> None:
        """Release what :meth:`prepare` started."""

    def run(self, tasks: Sequence[LogTask], shared: SharedWork, on_row: OnRow) -> None:
        raise NotImplementedError


class InlineEngine(Engine):
    """One log after the other in this process (``--workers 1``): what N ``slam-lcd run`` would do."""

    name = "inline"

    def run(self, tasks, shared, on_row) -> None:
        for task in tasks:
            row = run_task(task, shared)
            on_row(row)
            if row["status"] == "interrupted":  # run_log took the Ctrl-C and wrote a partial set
                raise KeyboardInterrupt


class LocalPoolEngine(Engine):
    """``workers`` processes on this machine (``concurrent.futures.ProcessPoolExecutor``).

    Workers are forked from a fresh server process (multiprocessing's ``forkserver``), not
    from the driver: a fork of a driver that has started torch or OpenMP threads can
    deadlock. The server imports the run's modules (torch, GTSAM, OpenCV) once, so each
    worker starts without paying that import again. Each worker is one process for its
    whole life: the weights it loads serve every log it runs.
    """

    name = "local"

    def __init__(self, workers: int):
        self.workers = max(1, int(workers))

    def run(self, tasks, shared, on_row) -> None:
        import multiprocessing as mp
        from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait

        ctx = mp.get_context("forkserver")
        ctx.set_forkserver_preload(PRELOAD)
        stop = ctx.Event()
        ex = ProcessPoolExecutor(max_workers=min(self.workers, len(tasks)) or 1, mp_context=ctx,
                                 initializer=pool_worker_init, initargs=(stop, shared.threads, os.getpid()))
        futures = {ex.submit(run_task, t, shared): t for t in tasks}
        # every future whose row has not been handed on yet: a Ctrl-C while one row is handed on
        # leaves the others that finished in the same wait to the handler below, not lost
        unreported = set(futures)
        try:
            while unreported:
                done, _ = wait(unreported, return_when=FIRST_COMPLETED)
                for f in done:
                    unreported.discard(f)
                    on_row(_future_row(f, futures[f]))
        except KeyboardInterrupt:
            stop.set()  # workers: running logs get one SIGINT each, tasks not started do not run
            for f in unreported:
                f.cancel()
            for f in unreported:
                if not f.cancelled():
                    on_row(_future_row(f, futures[f]))
            raise
        finally:
            _shut_down(ex, stop)


def _shut_down(ex, stop) -> None:
    """Stop the pool on every way out: wait for its workers; a further interrupt kills them.

    A worker left running would go on with the logs queued to it after the batch stopped (and
    publish them); its own watcher stops it should this process die outright
    (:func:`slam_lcd.batch.worker.pool_worker_init`).
    """
    try:
        ex.shutdown(wait=True, cancel_futures=True)
    except BaseException:  # a second Ctrl-C / SIGTERM while waiting: no more waiting
        stop.set()
        for p in list((getattr(ex, "_processes", None) or {}).values()):
            try:
                p.kill()
            except (OSError, ValueError):
                pass
        try:
            ex.shutdown(wait=False, cancel_futures=True)
        finally:
            raise


def _future_row(f, task: LogTask) -> dict:
    from concurrent.futures import CancelledError
    from concurrent.futures.process import BrokenProcessPool

    try:
        return f.result()
    except CancelledError:
        return interrupted_row(task.name, task.log, task.out_dir)
    except BrokenProcessPool:
        return error_row(task.name, task.log, task.out_dir,
                         f"{task.log}: its worker process died (killed, out of memory?); rerun the batch to retry it")


class RayEngine(Engine):
    """Ray tasks, one per log, on a local Ray or a running cluster.

    ``address``: ``local`` starts a Ray on this machine (no dashboard, bound to the loopback
    interface: nothing is reached over the network) with ``workers`` CPUs; ``auto`` joins the
    cluster this machine belongs to; anything else is passed to ``ray.init(address=...)``
    (``ray://head:10001``, ``head:6379``). When Ray is already initialised (a notebook, a
    test), that Ray is used as it is. Each task asks for ``batch.cpus_per_task`` CPUs and
    ``batch.gpus_per_task`` GPUs (:mod:`slam_lcd.batch.config`); ``workers`` also bounds the
    number of logs in flight at once (None: all are submitted and Ray schedules them).
    """

    name = "ray"

    def __init__(self, address: str = "local", workers: int | None = None, *, cpus: float = 1.0, gpus: float = 0.0,
                 max_retries: int = 2, temp_dir: str | Path | None = None):
        self.address = address
        self.workers = workers
        self.cpus = cpus
        self.gpus = gpus
        self.max_retries = max_retries
        self.temp_dir = temp_dir

    def _init(self, ray) -> bool:
        """Start or join Ray unless it is running in this process; True when we started it."""
        if ray.is_initialized():
            return False
        os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")  # offline machines: no usage report
        # workers import the same slam_lcd as the driver (a source checkout too)
        pkg_root = str(Path(__file__).resolve().parents[2])
        inherited = filter(None, os.environ.get("PYTHONPATH", "").split(os.pathsep))
        path = os.pathsep.join(dict.fromkeys([pkg_root, *inherited]))
        kwargs: dict = dict(include_dashboard=False, log_to_driver=False, configure_logging=False)
        if self.address == "local":
            kwargs.update(num_cpus=self.workers or os.cpu_count(), _node_ip_address="127.0.0.1",
                          runtime_env={"env_vars": {"PYTHONPATH": path}})
            if self.temp_dir is not None:
                kwargs["_temp_dir"] = str(self.temp_dir)
        else:
            kwargs.update(address=self.address)
        try:
            ray.init(**kwargs)
        except (ConnectionError, RuntimeError, ValueError) as e:
            raise InputError(f"cannot start or reach Ray ({type(e).__name__}: {e})", f"--ray {self.address}") from None
        return True

    _started = False

    def prepare(self) -> None:
        self._started = self._init(import_ray()) or self._started

    def close(self) -> None:
        if self._started:
            import_ray().shutdown()
            self._started = False

    def run(self, tasks, shared, on_row) -> None:
        ray = import_ray()
        if not ray.is_initialized():
            self.prepare()
        self._run(ray, tasks, shared, on_row)

    def _run(self, ray, tasks, shared, on_row) -> None:
        remote = ray.remote(run_task).options(num_cpus=self.cpus, num_gpus=self.gpus, max_retries=self.max_retries,
                                              retry_exceptions=False)
        shared_ref = ray.put(shared)
        queue = list(tasks)
        limit = self.workers or len(queue)
        inflight: dict = {}  # ref -> (task, when it was handed to Ray: see stopped_row)

        def submit():
            while queue and len(inflight) < limit:
                t = queue.pop(0)
                inflight[remote.remote(t, shared_ref)] = (t, time.time_ns())

        submit()
        try:
            while inflight:
                done, _ = ray.wait(list(inflight), num_returns=1)
                for ref in done:
                    t, since = inflight.pop(ref)
                    on_row(_ray_row(ray, ref, t, shared.config, since))
                submit()
        except KeyboardInterrupt:
            queue.clear()
            for ref in inflight:  # a running task gets a KeyboardInterrupt: run_log writes a partial set
                ray.cancel(ref, force=False)
            refs = list(inflight)
            done, _ = ray.wait(refs, num_returns=len(refs), timeout=RAY_STOP_WAIT_S) if refs else ([], [])
            finished = set(done)
            for ref in refs:
                t, since = inflight.pop(ref)
                on_row(_ray_row(ray, ref, t, shared.config, since) if ref in finished
                       else stopped_row(t, shared.config, since))
            raise


def _ray_row(ray, ref, task: LogTask, config, since_ns: int) -> dict:
    from ray.exceptions import RayTaskError, TaskCancelledError

    try:
        return ray.get(ref)
    except TaskCancelledError:  # the Ctrl-C reached the task outside run_log (maybe after it published)
        return stopped_row(task, config, since_ns)
    except RayTaskError as e:  # run_task returns rows for failing logs: this is Ray's or the worker's failure
        return error_row(task.name, task.log, task.out_dir, f"{task.log}: the Ray task failed ({e.cause!r})")
    except Exception as e:  # worker or node lost after its retries, object lost ...
        return error_row(task.name, task.log, task.out_dir,
                         f"{task.log}: the Ray task failed ({type(e).__name__}: {e})")


def import_ray():
    """``import ray``, or an InputError saying how to install it."""
    try:
        import ray
    except ImportError:
        raise InputError("Ray is not installed: pip install 'slam-lcd[ray]' (or run without --ray: a local "
                         "process pool)", "--ray") from None
    return ray
