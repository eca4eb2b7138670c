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
import sys
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


_resend = threading.Event()  # set by the hook below: the helper thread sends SIGINT again
_resender: threading.Thread | None = None


def _resend_sigint() -> None:
    while True:
        _resend.wait()
        _resend.clear()
        signal.raise_signal(signal.SIGINT)


def keep_lost_interrupts() -> None:
    """Make a Ctrl-C that Python could not raise take effect anyway (a command line's set-up).

    Why: a SIGINT is raised as ``KeyboardInterrupt`` at the next bytecode the main thread runs;
    when that bytecode belongs to a weak-reference callback or a ``__del__`` (run whenever the
    garbage collector frees something), Python prints "Exception ignored" and drops it, and the
    command carried on to the end as if nobody had pressed Ctrl-C (once in 30 interrupted batch
    runs under load). This hook, for ``sys.unraisablehook``, has such a ``KeyboardInterrupt``
    sent back as a fresh SIGINT by a helper thread (sent from the hook itself it would be raised
    in the hook and dropped again; a thread started there waits on the main thread, which would
    take it there too). The main thread raises it in the code it returns to, or ``defer_sigint``
    holds it; should it land in a finaliser again, it comes back again. Other unraisable
    exceptions go to the hook that was there. Installed once per process.
    """
    global _resender
    previous = sys.unraisablehook
    if getattr(previous, "_slam_lcd_keeps_interrupts", False):
        return
    if _resender is None:
        _resender = threading.Thread(target=_resend_sigint, name="slam-lcd-sigint", daemon=True)
        _resender.start()

    def hook(unraisable) -> None:
        if (unraisable.exc_type is not None and issubclass(unraisable.exc_type, KeyboardInterrupt)
                and threading.current_thread() is threading.main_thread()
                and callable(signal.getsignal(signal.SIGINT))):
            _resend.set()
            return
        previous(unraisable)

    hook._slam_lcd_keeps_interrupts = True
    sys.unraisablehook = hook
