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


def _forget_caught_keyboard_interrupt() -> None:
    """Clear CPython's record of a caught Ctrl-C in string-evaluated code (see the module docstring)."""
    exec("None", {})  # noqa: S102 - a constant; the call itself is what clears the flag


try:
    from .cli.main import main
except KeyboardInterrupt:  # Ctrl-C while the command line loads (imports run dataclasses' exec): one line
    print("slam-lcd: interrupted", file=sys.stderr)
    _forget_caught_keyboard_interrupt()
    sys.exit(130)

status = main()
_forget_caught_keyboard_interrupt()
sys.exit(status)
