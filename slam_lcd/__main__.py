import sys

try:
    from .cli.main import main
except KeyboardInterrupt:  # Ctrl-C while the command line loads: one line, no traceback
    print("slam-lcd: interrupted", file=sys.stderr)
    sys.exit(130)

sys.exit(main())
