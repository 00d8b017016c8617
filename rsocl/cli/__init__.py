"""Layer 8, the ``rsocl`` command line: one module per subcommand, the shared arguments in :mod:`~rsocl.cli.options`."""

from rsocl.cli.main import build_parser, entry, main

__all__ = ["build_parser", "entry", "main"]
