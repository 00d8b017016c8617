"""A JSON file of finished benchmark cases, so that a long study resumes where it stopped.

Each case's result (a JSON value) is stored under a key that names everything it depends on
(rig, scene, noise, settings); the file is rewritten atomically after every case.
"""

from __future__ import annotations

import json
import os
from pathlib import Path


class Cache:
    """The cases of ``path`` (read when it exists), rewritten atomically after each new one."""

    def __init__(self, path):
        self.path = Path(path)
        self.data = json.loads(self.path.read_text()) if self.path.exists() else {}

    def __contains__(self, key) -> bool:
        return key in self.data

    def __getitem__(self, key):
        return self.data[key]

    def put(self, key, value):
        """Store ``value`` under ``key`` and rewrite the file."""
        self.data[key] = value
        tmp = self.path.with_suffix(".tmp")
        tmp.write_text(json.dumps(self.data))
        os.replace(tmp, self.path)
        return value

    def get(self, key, compute):
        """The value of ``key``: stored, or ``compute()`` stored first."""
        if key not in self.data:
            self.put(key, compute())
        return self.data[key]
