"""Entry point of ``slam-lcd``.

Library errors (:class:`slam_lcd.errors.SlamLcdError`) become one line on stderr and exit
status 2; ``--debug`` shows the traceback instead. Each subcommand lives in its own module
of this package and exposes ``register(subparsers)``, which sets ``func(args) -> int``.

The global flags (``--debug``, ``-v/--verbose``, ``--no-progress``) are accepted before or
after the subcommand: each subcommand parser gets them too, with a suppressed default so
that a flag given before the subcommand is not reset by the subcommand's parser.
"""
from __future__ import annotations

import argparse
import importlib
import logging
import sys
import warnings

from ..errors import SlamLcdError
from ..files.atomic import user_path
from ..runtime.interrupts import (
    Terminated,
    exit_status,
    install_stop_signals,
    interrupt_behind,
    keep_lost_interrupts,
    signal_name,
    status_of,
)
from ..version import __version__
from .util import one_line_errors, subparsers_of

# module name in slam_lcd.cli -> registered subcommands
COMMAND_MODULES = [
    "info",
    "make_demo_log",
    "vocab",
    "eval_lcd",
    "run",
    "localize",
    "map",
    "batch",
    "demo",
    "ate",
    "export",
    "export_map",
    "weights",
    "view",
]

# flags every command takes, before or after the subcommand name
GLOBAL_FLAGS = [
    (("--debug",), "show the full traceback on errors (default: a one-line message, exit status 2)"),
    (("-v", "--verbose"), "log progress details (INFO) on stderr (default: warnings only)"),
    (("--no-progress",), "no progress bars and no per-stage lines (default: a bar with rate and ETA when "
                         "stderr is a terminal, otherwise one line per stage)"),
]


def add_global_flags(parser: argparse.ArgumentParser, *, suppress: bool) -> None:
    group = parser.add_argument_group("global options (before or after the subcommand)")
    for names, text in GLOBAL_FLAGS:
        group.add_argument(*names, action="store_true", help=text,
                           default=argparse.SUPPRESS if suppress else False)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="slam-lcd",
        description="Loop-closure back end for visual SLAM (Bag of SuperPoints + graph verification + GTSAM iSAM2).",
    )
    parser.add_argument("--version", action="version", version=f"slam-lcd {__version__}")
    add_global_flags(parser, suppress=False)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMAND_MODULES:
        mod = importlib.import_module(f".{name}", __package__)
        mod.register(sub)
    # usage errors are one line too (exit status 2), for the root parser and every subcommand
    one_line_errors(parser)
    for p in subparsers_of(parser):
        add_global_flags(p, suppress=True)
        one_line_errors(p)
    return parser


def stopped_line(prefix: str, exc: BaseException) -> str:
    """``slam-lcd run: interrupted`` (Ctrl-C) or ``slam-lcd run: terminated (SIGTERM)``."""
    return f"{prefix}: terminated ({signal_name(exc)})" if isinstance(exc, Terminated) else f"{prefix}: interrupted"


def main(argv: list[str] | None = None) -> int:
    install_stop_signals()  # SIGTERM and SIGHUP take Ctrl-C's path (exit 143 / 129)
    keep_lost_interrupts()  # a Ctrl-C that lands in a finaliser still stops the command
    try:
        parser = build_parser()  # imports every subcommand module: a Ctrl-C here is one line too
        args = parser.parse_args(argv)
    except (KeyboardInterrupt, ImportError) as caught:
        e = interrupt_behind(caught)  # an extension module interrupted while it initialised: ImportError
        if e is None:
            raise
        print(stopped_line("slam-lcd", e), file=sys.stderr)
        return exit_status(e)
    except SystemExit as e:  # usage errors (one line, already printed), --help, --version
        return int(e.code or 0) if not isinstance(e.code, str) else 2
    logging.basicConfig(
        level=logging.INFO if args.verbose else logging.WARNING,
        format="%(levelname)s: %(message)s",
    )
    if not args.debug:  # library warnings (torch, numpy, matplotlib) are not ours to show
        warnings.filterwarnings("ignore")
    # the exact command line, for the run's report (argv as given, the program named as installed)
    args.command_line = ["slam-lcd", *(sys.argv[1:] if argv is None else argv)]
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
    except BrokenPipeError:  # `slam-lcd info x | head`: the reader left; not an error of ours
        import os

        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except OSError as e:  # a file system error no subcommand turned into its own message
        if args.debug:
            raise

        where = f"{user_path(e.filename)}: " if getattr(e, "filename", None) else ""
        print(f"slam-lcd {args.command}: error: {where}{e.strerror or e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as e:
        print(stopped_line(f"slam-lcd {args.command}", e), file=sys.stderr)
        return exit_status(e)
    except ImportError as caught:  # a module imported late (torch, GTSAM) whose initialisation a signal stopped
        interrupted = interrupt_behind(caught)
        if interrupted is None or args.debug:
            raise
        print(stopped_line(f"slam-lcd {args.command}", interrupted), file=sys.stderr)
        return exit_status(interrupted)


def console() -> int:
    """The installed ``slam-lcd`` script: :func:`main`, then stop signals ignored while Python exits
    (:func:`slam_lcd.runtime.interrupts.status_of`)."""
    return status_of(main)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(console())
