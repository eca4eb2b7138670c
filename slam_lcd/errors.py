"""Typed errors of slam-lcd.

Library code raises these; only the CLI turns them into a one-line message and exit
status 2. Every error names the file (or object) it is about and what is wrong with it,
in a single line, so that ``str(err)`` is what a user sees.
"""
from __future__ import annotations

from pathlib import Path


class SlamLcdError(Exception):
    """Base class of every error slam-lcd raises on purpose."""

    def __init__(self, message: str, path: str | Path | None = None):
        self.path = Path(path) if path is not None else None
        self.problem = " ".join(str(message).split())  # one line, always
        text = f"{self.path}: {self.problem}" if self.path is not None else self.problem
        super().__init__(text)


class InputError(SlamLcdError):
    """Something wrong with what the user gave us (file, topic, value)."""


class FileMissingError(InputError):
    """The path does not exist (or is not the kind of thing expected)."""


class UnsupportedFormatError(InputError):
    """The file exists but is not a format slam-lcd reads."""


class CorruptLogError(InputError):
    """A log (bag/MCAP) whose bytes cannot be parsed."""


class TruncatedLogError(CorruptLogError):
    """A log that ends early; ``recovered`` messages could still be read."""

    def __init__(self, message: str, path=None, recovered: int = 0):
        self.recovered = recovered
        super().__init__(message, path)


class TopicNotFoundError(InputError):
    """A requested topic is not in the log; ``available`` lists the ones that are.

    ``flag``: the flag that named the topic (``--image-topic``), said beside it; ``hint``: how to
    supply what the topic would have given (``--calib FILE`` for a missing CameraInfo), said last.
    """

    def __init__(self, topic: str, available, path=None, *, flag: str | None = None, hint: str | None = None):
        self.topic = topic
        self.available = sorted(available)
        shown = ", ".join(self.available) if self.available else "(none)"
        given = f" ({flag})" if flag else ""
        super().__init__(f"topic {topic!r}{given} not found; available topics: {shown}"
                         + (f"; {hint}" if hint else ""), path)


class MessageEncodingError(InputError):
    """A message whose encoding/type we cannot decode (e.g. image encoding 'yuv422')."""


class TopicTypeError(InputError):
    """A topic whose message type does not fit what it was chosen for (e.g. --image-topic /odom)."""


class DamagedImageError(MessageEncodingError):
    """An image whose bytes are damaged (e.g. a truncated JPEG): the decoder said so."""


class TrajectoryFormatError(InputError):
    """A malformed trajectory file line; ``line`` is 1-based."""

    def __init__(self, message: str, path=None, line: int | None = None):
        self.line = line
        where = f"line {line}: " if line is not None else ""
        super().__init__(f"{where}{message}", path)


class InvalidPoseError(InputError):
    """A pose with NaN/inf values, a non-unit quaternion that cannot be normalised, etc."""


class UnsortedStampsError(InputError):
    """Timestamps that go backwards where a time-ordered series is required."""


class ConfigError(InputError):
    """Unknown key, wrong type or bad value in a configuration file or override."""


class CalibrationError(InputError):
    """A camera calibration file (Kalibr camchain.yaml, EuRoC sensor.yaml) with a key missing or malformed."""


class WeightsError(InputError):
    """Network weights missing, corrupt, or of the wrong shape."""


class VocabularyError(InputError):
    """A vocabulary file that is missing, truncated or not a slam-lcd vocabulary."""


class DownloadError(SlamLcdError):
    """A download that failed (offline, bad URL, checksum mismatch)."""


class NotBuiltError(SlamLcdError):
    """A feature that is not implemented yet; raised instead of faking a result."""


class ViewerMissingError(SlamLcdError):
    """The optional viewer extra (rerun-sdk) is not installed; the message says how to install it."""


class PipelineError(SlamLcdError):
    """A run that cannot proceed (e.g. log without the image topic it needs)."""


_CONTEXT_KINDS = (DamagedImageError, InvalidPoseError, UnsortedStampsError, MessageEncodingError, TopicTypeError,
                  ConfigError, CalibrationError, CorruptLogError, WeightsError, VocabularyError, FileMissingError,
                  InputError, PipelineError)


def in_context(err: SlamLcdError, where: str, path: str | Path | None = None) -> SlamLcdError:
    """The same kind of error with ``where`` (e.g. ``topic /odom, stamp 12.5 s``) before its problem.

    Decoders do not know which log, topic or message they were given; the caller does,
    and adds it here so that the one line the user sees says where the problem is.
    """
    kind = next((k for k in _CONTEXT_KINDS if isinstance(err, k)), SlamLcdError)
    return kind(f"{where}: {err.problem}", path if path is not None else err.path)


def stamp_text(stamp_ns: int) -> str:
    """``1700000000.100000000 s``: a stamp as exact decimal seconds."""
    ns = int(stamp_ns)
    sign = "-" if ns < 0 else ""
    ns = abs(ns)
    return f"{sign}{ns // 1_000_000_000}.{ns % 1_000_000_000:09d} s"
