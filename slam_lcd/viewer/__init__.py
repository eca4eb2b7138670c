"""Rerun recordings of what slam-lcd wrote: `slam-lcd view` and `slam-lcd run --rerun`.

Why a package of its own: rerun-sdk is an optional extra (``pip install 'slam-lcd[viewer]'``),
so it is imported here only, and only inside functions; every other module of slam-lcd stays
importable (and the test suite runs) without it. :func:`require_rerun` is the one place that
imports it and turns its absence into a one-line :class:`~slam_lcd.errors.ViewerMissingError`.

- :mod:`.folders` reads a run folder, a map folder and a ``localize`` folder (no rerun);
- :mod:`.record` logs them into a recording stream, :mod:`.layout` sets the first view;
- :mod:`.targets` saves the recording atomically, spawns the native viewer or serves the web one;
- :mod:`.live` logs keyframes and loops while ``slam-lcd run --rerun`` goes.
"""
from __future__ import annotations

from ..errors import ViewerMissingError

INSTALL_HINT = "pip install 'slam-lcd[viewer]'"
APPLICATION_ID = "slam-lcd"
TIMELINE = "stamp"  # the log's stamps (a timestamp timeline)


def require_rerun():
    """The ``rerun`` module, or :class:`~slam_lcd.errors.ViewerMissingError` saying how to install it."""
    try:
        import rerun
    except ImportError:
        raise ViewerMissingError(f"the Rerun viewer needs rerun-sdk, which is not installed: {INSTALL_HINT}") from None
    return rerun
