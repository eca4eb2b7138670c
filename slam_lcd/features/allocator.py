"""Keep freed memory in the process for CPU inference (glibc ``mallopt``).

Why: PyTorch's CPU allocator asks ``malloc`` for every activation. SuperPoint's first layers
at 640x480 need 78 MB buffers, above glibc's mmap threshold (at most 32 MB), so each forward
pass maps fresh zeroed pages and unmaps them again: about 130,000 page faults and ~30% of
the forward time on a 2-core machine (measured: sys time 195-227 ms of a ~900 ms call, and
~5 ms with the setting below). Telling glibc to serve large blocks from the heap and not to
trim it lets the next forward pass reuse the same pages.

The cost is that the heap keeps up to ``trim_threshold`` bytes of freed memory instead of
returning it to the system; a SuperPoint forward pass holds about 250 MB at its peak, so that
memory is reused every keyframe anyway. The setting is process-wide, applied once by the
program itself (not by the user's environment), and a no-op where the C library is not glibc.
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

_applied: str | None = None


def retain_freed_memory(trim_threshold: int = 1 << 30, top_pad: int = 64 << 20) -> bool:
    """Serve large blocks from the heap and keep freed memory for reuse; True when applied."""
    global _applied
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
    if ok:
        _applied = "retain"
        log.debug("glibc %s: large blocks from the heap, freed memory kept (trim threshold %d MB)",
                  gnu_get_libc_version().decode(), trim_threshold >> 20)
    return ok


def allocator_state() -> str:
    """'retain' once applied, 'unavailable' where it could not be, 'system' when never asked."""
    return _applied or "system"
