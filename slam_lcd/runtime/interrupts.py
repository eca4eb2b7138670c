"""Ctrl-C, SIGTERM and SIGHUP: one way to stop, which waits for a short critical section to finish.

Why: a few steps must happen together or not at all (iSAM2 update and the pose graph's
bookkeeping, renaming an output set into place, removing a temporary folder). Python
raises ``KeyboardInterrupt`` between any two bytecodes, so a Ctrl-C in the middle of such
a step would leave half of it done. :func:`defer_sigint` holds the stop signals back for the
duration of the block and re-raises them right after, so the state is consistent on either
side of the interrupt. It does nothing outside the main thread (signals are only
delivered there) or for a signal whose handler someone else installed.

SIGTERM (``timeout``, ``systemd``, ``docker stop``, cluster schedulers) and SIGHUP (the
terminal closed) take the same path as Ctrl-C once :func:`install_stop_signals` ran (the
command line does it first): they raise :class:`Terminated`, a ``KeyboardInterrupt``, so
every ``except KeyboardInterrupt`` / ``finally`` that makes Ctrl-C safe makes them safe too.
The exit status says which signal stopped the command (:func:`exit_status`): 130 for Ctrl-C,
143 for SIGTERM, 129 for SIGHUP (128 + the signal's number, as a shell reports it).
"""
from __future__ import annotations

import contextlib
import signal
import sys
import threading

# signals turned into Terminated (SIGHUP does not exist on every platform)
STOP_SIGNALS = tuple(getattr(signal, n) for n in ("SIGTERM", "SIGHUP") if hasattr(signal, n))
_received: list[int] = []  # the stop signals this process took, first first (exit status, messages)


class Terminated(KeyboardInterrupt):
    """SIGTERM or SIGHUP, raised where a Ctrl-C would be (``signum`` says which)."""

    def __init__(self, signum: int):
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


def _terminate(signum, frame):  # signal handler signature
    _received.append(signum)
    raise Terminated(signum)


def install_stop_signals() -> None:
    """Make SIGTERM and SIGHUP raise :class:`Terminated` in the main thread (the command line's set-up).

    A signal someone set to be ignored (``nohup``) stays ignored; the handlers of a caller
    that installed its own are left alone.
    """
    _received.clear()
    if threading.current_thread() is not threading.main_thread():
        return
    for s in STOP_SIGNALS:
        try:
            if signal.getsignal(s) in (signal.SIG_DFL, _terminate):
                signal.signal(s, _terminate)
        except (ValueError, OSError):  # pragma: no cover - no signal support here
            pass


def _is_ours(signum: int, handler) -> bool:
    return handler is (signal.default_int_handler if signum == signal.SIGINT else _terminate)


def signal_name(exc: BaseException | None = None) -> str:
    """'SIGTERM' / 'SIGHUP' for a stop by that signal (``exc`` or the first one this process took), else 'Ctrl-C'."""
    if isinstance(exc, Terminated):
        return signal.Signals(exc.signum).name
    if exc is None and _received:
        return signal.Signals(_received[0]).name
    return "Ctrl-C"


def interrupted_word() -> str:
    """'interrupted' after a Ctrl-C, 'interrupted (SIGTERM)' after that signal (warning lines)."""
    name = signal_name()
    return "interrupted" if name == "Ctrl-C" else f"interrupted ({name})"


def exit_status(exc: BaseException | None = None) -> int:
    """Exit status of a command stopped by ``exc`` (or, None, by the first stop signal taken): 128 + signal."""
    if isinstance(exc, Terminated):
        return 128 + exc.signum
    if exc is None and _received:
        return 128 + _received[0]
    return 128 + signal.SIGINT


def interrupt_behind(exc: BaseException | None) -> KeyboardInterrupt | None:
    """The Ctrl-C / SIGTERM that caused ``exc``, if any (an extension module whose initialisation
    the signal interrupted raises ``ImportError: initialization failed`` from it)."""
    seen = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(exc, KeyboardInterrupt):
            return exc
        seen.add(id(exc))
        exc = exc.__cause__ or exc.__context__
    return None


@contextlib.contextmanager
def defer_sigint():
    """Run the block with Ctrl-C, SIGTERM and SIGHUP postponed; one that came is raised when it ends."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    try:
        held = {s: signal.getsignal(s) for s in (signal.SIGINT, *STOP_SIGNALS)}
    except (ValueError, OSError):  # pragma: no cover - no signal support here
        yield
        return
    held = {s: h for s, h in held.items() if _is_ours(s, h)}  # a custom handler (or SIG_IGN) owns the rest
    received: list[int] = []

    def hold(signum, frame):  # signal handler signature
        received.append(signum)

    installed = []
    try:
        for s, h in held.items():
            signal.signal(s, hold)
            installed.append((s, h))
        yield
    finally:
        for s, h in installed:
            signal.signal(s, h)
        if received:
            stop = [s for s in received if s != signal.SIGINT]
            if stop:
                _received.append(stop[0])
                raise Terminated(stop[0])
            raise KeyboardInterrupt


defer_interrupts = defer_sigint  # the same, by what it does


def finish(step, *args) -> None:
    """Run ``step(*args)`` to its end whatever stop signals arrive; the first one is raised afterwards.

    For clean-up (removing a temporary folder): an interrupt that lands before the deferral
    starts makes the step run again instead of being skipped (so it must be harmless to repeat).
    """
    pending = None
    done = False
    while not done:
        try:
            with defer_sigint():
                step(*args)
                done = True
        except KeyboardInterrupt as e:
            pending = pending or e
    if pending is not None:
        raise pending


_resend = threading.Event()  # set by the hook below: the helper thread sends the signal again
_resend_signals: list[int] = []
_resender: threading.Thread | None = None


def _resend_sigint() -> None:
    while True:
        _resend.wait()
        _resend.clear()
        while _resend_signals:
            signal.raise_signal(_resend_signals.pop(0))


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
                and threading.current_thread() is threading.main_thread()):
            signum = getattr(unraisable.exc_value, "signum", signal.SIGINT)  # a SIGTERM is sent again as one
            if callable(signal.getsignal(signum)):
                _resend_signals.append(signum)
                _resend.set()
                return
        previous(unraisable)

    hook._slam_lcd_keeps_interrupts = True  # type: ignore[attr-defined]  # a mark on the function object
    sys.unraisablehook = hook


def status_of(command) -> int:
    """Run ``command()`` (a command line's ``main``) and return its exit status, with Ctrl-C, SIGTERM
    and SIGHUP ignored from the moment it has one.

    Why: once a command has its status, a stop signal can only spoil it. One that lands while the
    interpreter tears down (atexit callbacks, finalisers, code run from a string) is dropped by
    Python, or leaves CPython's record of an unhandled Ctrl-C so that the process then kills itself
    by SIGINT with nothing said: exit -2 instead of the command's 0 or 130. Ignored, it changes
    nothing. A stop signal that lands before the command has a status gives the status of that signal
    (130, 143, 129); one that lands after keeps the command's.
    """
    status: int | None = None
    while True:
        try:
            if status is None:
                status = int(command() or 0)
            for s in (signal.SIGINT, *STOP_SIGNALS):
                signal.signal(s, signal.SIG_IGN)
            return status
        except KeyboardInterrupt as e:
            if status is None:
                status = exit_status(e)
