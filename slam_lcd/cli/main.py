"""Entry point of ``slam-lcd``.

Library errors (:class:`slam_lcd.errors.SlamLcdError`) become one line on stderr and exit
status 2; ``--debug`` shows the traceback instead. Each subcommand lives in its own module
of this package and exposes ``register(subparsers)``, which sets ``func(args) -> int``.
"""
from __future__ import annotations

import argparse
import importlib
import logging
import sys
import warnings

from .. import __version__
from ..errors import SlamLcdError
from .util import one_line_errors

# module name in slam_lcd.cli -> registered subcommands
COMMAND_MODULES = [
    "info",
    "make_demo_log",
    "vocab",
    "eval_lcd",
    "run",
    "demo",
    "ate",
    "export",
]


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="slam-lcd",
        description="Loop-closure back end for visual SLAM (Bag of SuperPoints + graph verification + GTSAM iSAM2).",
    )
    parser.add_argument("--version", action="version", version=f"slam-lcd {__version__}")
    parser.add_argument("--debug", action="store_true", help="show full tracebacks on errors")
    parser.add_argument("-v", "--verbose", action="store_true", help="log progress details")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMAND_MODULES:
        mod = importlib.import_module(f".{name}", __package__)
        mod.register(sub)
    # usage errors are one line too (exit status 2), for the root parser and every subcommand
    one_line_errors(parser)
    for p in sub.choices.values():
        one_line_errors(p)
    return parser


def main(argv: list[str] | None = None) -> int:
    try:
        parser = build_parser()  # imports every subcommand module: a Ctrl-C here is one line too
        args = parser.parse_args(argv)
    except KeyboardInterrupt:
        print("slam-lcd: interrupted", file=sys.stderr)
        return 130
    logging.basicConfig(
        level=logging.INFO if args.verbose else logging.WARNING,
        format="%(levelname)s: %(message)s",
    )
    if not args.debug:  # library warnings (torch, numpy, matplotlib) are not ours to show
        warnings.filterwarnings("ignore")
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    try:
        return int(args.func(args) or 0)
    except SlamLcdError as e:
        if args.debug:
            raise
        print(f"slam-lcd {args.command}: error: {e}", file=sys.stderr)
        return 2
    except OSError as e:  # a file system error no subcommand turned into its own message
        if args.debug:
            raise
        where = f"{e.filename}: " if getattr(e, "filename", None) else ""
        print(f"slam-lcd {args.command}: error: {where}{e.strerror or e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"slam-lcd {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
