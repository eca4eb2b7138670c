"""Progress bars for long commands: tqdm (rate and ETA) on a terminal, one line per stage otherwise.

Why one module: every long stage (reading frames, rendering, extracting features, training a
vocabulary) reports progress the same way. On a terminal it is a tqdm bar on stderr; when
stderr is not a terminal (a CI log, a pipe) a bar would fill the log with carriage returns,
so a stage prints one line when it ends instead (count, seconds, rate); ``enabled=False``
(``--no-progress``) prints nothing at all.
"""
from __future__ import annotations

import sys
import time
from collections.abc import Iterable, Sized
from typing import TextIO


def stderr_is_terminal(stream: TextIO | None = None) -> bool:
    stream = sys.stderr if stream is None else stream
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError):  # closed or replaced stream
        return False


class StageLine:
    """The non-terminal stand-in for a tqdm bar: counts, and prints one line on ``close``."""

    def __init__(self, iterable: Iterable | None = None, *, total: int | None = None, desc: str = "",
                 unit: str = "it", stream: TextIO | None = None):
        self.iterable = iterable
        self.total = total if total is not None else (len(iterable) if isinstance(iterable, Sized) else None)
        self.desc = desc
        self.unit = unit
        self.n = 0
        self.stream = stream
        self._t0 = time.perf_counter()
        self._closed = False

    def __iter__(self):
        try:
            for item in self.iterable:
                self.n += 1  # counted when handed out: a consumer that stops after the last item still counts it
                yield item
        finally:
            self.close()

    def update(self, n: int = 1) -> None:
        self.n += n

    def set_postfix_str(self, s: str = "", refresh: bool = True) -> None:  # tqdm's API, nothing to show
        pass

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        dt = time.perf_counter() - self._t0
        rate = f", {self.n / dt:.1f} {self.unit}/s" if dt > 0 and self.n else ""
        of = f"/{self.total}" if self.total is not None else ""
        print(f"{self.desc}: {self.n}{of} {self.unit} in {dt:.1f} s{rate}", file=self.stream or sys.stderr,
              flush=True)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False


class _Silent(StageLine):
    def close(self) -> None:
        self._closed = True


def progress_bar(iterable: Iterable | None = None, *, total: int | None = None, desc: str = "", unit: str = "it",
                 enabled: bool = True, leave: bool = True):
    """A tqdm bar with rate and ETA when ``enabled`` and stderr is a terminal; else a :class:`StageLine`
    (one line at the end) when ``enabled``; else nothing is printed. Use like tqdm (iterate, or
    ``update``/``close``)."""
    if not enabled:
        return _Silent(iterable, total=total, desc=desc, unit=unit)
    if not stderr_is_terminal():
        return StageLine(iterable, total=total, desc=desc, unit=unit)
    from tqdm import tqdm

    # tqdm's default format shows count, elapsed<remaining (ETA) and rate
    return tqdm(iterable, total=total, desc=desc, unit=unit, dynamic_ncols=True, leave=leave)


class stage:
    """A stage with no countable steps (training a tree, optimising): one line when it ends
    (``<desc>: done in 12.3 s``), and on a terminal also one when it starts; nothing when not
    ``enabled``."""

    def __init__(self, desc: str, enabled: bool = True):
        self.desc = desc
        self.enabled = enabled

    def __enter__(self):
        self._t0 = time.perf_counter()
        if self.enabled and stderr_is_terminal():
            print(f"{self.desc} ...", file=sys.stderr, flush=True)
        return self

    def __exit__(self, exc_type, *exc):
        if self.enabled and exc_type is None:
            print(f"{self.desc}: done in {time.perf_counter() - self._t0:.1f} s", file=sys.stderr, flush=True)
        return False
