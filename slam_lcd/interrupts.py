"""Ctrl-C that waits for a short critical section to finish.

Why: a few steps must happen together or not at all (iSAM2 update and the pose graph's
bookkeeping, renaming an output set into place, removing a temporary folder). Python
raises ``KeyboardInterrupt`` between any two bytecodes, so a Ctrl-C in the middle of such
a step would leave half of it done. :func:`defer_sigint` holds SIGINT back for the
duration of the block and re-raises it right after, so the state is consistent on either
side of the interrupt. It does nothing outside the main thread (signals are only
delivered there) or when someone else installed a SIGINT handler.
"""
from __future__ import annotations

import contextlib
import signal
import threading


@contextlib.contextmanager
def defer_sigint():
    """Run the block with Ctrl-C postponed; a Ctrl-C during it is raised when it ends."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    try:
        previous = signal.getsignal(signal.SIGINT)
    except (ValueError, OSError):  # pragma: no cover - no signal support here
        yield
        return
    if previous is not signal.default_int_handler:
        yield  # a custom handler (or SIG_IGN) owns Ctrl-C: leave it alone
        return
    received = []

    def hold(signum, frame):  # noqa: ARG001 - signal handler signature
        received.append(signum)

    signal.signal(signal.SIGINT, hold)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
        if received:
            raise KeyboardInterrupt
