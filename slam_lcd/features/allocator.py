"""Keep freed memory in the process for CPU inference (glibc ``mallopt``).

Why: PyTorch's CPU allocator asks ``malloc`` for every activation. SuperPoint's first layers
at 640x480 need 78 MB buffers, above glibc's mmap threshold (at most 32 MB), so each forward
pass maps fresh zeroed pages and unmaps them again: about 130,000 page faults and ~30% of
the forward time on a 2-core machine (measured: sys time 195-227 ms of a ~900 ms call, and
~5 ms with the setting below). Telling glibc to serve large blocks from the heap and not to
trim it lets the next forward pass reuse the same pages.

The same holds in the extraction threads only if they allocate from the main heap: glibc gives
each new thread an arena of its own, whose heaps are at most 64 MB, so a 78 MB block there is
always mapped afresh (and the mmap limit above does not stop it). Measured on the 2-lap demo
(2 cores, two extraction threads): 10.1 s of system time in a 40.7 s run; with one arena 1.2 s
and 37.1 s. So the arenas are limited to one (``M_ARENA_MAX``); SuperPoint's threads and the loop
detection then share the main heap's lock, which cost less than the page faults in every run
measured (docs/features.md).

The cost is that the heap keeps freed memory instead of returning it to the system; a
SuperPoint forward pass holds about 250 MB at its peak, so that memory is reused every keyframe
anyway. But not all of it: the forward's blocks are freed around smaller ones that live on
(features, the vocabulary's arrays), and the holes between them grew the heap by 0.7-1.5 MB per
keyframe on the 10-lap demo log (835 keyframes: 1.1 GB free inside a 2 GB process). So
:func:`trim_when_fragmented`, called after each forward, hands free pages back
(``malloc_trim``, ~7-30 ms) once the heap's free bytes grew by :data:`FREE_LIMIT` since the
last trim, at most once per :data:`TRIM_MIN_CALLS` forwards: 6-7 times in 835 keyframes, each
costing the next forwards their page faults once.

The settings are process-wide, applied once by the program itself (not by the user's
environment), and a no-op where the C library is not glibc.
An arena that a thread already holds stays its own: applied before the extraction threads start.
"""
from __future__ import annotations

import ctypes
import ctypes.util
import logging
import sys

log = logging.getLogger(__name__)

# glibc malloc.h parameter numbers
_M_TRIM_THRESHOLD = -1
_M_TOP_PAD = -2
_M_MMAP_MAX = -4
_M_ARENA_MAX = -8

_applied: str | None = None
_libc = None

# growth of the heap's free bytes after which trim_when_fragmented returns them (two forwards' working sets fit)
FREE_LIMIT = 256 << 20


class _MallInfo2(ctypes.Structure):
    _fields_ = [(n, ctypes.c_size_t) for n in
                ("arena", "ordblks", "smblks", "hblks", "hblkhd", "usmblks", "fsmblks", "uordblks", "fordblks",
                 "keepcost")]


def retain_freed_memory(trim_threshold: int = 1 << 30, top_pad: int = 64 << 20) -> bool:
    """Serve large blocks from the one main heap and keep freed memory for reuse; True when applied."""
    global _applied, _libc
    if _applied is not None:
        return _applied == "retain"
    _applied = "unavailable"
    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        mallopt = libc.mallopt
        gnu_get_libc_version = libc.gnu_get_libc_version  # present in glibc only
    except (OSError, AttributeError):
        return False
    mallopt.argtypes = [ctypes.c_int, ctypes.c_int]
    mallopt.restype = ctypes.c_int
    gnu_get_libc_version.restype = ctypes.c_char_p
    ok = bool(mallopt(_M_MMAP_MAX, 0)) and bool(mallopt(_M_TRIM_THRESHOLD, int(trim_threshold)))
    mallopt(_M_TOP_PAD, int(top_pad))
    ok = ok and bool(mallopt(_M_ARENA_MAX, 1))
    if ok:
        _applied = "retain"
        _libc = libc
        if hasattr(libc, "mallinfo2"):  # glibc >= 2.33
            libc.mallinfo2.restype = _MallInfo2
        log.debug("glibc %s: large blocks from the heap, freed memory kept (trim threshold %d MB)",
                  gnu_get_libc_version().decode(), trim_threshold >> 20)
    return ok


def allocator_state() -> str:
    """'retain' once applied, 'unavailable' where it could not be, 'system' when never asked."""
    return _applied or "system"


def heap_free_bytes() -> int | None:
    """Bytes lying free inside glibc's heaps (``mallinfo2``, glibc >= 2.33); None where unknown."""
    if _libc is None or not hasattr(_libc, "mallinfo2"):
        return None
    return int(_libc.mallinfo2().fordblks)


# calls of trim_when_fragmented between two trims at least (and before the first): a trim costs the
# next forward passes their page faults once, so it must never come every forward
TRIM_MIN_CALLS = 50
_free_after_trim = 0
_calls_since_trim = 0


def trim_when_fragmented(limit: int = FREE_LIMIT, min_calls: int = TRIM_MIN_CALLS) -> bool:
    """With 'retain' applied: ``malloc_trim(0)`` once the heap's free bytes grew by more than ``limit``
    since the last trim, and at most once per ``min_calls`` calls; True if trimmed.

    Free chunks whose pages were handed back still count as free (``mallinfo2``), hence the
    growth since the last trim, not the total; but a trim also shrinks the heap's top, which the
    next forward grows again, hence the spacing. ``mallinfo2`` takes ~2 us: cheap after every forward."""
    global _free_after_trim, _calls_since_trim
    _calls_since_trim += 1
    if _calls_since_trim < min_calls:
        return False
    free = heap_free_bytes()
    if free is None or _libc is None or free - _free_after_trim <= limit:  # free is None without libc
        return False
    _libc.malloc_trim(0)
    _calls_since_trim = 0
    _free_after_trim = heap_free_bytes() or 0
    log.debug("glibc heap: %d MB free inside it; pages returned to the system (malloc_trim)", free >> 20)
    return True
