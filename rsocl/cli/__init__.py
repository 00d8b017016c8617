"""Layer 8, the ``rsocl`` command line: one module per group of subcommands."""

from rsocl.cli.main import build_parser, main

__all__ = ["build_parser", "main"]
