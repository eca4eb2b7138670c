"""Keyframe features extracted ahead, in worker threads (``run.extract_ahead``), for the pipeline.

Why a module of its own: :class:`~slam_lcd.run.pipeline.Pipeline` keeps keyframes in order through
the graph and loop detection; how many threads extract meanwhile, and what that does to
torch's own thread count, is separate bookkeeping with a life of its own: the threads start
with the first keyframe that needs them (a run that hands in ready features never starts
one), several workers share torch's threads out between them (one forward each, so the
cores stay busy between forwards), and :meth:`ExtractionPool.close` gives torch its count
back. ``lcd_threads``: the BLAS/faiss threads loop detection keeps while extraction runs,
so one core is left to it.
"""
from __future__ import annotations

from concurrent.futures import Future, ThreadPoolExecutor


def extract_workers(run_conf, extractor, ahead: int) -> int:
    """Extraction threads (``run.extract_workers``): several only for a torch model on the CPU."""
    n = int(run_conf.extract_workers)
    device = getattr(getattr(extractor, "device", None), "type", None)
    if ahead == 0 or device != "cpu":
        return 1
    if n == 0:
        import torch

        n = torch.get_num_threads()
    return max(1, min(n, ahead))


class ExtractionPool:
    """The worker threads of ``run.extract_ahead`` (``ahead``: keyframes handed in before the oldest is used)."""

    def __init__(self, run_conf, extractor):
        self.ahead = max(0, int(run_conf.extract_ahead))
        self.lcd_threads = int(run_conf.lcd_threads) if self.ahead else 0  # leave a core to extraction
        self.workers = extract_workers(run_conf, extractor, self.ahead)
        self._torch_threads_before: int | None = None  # torch's own thread count while the workers share it out
        self._executor: ThreadPoolExecutor | None = None

    def submit(self, fn, *args) -> Future:
        """Run ``fn(*args)`` in a worker (the threads start on the first call)."""
        if self._executor is None:
            if self.workers > 1:  # N keyframes at once, torch's threads shared out between them
                import torch

                self._torch_threads_before = torch.get_num_threads()
                torch.set_num_threads(max(1, self._torch_threads_before // self.workers))
            self._executor = ThreadPoolExecutor(max_workers=self.workers, thread_name_prefix="slam-lcd-features")
        return self._executor.submit(fn, *args)

    def close(self) -> None:
        """Stop the threads (work not started is cancelled) and give torch its thread count back."""
        if self._executor is not None:
            self._executor.shutdown(wait=True, cancel_futures=True)
            self._executor = None
        if self._torch_threads_before is not None:
            import torch

            torch.set_num_threads(self._torch_threads_before)
            self._torch_threads_before = None
