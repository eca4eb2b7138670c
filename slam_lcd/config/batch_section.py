"""Configuration section `batch`: what one log's task asks of a worker (used by :mod:`slam_lcd.batch`).

Why in the configuration and not only on the command line: a cluster run is described by a
config file that travels with the command; the resources a log needs (one CPU core for the
ORB path, a GPU share for SuperPoint) belong to the run's description like the extractor
choice that causes them. Why kept here rather than in ``slam_lcd/batch/``: the batch driver
sits above the runner and everything the configuration gathers, so the configuration owns
this one section and ``slam_lcd.batch.config`` re-exports it.
"""
from __future__ import annotations

from dataclasses import dataclass

from ..value_range import ranged


@dataclass
class BatchConfig:
    # CPU cores one log's task takes: Ray's num_cpus per task; in every worker process also
    # the number of torch / OpenCV threads (so N workers do not oversubscribe N cores)
    cpus_per_task: float = ranged(1.0, "(0, inf)")
    # GPUs one task takes (Ray's num_gpus; fractions share a GPU, e.g. 0.25 = four logs per
    # GPU); None = 1 when features.kind is superpoint and features.device is cuda, else 0
    gpus_per_task: float | None = ranged(None, "[0, inf)")
    # Ray only: times a task is re-run when its worker process dies (machine lost, killed
    # for memory); a log that fails with an error is not retried, it becomes an error row
    max_retries: int = ranged(2, "[0, inf)")
