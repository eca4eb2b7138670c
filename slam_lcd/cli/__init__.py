"""The ``slam-lcd`` command line: one module per subcommand, each with ``register(subparsers)``."""
