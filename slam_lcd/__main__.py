"""`python -m slam_lcd`: the command line, with the exit status it returns.

Why the string ``exec`` before exiting: CPython (3.11, 3.12) remembers a ``KeyboardInterrupt``
that ended any code run from a string (``exec``/``eval`` of source text, as ``dataclasses``,
``namedtuple`` and generated message types do) even when a caller caught it, and under
``python -m`` it then kills the process with SIGINT at exit instead of returning our status:
a Ctrl-C that lands in such code turned ``exit 130`` into a death by signal. A string
evaluation clears that flag when it starts, so one right before exiting leaves the status we
return. (The installed ``slam-lcd`` script does not take this path.)
"""
import sys

from .runtime.interrupts import Terminated, exit_status, install_stop_signals, interrupt_behind, status_of


def _forget_caught_keyboard_interrupt() -> None:
    """Clear CPython's record of a caught Ctrl-C in string-evaluated code (see the module docstring)."""
    exec("None", {})  # a constant; the call itself is what clears the flag


install_stop_signals()  # SIGTERM / SIGHUP while the command line loads: one line too
try:
    from .cli.main import main
except (KeyboardInterrupt, ImportError) as caught:  # Ctrl-C while the command line loads: one line
    e = interrupt_behind(caught)  # an extension module interrupted while it initialised: ImportError from it
    if e is None:
        raise
    print(f"slam-lcd: terminated ({e})" if isinstance(e, Terminated) else "slam-lcd: interrupted", file=sys.stderr)
    _forget_caught_keyboard_interrupt()
    sys.exit(exit_status(e))

status = status_of(main)  # from here on stop signals are ignored: the interpreter's teardown cannot spoil the status
_forget_caught_keyboard_interrupt()
sys.exit(status)
