"""Small helpers shared by the subcommands (one-line usage errors, output-path checks)."""
from __future__ import annotations

import argparse
import sys
import types

from ..errors import InputError
from ..files.atomic import check_no_clash, check_writable_target


def one_line_errors(parser: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """Make argparse usage errors one line on stderr with exit status 2 (no usage dump), with a
    near-miss suggestion for a mistyped subcommand, choice or option."""

    def error(self, message: str):  # argparse's signature
        message = " ".join(str(message).split())
        print(f"{self.prog}: error: {message}{_suggest_choice(message)}", file=sys.stderr)
        sys.exit(2)

    def parse_known_args(self, args=None, namespace=None):
        # unknown options would otherwise reach the top-level parser, which prints its usage
        ns, extras = argparse.ArgumentParser.parse_known_args(self, args, namespace)
        late = getattr(self, "late_positional", None)
        if late and len(extras) == 1 and not extras[0].startswith("-") and getattr(ns, late, None) is None:
            # an optional positional after options (`export A --to tum B`): argparse leaves it over
            setattr(ns, late, extras.pop())
        if extras:
            self.error(f"unrecognized arguments: {' '.join(extras)}{_suggest_option(self, extras)}")
        return ns, extras

    # per-instance overrides: argparse builds the subcommand parsers itself, so no subclass reaches them
    parser.error = types.MethodType(error, parser)  # type: ignore[method-assign]
    parser.parse_known_args = types.MethodType(parse_known_args, parser)  # type: ignore[method-assign]
    return parser


def _suggest_choice(message: str) -> str:
    """'; did you mean 'run'?' for argparse's "invalid choice: 'rn' (choose from 'run', ...)"."""
    import difflib
    import re

    m = re.search(r"invalid choice: '([^']*)' \(choose from (.*)\)", message)
    if not m:
        return ""
    choices = re.findall(r"'([^']*)'", m.group(2)) or [c.strip() for c in m.group(2).split(",")]
    close = difflib.get_close_matches(m.group(1), choices, n=2, cutoff=0.5)
    return f"; did you mean {' or '.join(repr(c) for c in close)}?" if close else ""


def _suggest_option(parser: argparse.ArgumentParser, extras: list[str]) -> str:
    """'; did you mean --image-topic?' for a mistyped long option."""
    import difflib

    known = [o for a in parser._actions for o in a.option_strings if o.startswith("--")]
    hints = []
    for x in extras:
        if x.startswith("--"):
            close = difflib.get_close_matches(x.split("=", 1)[0], known, n=1, cutoff=0.6)
            if close:
                hints.append(close[0] if len(extras) == 1 else f"{close[0]} (for {x})")
    return f"; did you mean {', '.join(hints)}?" if hints else ""


def subparsers_of(parser: argparse.ArgumentParser) -> list[argparse.ArgumentParser]:
    """Every subcommand parser below ``parser`` (nested ones too, e.g. ``vocab train``)."""
    found = []
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub in dict.fromkeys(action.choices.values()):  # aliases map to the same parser
                found.append(sub)
                found += subparsers_of(sub)
    return found


def _input_path(spec):
    """The file an input names: ``LOG:TOPIC`` names its log."""
    from ..sensors.trajectories import split_log_topic

    if spec is None:
        return None
    lt = split_log_topic(str(spec))
    return lt[0] if lt else spec


def check_outputs(outputs: dict, inputs: dict, *, folders=()) -> None:
    """The command line's rule for what a command writes, before any work is done.

    ``outputs`` and ``inputs`` map a flag (``'OUT'``, ``'--times-out'``, ``'TRAJ'`` ...) to a
    path (None: not given; ``LOG:TOPIC`` inputs name their log). No output may land on or inside
    an input, hold an input, or share its path with another output
    (:func:`slam_lcd.files.atomic.check_no_clash`); then each output must be writable
    (:func:`slam_lcd.files.atomic.check_writable_target`; ``folders``: the flags whose output is a folder).
    """
    outs = {w: o for w, o in outputs.items() if o is not None}
    check_no_clash(outs, {w: _input_path(p) for w, p in inputs.items()})
    for w, o in outs.items():
        check_writable_target(o, folder=w in folders)


def write_guard(out):
    """Turn OS errors while writing ``out`` (permissions, full disk) into a one-line InputError."""
    import contextlib

    @contextlib.contextmanager
    def guard():
        try:
            yield
        except OSError as e:
            raise InputError(f"cannot write output ({e.strerror or e}); nothing was written there", out) from None

    return guard()


def parse_size(text: str) -> tuple[int, int]:
    """argparse type of ``--size WxH`` (at least 16x16)."""
    try:
        w, h = (int(v) for v in str(text).lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"--size must look like 640x480, got {text!r}") from None
    if w < 16 or h < 16:
        raise argparse.ArgumentTypeError(f"--size {text} is too small (at least 16x16)")
    return w, h
