"""Configuration section `batch` as the batch driver reads it: :class:`BatchConfig` (kept in
:mod:`slam_lcd.config.batch_section`, so the configuration imports nothing above it) and the
GPU share of one task."""
from __future__ import annotations

from ..config.batch_section import BatchConfig

__all__ = ["BatchConfig", "gpus_per_task"]


def gpus_per_task(conf: BatchConfig, features) -> float:
    """The GPU share of one task (see :attr:`BatchConfig.gpus_per_task`)."""
    if conf.gpus_per_task is not None:
        return float(conf.gpus_per_task)
    return 1.0 if (features.kind == "superpoint" and features.device == "cuda") else 0.0
