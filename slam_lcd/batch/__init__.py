"""slam_lcd.batch: ``slam-lcd batch``, one ``run`` per log on a local process pool or on Ray.

``run_batch(logs, out_dir, config, workers=..., ray=...)`` returns a
:class:`~slam_lcd.batch.run.BatchResult` (one summary row per log) and writes
``summary.csv``, ``summary.md`` and ``ate_before_after.png`` into ``out_dir`` beside one
output folder per log. See docs/batch.md.

Names are imported lazily (PEP 562): importing :class:`BatchConfig` (the configuration's
``batch`` section) must not pull in the runner (and torch) with it.
"""
from __future__ import annotations

from ..runtime.lazy_names import lazy_getattr
from .config import BatchConfig

_LAZY = {
    "run_batch": ".run",
    "BatchResult": ".run",
    "make_engine": ".run",
    "discover_logs": ".discovery",
    "InlineEngine": ".engines",
    "LocalPoolEngine": ".engines",
    "RayEngine": ".engines",
    "read_summary_csv": ".summary",
    "COLUMNS": ".rows",
}

__all__ = ["BatchConfig", *_LAZY]


__getattr__ = lazy_getattr(__name__, _LAZY, globals())
