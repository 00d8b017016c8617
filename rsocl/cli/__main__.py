"""``python -m rsocl.cli``: the same as the ``rsocl`` command."""

import sys

from rsocl.cli import entry

sys.exit(entry())
