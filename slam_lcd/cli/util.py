"""Small helpers shared by the subcommands (one-line usage errors, output-path checks)."""
from __future__ import annotations

import argparse
import sys
import types


def one_line_errors(parser: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """Make argparse usage errors one line on stderr with exit status 2 (no usage dump)."""

    def error(self, message: str):  # noqa: ANN001 - argparse's signature
        print(f"{self.prog}: error: {' '.join(str(message).split())}", file=sys.stderr)
        sys.exit(2)

    def parse_known_args(self, args=None, namespace=None):
        # unknown options would otherwise reach the top-level parser, which prints its usage
        ns, extras = argparse.ArgumentParser.parse_known_args(self, args, namespace)
        if extras:
            self.error(f"unrecognized arguments: {' '.join(extras)}")
        return ns, extras

    parser.error = types.MethodType(error, parser)
    parser.parse_known_args = types.MethodType(parse_known_args, parser)
    return parser


def describe(spec: str, fmt: str | None, n: int) -> str:
    return f"{spec} ({fmt or 'auto'}, {n} poses)"


def check_output_path(out: str | None, *inputs) -> None:
    """Refuse outputs that are folders or inputs, before any work is done."""
    from pathlib import Path

    from ..atomic import check_writable_target, guard_not_input
    from ..errors import InputError

    if out is None:
        return
    if Path(out).is_dir():
        raise InputError("output path is a folder; give a file name", out)
    from ..eval.sources import split_log_topic

    paths = []
    for inp in inputs:  # LOG:TOPIC names the log as the input
        lt = split_log_topic(str(inp)) if inp is not None else None
        paths.append(lt[0] if lt else inp)
    guard_not_input(out, *paths)
    check_writable_target(out)


def write_guard(out):
    """Turn OS errors while writing ``out`` (permissions, full disk) into a one-line InputError."""
    import contextlib

    from ..errors import InputError

    @contextlib.contextmanager
    def guard():
        try:
            yield
        except OSError as e:
            raise InputError(f"cannot write output ({e.strerror or e}); nothing was written there", out) from None

    return guard()
