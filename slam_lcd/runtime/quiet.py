"""Native libraries' own messages stay off the user's terminal; ours say what happened.

Why: OpenCV prints ``[ WARN:0@0.1] global loadsave.cpp ... imread_(...)`` lines, and
libjpeg/libpng write ``Premature end of JPEG file`` straight to file descriptor 2, beside
(or instead of) slam-lcd's one-line message. :func:`quiet_opencv` silences OpenCV's
logger; :func:`native_stderr` captures what C code writes to fd 2 during a decode, so the
caller can turn a damaged-image report into its own message (or drop a harmless one).
"""
from __future__ import annotations

import contextlib
import os
import re
import sys
import tempfile
import threading

# what decoders say when the bytes are damaged (libjpeg, libpng, OpenCV's own readers)
DAMAGE = re.compile(r"premature|corrupt|truncat|unexpected end|extraneous|error|invalid|bad ", re.I)
_ANSI = re.compile(r"\x1b\[[0-9;]*[A-Za-z]")

_lock = threading.Lock()
_sink = None
_opencv_quiet = False


def quiet_opencv() -> None:
    """Silence OpenCV's own log lines (once per process)."""
    global _opencv_quiet
    if _opencv_quiet:
        return
    import cv2

    try:
        cv2.setLogLevel(0)  # type: ignore[attr-defined]  # LOG_LEVEL_SILENT; OpenCV's stubs leave it out
    except AttributeError:  # pragma: no cover - older OpenCV
        cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_SILENT)
    _opencv_quiet = True


class Captured:
    """Text that native code wrote to fd 2 inside a :func:`native_stderr` block."""

    text = ""

    @property
    def damage(self) -> str:
        """The first line that reports damaged data, or ''."""
        for line in self.text.splitlines():
            if DAMAGE.search(line):
                return one_line(line)
        return ""


@contextlib.contextmanager
def native_stderr():
    """Capture what C libraries write to file descriptor 2 inside the block (``.text`` after it)."""
    global _sink
    cap = Captured()
    with _lock:
        try:
            sys.stderr.flush()
            if _sink is None:
                _sink = tempfile.TemporaryFile()
            _sink.seek(0)
            _sink.truncate()
            saved = os.dup(2)
        except (OSError, ValueError):  # no fd 2, or no room for a temporary file: do not capture
            yield cap
            return
        os.dup2(_sink.fileno(), 2)
        try:
            yield cap
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            _sink.seek(0)
            cap.text = _sink.read(64 * 1024).decode("utf-8", "replace").strip()


def one_line(text: object, limit: int = 200) -> str:
    """``str(text)`` (a message, an exception) without ANSI colour codes, on one line, at most ``limit`` characters."""
    s = " ".join(_ANSI.sub("", str(text)).split())
    return s if len(s) <= limit else s[: limit - 3] + "..."
