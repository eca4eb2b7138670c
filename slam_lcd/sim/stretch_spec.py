"""The bad stretches ``make-demo-log`` can put into a log (``--blur``, ``--dark``, ``--drop-frames``,
``--freeze``, ``--stamp-jump``, ``--odom-dropout``, ``--odom-zero-covariance``): what was asked and
its checks.

Why a module of its own, without numpy: the command line parses these flags for every command
(``slam-lcd --help`` included); :mod:`slam_lcd.sim.stretches` turns them into what each frame and
odometry sample gets.

Times are seconds from the log's first camera frame on the world's clock (the clock before any
``--stamp-jump``); a stretch holds the stamps ``START <= t < START + SECONDS``.
"""
from __future__ import annotations

import argparse
import math
from dataclasses import dataclass, fields

from ..errors import InputError

BLUR_PX = 15.0  # --blur's kernel length (px at 640 px image width) when PX is not given
MAX_BLUR_PX = 640.0  # one image width
MAX_JUMP_S = 1e9  # all --stamp-jump together: ROS1 stamps are 32-bit seconds (the log starts at 1.7e9 s)


@dataclass(frozen=True)
class Stretch:
    """One stretch: ``start_s`` (``AT`` of a stamp jump), ``seconds`` and, for ``--blur``, ``px``."""

    start_s: float
    seconds: float
    px: float | None = None

    def text(self) -> str:
        return f"{self.start_s:g}:{self.seconds:g}" + ("" if self.px is None else f":{self.px:g}")


def check_stretch(flag: str, s: Stretch) -> None:
    """ValueError naming what is wrong with ``s`` as ``flag`` takes it."""
    first = "AT" if flag == "--stamp-jump" else "START"
    if not (math.isfinite(s.start_s) and s.start_s >= 0):
        raise ValueError(f"{first} must be a number of seconds >= 0, got {s.start_s:g}")
    if not (math.isfinite(s.seconds) and s.seconds > 0):
        raise ValueError(f"SECONDS must be a number of seconds > 0, got {s.seconds:g}")
    if flag == "--stamp-jump" and s.seconds > MAX_JUMP_S:
        raise ValueError(f"SECONDS must be at most {MAX_JUMP_S:g} (ROS1 stamps are 32-bit seconds), got {s.seconds:g}")
    if s.px is not None and not (math.isfinite(s.px) and 0 < s.px <= MAX_BLUR_PX):
        raise ValueError(f"PX must be a kernel length in pixels > 0 and at most {MAX_BLUR_PX:g}, got {s.px:g}")


def parse_stretch(flag: str, text: str) -> Stretch:
    """``START:SECONDS`` (``--blur``: ``START:SECONDS[:PX]``, PX default :data:`BLUR_PX`)."""
    syntax = "START:SECONDS[:PX]" if flag == "--blur" else ("AT:SECONDS" if flag == "--stamp-jump" else
                                                             "START:SECONDS")
    parts = str(text).split(":")
    try:
        if len(parts) not in ((2, 3) if flag == "--blur" else (2,)):
            raise ValueError
        values = [float(p) for p in parts]
    except ValueError:
        raise ValueError(f"expected {syntax} (seconds from the first camera frame), got {text!r}") from None
    s = Stretch(values[0], values[1], (values[2] if len(values) == 3 else BLUR_PX) if flag == "--blur" else None)
    check_stretch(flag, s)
    return s


def stretch_arg(flag: str):
    """The argparse ``type`` of ``flag``: a usage error (one line, exit 2) on a bad value."""
    def parse(text: str) -> Stretch:
        try:
            return parse_stretch(flag, text)
        except ValueError as e:
            raise argparse.ArgumentTypeError(str(e)) from None

    parse.__name__ = flag.lstrip("-")  # argparse names the type in some messages
    return parse


@dataclass(frozen=True)
class Stretches:
    """Every stretch asked for a log (each kind may repeat; overlapping stretches of one kind act as one)."""

    blur: tuple[Stretch, ...] = ()
    dark: tuple[Stretch, ...] = ()
    drop_frames: tuple[Stretch, ...] = ()
    freeze: tuple[Stretch, ...] = ()
    stamp_jump: tuple[Stretch, ...] = ()
    odom_dropout: tuple[Stretch, ...] = ()
    odom_zero_covariance: bool = False

    def __bool__(self) -> bool:
        return any(getattr(self, f.name) for f in fields(self))

    @property
    def odometry(self) -> list[str]:
        """The flags given that change the odometry."""
        return [f for f, on in (("--odom-dropout", self.odom_dropout),
                                ("--odom-zero-covariance", self.odom_zero_covariance)) if on]

    def flags(self) -> list[str]:
        """As the command line gives them: ``['--blur 2:1:15', '--odom-zero-covariance', ...]``."""
        out = []
        for f in fields(self):
            v = getattr(self, f.name)
            flag = "--" + f.name.replace("_", "-")
            if isinstance(v, bool):
                out += [flag] if v else []
            else:
                out += [f"{flag} {s.text()}" for s in v]
        return out

    def check(self) -> None:
        """InputError (one line naming the flag) on a bad value: the library's check of what the CLI parses."""
        for f in fields(self):
            v = getattr(self, f.name)
            if isinstance(v, bool):
                continue
            flag = "--" + f.name.replace("_", "-")
            for s in v:
                if (s.px is not None) != (flag == "--blur"):
                    raise InputError(f"{flag} {s.text()}: " + ("PX is --blur's only" if s.px is not None else
                                                               "give PX (kernel length in pixels)"))
                try:
                    check_stretch(flag, s)
                except ValueError as e:
                    raise InputError(f"{flag} {s.text()}: {e}") from None
        total = sum(s.seconds for s in self.stamp_jump)
        if total > MAX_JUMP_S:
            raise InputError(f"--stamp-jump: the jumps add up to {total:g} s; at most {MAX_JUMP_S:g} "
                             "(ROS1 stamps are 32-bit seconds)")
