"""The ``slam-lcd`` command line: one module per subcommand, each with ``register(subparsers)``.
May import: everything; nothing imports it but ``slam_lcd.__main__``.
"""
