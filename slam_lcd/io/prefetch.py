"""Read a log in a thread of its own, a few messages ahead of the one who uses them.

Why: ``run``'s main thread both reads the log (chunk decompression, CRC checks, CDR
deserialisation: ~1.8 s of one core on the 2-lap demo) and detects loops. Whenever the
feature extraction is not what everything waits for (features cached, a GPU, many cores),
the main thread is the run's critical path and the reading is a fifth of it.
Decompression and CRCs release the GIL, so in a thread of their own they overlap the loop
detection instead of adding to it (the 2-lap demo with its features cached: 13.9 s ->
12.7 s). When the extraction *is* the bottleneck (SuperPoint on two CPU cores) a fourth
busy thread only adds hand-overs and memory, so a :class:`Prefetched` starts inline (the
consumer reads) and its owner calls :meth:`Prefetched.start` once reading ahead pays.

It keeps the order, the items and the errors of the iterator it wraps: an exception raised
while reading reaches the consumer as the same object, after the items read before it.
Closing it (or leaving it by an exception, such as Ctrl-C in the consumer) stops the
reading thread and waits for it, so that nothing it calls (e.g. a ``raw_sink``) runs after
the consumer has moved on. The source is only ever advanced by one thread at a time: the
consumer until :meth:`~Prefetched.start`, the reading thread after it.
"""
from __future__ import annotations

import queue
import threading
from collections.abc import Iterable, Iterator
from typing import TypeVar

T = TypeVar("T")

_END = object()
_BATCH = 16  # items handed over at once at most


class _Failed:
    __slots__ = ("error",)

    def __init__(self, error: BaseException):
        self.error = error


class Prefetched(Iterator[T]):
    """An iterator over ``source``, read inline until :meth:`start`, then ``depth`` ahead by a daemon thread."""

    def __init__(self, source: Iterable[T], depth: int = 64, name: str = "slam-lcd-reader", threaded: bool = True):
        if depth < 1:
            raise ValueError(f"prefetch depth must be >= 1, got {depth}")
        self._source = iter(source)
        # items go over in batches: one hand-over per item (a lock, a wake-up, the GIL passed on)
        # costs more than the reading it overlaps on a busy machine
        self._batch = max(1, min(_BATCH, depth // 2))
        self._queue: queue.Queue = queue.Queue(maxsize=max(1, depth // self._batch))
        self._items: list = []
        self._next = 0
        self._stop = threading.Event()
        self._done = False
        self._name = name
        self._thread: threading.Thread | None = None
        if threaded:
            self.start()

    @property
    def threaded(self) -> bool:
        """Whether a thread reads ahead (after :meth:`start`)."""
        return self._thread is not None

    def start(self) -> None:
        """Read ahead from now on (call it from the consumer's thread; again: no effect)."""
        if self._thread is not None or self._done:
            return
        self._thread = threading.Thread(target=self._produce, name=self._name, daemon=True)
        self._thread.start()

    def _put(self, item) -> bool:
        """Hand ``item`` over; False once the consumer stopped listening."""
        while not self._stop.is_set():
            try:
                self._queue.put(item, timeout=0.1)
                return True
            except queue.Full:
                continue
        return False

    def _produce(self) -> None:
        batch: list = []
        try:
            for item in self._source:
                batch.append(item)
                if len(batch) >= self._batch:
                    if not self._put(batch):
                        return
                    batch = []
            if batch and not self._put(batch):
                return
            self._put(_END)
        except BaseException as e:  # handed to the consumer, raised there
            if not batch or self._put(batch):  # the items read before it come first
                self._put(_Failed(e))
        finally:
            self._close_source()  # a generator is closed in the thread that ran it

    def _close_source(self) -> None:
        close = getattr(self._source, "close", None)
        if close is not None:
            try:
                close()
            except Exception:  # closing must not mask what happened
                pass

    def __iter__(self) -> Prefetched[T]:
        return self

    def __next__(self) -> T:
        if self._next < len(self._items):
            item = self._items[self._next]
            self._next += 1
            return item
        if self._done:
            raise StopIteration
        if self._thread is None:  # inline: the consumer reads
            try:
                return next(self._source)
            except StopIteration:
                self._done = True
                raise
        try:
            got = self._queue.get()
        except BaseException:
            self.close()
            raise
        if got is _END:
            self._done = True
            self._thread.join()
            raise StopIteration
        if isinstance(got, _Failed):
            self._done = True
            self._thread.join()
            raise got.error
        self._items, self._next = got, 1
        return got[0]

    def close(self) -> None:
        """Stop reading ahead and wait until the reading thread has let go of the source."""
        self._done = True
        self._items, self._next = [], 0
        self._stop.set()
        if self._thread is None:
            self._close_source()
            return
        while self._thread.is_alive():
            try:  # unblock a reader waiting for room
                while True:
                    self._queue.get_nowait()
            except queue.Empty:
                pass
            self._thread.join(timeout=0.05)

    def __enter__(self) -> Prefetched[T]:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def prefetched(source: Iterable[T], depth: int = 64, name: str = "slam-lcd-reader",
               threaded: bool = True) -> Prefetched[T]:
    """``source``'s items, read ``depth`` ahead in a background thread (from :meth:`Prefetched.start`
    on when ``threaded`` is False; see the module docstring)."""
    return Prefetched(source, depth, name, threaded)
